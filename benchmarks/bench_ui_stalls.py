"""Desktop app at full resolution: main-thread stalls of a real Qt event loop (issue 15, item 3).

What it measures: the real :class:`spikeview.gui.main_window.MainWindow` (``QT_QPA_PLATFORM=offscreen``,
1600×1000, every panel visible) on simulated 1000×1000 captures, **monochrome and RGGB**, while

* **open** — ``open_path`` of the file until every preview (stream, TFI, rates, degradation, α) is shown
  and the workers are idle;
* **playback** — "every window" playback (Δτ = 10 ticks, TFI pane on, rates throttled);
* **MP4 export** — a marked range exported as TFP frames to MP4, as the Export panel starts it;
* **guided run** — a full-frame guided run (defaults, ``steps`` set by ``--guided-steps``), a preview
  reported after every step.

A 5 ms precise ``QTimer`` records the time of each of its ticks; an interval between two ticks is how
long the event loop did not run (a stall of the window) plus the 5 ms period. Reported per scenario:
the largest interval, the 99th percentile and the median (ms). **Baseline, same process**: the same
timer with the window open and nothing running ("idle"), which shows what the machine's load alone
does to the timer (the machine is shared).

``--diagnose``: a watchdog thread samples the GUI thread's Python stack whenever the timer is more
than ``--late`` ms late and counts where it was (``sys._current_frames``); the top places are printed
and written to the JSON. A GUI thread "waiting in the event loop" during a stall was not running
Python code: it was off the CPU (load) or in Qt's C++ (painting).

Before/after: the script runs every tree given by ``--tree LABEL=DIR`` (``DIR`` on ``PYTHONPATH``, e.g. a
``git archive`` of the starting commit) and the working tree (``after``) in child processes, alternating
``--rounds`` times, and writes ``benchmarks/results/ui_stalls.{md,json}``.

Usage::

    git archive HEAD | tar -x -C /tmp/before
    python benchmarks/bench_ui_stalls.py --tree before=/tmp/before
    python benchmarks/bench_ui_stalls.py --quick --diagnose --out /tmp/s.md   # this tree only, short
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections import Counter
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import cpu_model, synthetic_capture, wait as _wait, write_report  # noqa: E402


def wait(app, cond, timeout: float = 300.0) -> None:
    _wait(app, cond, timeout, pause=0.002)

SCENARIOS = ("idle", "burst", "open_first", "open", "playback", "export", "guided")
BURST_MS = 20
TIMER_MS = 5


# ------------------------------------------------------------------------------------ data
def load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


# ------------------------------------------------------------------------------------ measurement
class Sampler(threading.Thread):
    """Samples the GUI thread's Python stack while the stall timer is late (``--diagnose``)."""

    def __init__(self, gui_ident: int, late_ms: float):
        super().__init__(daemon=True)
        self.gui, self.late = gui_ident, late_ms / 1000
        self.last = time.perf_counter()
        self.last_cpu = 0.0  # the GUI thread's CPU time at its last tick
        self.clock = time.pthread_getcpuclockid(gui_ident)
        self.counts: Counter[str] = Counter()
        self.samples: list[tuple[float, str]] = []
        self.stop_flag = threading.Event()

    def run(self) -> None:
        names = {}
        while not self.stop_flag.wait(0.003):
            late = time.perf_counter() - self.last >= self.late
            busy = time.clock_gettime(self.clock) - self.last_cpu >= self.late / 3
            if not (late or busy):
                continue
            frames = sys._current_frames()
            frame = frames.get(self.gui)
            if frame is None:
                continue
            key = self._where(frame, gui=True)
            self.counts[key] += 1
            now = time.perf_counter()
            self.samples.append((now, key))
            if len(names) != threading.active_count():
                names = {t.ident: t.name for t in threading.enumerate()}
            for ident, f in frames.items():  # where the other threads are (a worker holding the lock in C code)
                if ident not in (self.gui, threading.get_ident()):
                    w = self._where(f, gui=False)
                    if w:
                        self.samples.append((now, f"    [{names.get(ident, ident)}] {w}"))

    @staticmethod
    def _where(frame, gui: bool) -> str:
        stack = traceback.extract_stack(frame)
        own = [f for f in stack if any(s in f.filename for s in ("spikeview", "pyqtgraph", "numpy", "torch", "/av/", "numba"))
               and "bench_ui_stalls" not in f.filename]
        if not own:
            return "waiting in the event loop (no Python running)" if gui else ""
        parts = [own[0]] + own[-2:] if len(own) > 3 else own  # the slot (outermost of ours) and the innermost two
        return " > ".join(f"{Path(f.filename).name}:{f.name}:{f.lineno}" for f in parts)


def measure(app, start, done, timeout: float, sampler: Sampler | None = None) -> dict:
    """Intervals between ticks of a precise ``TIMER_MS`` QTimer while ``start()``'s work runs until ``done()``."""
    from PySide6 import QtCore

    stamps: list[float] = []
    cpu: list[float] = []  # the GUI thread's own CPU time at each tick (time.thread_time)
    loop = QtCore.QEventLoop()
    t_end = time.perf_counter() + timeout

    def tick() -> None:
        now = time.perf_counter()
        stamps.append(now)
        cpu.append(time.thread_time())
        if sampler is not None:
            sampler.last, sampler.last_cpu = now, cpu[-1]
        if done() or now > t_end:
            loop.quit()

    timer = QtCore.QTimer()
    timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    timer.setInterval(TIMER_MS)
    timer.timeout.connect(tick)
    if sampler is not None:
        sampler.counts.clear()
        sampler.samples.clear()
        sampler.last, sampler.last_cpu = time.perf_counter(), time.thread_time()
    t0, c0 = time.perf_counter(), time.thread_time()
    timer.start()
    start()
    loop.exec()
    timer.stop()
    gaps = np.diff(np.array([t0] + stamps)) * 1000
    busy = np.diff(np.array([c0] + cpu)) * 1000
    out = {"max": float(gaps.max()), "p99": float(np.percentile(gaps, 99)), "median": float(np.median(gaps)),
           "cpu_max": float(busy.max()), "cpu_p99": float(np.percentile(busy, 99)), "cpu_total": float(busy.sum()),
           "n": int(gaps.size), "over50": int((gaps > 50).sum()), "seconds": float(stamps[-1] - t0),
           "timed_out": bool(stamps[-1] > t_end)}
    if sampler is not None:
        out["where"] = sampler.counts.most_common(12)
        # the places seen during the three longest stalls
        ends = np.array(stamps)
        worst = list(np.argsort(gaps)[::-1][:3]) + [i for i in np.argsort(busy)[::-1][:3] if busy[i] > 8]
        out["worst"] = []
        for i in dict.fromkeys(worst):
            hi = ends[i]
            lo = hi - gaps[i] / 1000
            seen = Counter(k for ts, k in sampler.samples if lo <= ts <= hi)
            out["worst"].append([float(gaps[i]), seen.most_common(8), float(busy[i])])
    return out


def spin(app, seconds: float) -> None:
    wait(app, lambda e=time.perf_counter() + seconds: time.perf_counter() > e)


def idle_workers(w) -> bool:
    c = w.controller
    return not any(x.is_active() for x in (c.preview, c.tfi, c.guided, c.exporter, w.loader))


def calibration(app, seconds: float, sampler=None) -> dict:
    """The load's effect on known work: every 200 ms the GUI thread computes for 20 ms of its own CPU time
    (nothing else running); the largest interval shows how long a 20 ms task takes on this machine now."""
    from PySide6 import QtCore

    def busy() -> None:
        end = time.thread_time() + BURST_MS / 1000
        while time.thread_time() < end:
            pass

    timer = QtCore.QTimer()
    timer.setInterval(200)
    timer.timeout.connect(busy)
    timer.start()
    try:
        return measure(app, lambda: None, lambda: False, seconds, sampler)
    finally:
        timer.stop()


def cancel_latency(app, w, delays: list[float]) -> list[dict]:
    """Cancel a full-frame guided run ``d`` s after Run (the window's α is cached; at 1000×1000 the first
    second or two builds the observation and the plan): ms from ``cancel_guided()`` until the worker says
    the job ended (its ``cancelled`` signal, queued to the GUI thread), and what had been reported by then."""
    s, c = w.session, w.controller
    rows = []
    for d in delays:
        wait(app, lambda: idle_workers(w))
        seen: dict = {"plan": False, "steps": 0}
        on_update = lambda u: seen.__setitem__("plan", True) if u.kind == "plan" else seen.__setitem__("steps", seen["steps"] + 1)
        on_cancel = lambda ch, job, *_: seen.__setitem__("end", time.perf_counter()) if job == seen.get("job") else None
        c.guided_update.connect(on_update)
        c.guided.cancelled.connect(on_cancel)
        c.guided.finished.connect(on_cancel)  # a run that ended before Cancel reached it
        c.run_guided()
        seen["job"] = c.guided._latest.get("guided")  # this run's job id (signals of earlier jobs are ignored)
        spin(app, d)
        stage = "steps" if seen["steps"] else ("sampler (plan shown)" if seen["plan"] else "building the window")
        t0 = time.perf_counter()
        c.cancel_guided()
        wait(app, lambda: "end" in seen, 300)
        end = seen["end"]
        c.guided_update.disconnect(on_update)
        c.guided.cancelled.disconnect(on_cancel)
        c.guided.finished.disconnect(on_cancel)
        rows.append({"delay_s": d, "latency_ms": 1000 * (end - t0), "stage": stage, "steps_before": seen["steps"], "by_job_id": True})
        print(f"    cancel {d:.2f} s after Run ({stage}): {1000 * (end - t0):.0f} ms", flush=True)
    return rows


# ------------------------------------------------------------------------------------ one tree
def child(args) -> int:
    from PySide6 import QtCore

    from spikeview.gui.app import make_application
    from spikeview.gui.main_window import MainWindow

    app = make_application()
    data = Path(args.data)
    sampler = None
    if args.diagnose:
        sampler = Sampler(threading.get_ident(), args.late)
        sampler.start()
    res: dict = {"load_start": load(), "scenarios": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        st = QtCore.QSettings(str(tmp / "settings.ini"), QtCore.QSettings.Format.IniFormat)
        st.clear()
        w = MainWindow(settings=st)
        w.ask_overwrite = lambda out, existing: True
        w.resize(1600, 1000)
        w.show()
        spin(app, 1.0)
        s, c = w.session, w.controller
        for cfa in args.cfas:
            label = cfa or "mono"
            path = synthetic_capture(data, args.size, args.ticks, None if cfa == "none" else cfa)
            out = res["scenarios"].setdefault(label, {})

            def opened(p=path):
                return (s.stream is not None and s.stream.path == p and c.last_frames is not None
                        and w.degradation_panel.last is not None and idle_workers(w))

            # the first open of the process (cold for the first capture: numba kernels load, first paints), then
            # the same file again ("open")
            first: dict = {"old": s.stream}
            out["open_first"] = measure(app, lambda: (first.__setitem__("t", time.perf_counter()), w.open_path(path)),
                                        lambda: time.perf_counter() - first["t"] > 0.3 and opened()
                                        and s.stream is not first.get("old"), 300, sampler)
            spin(app, 0.5)
            print(f"[{label}] idle…", flush=True)
            out["idle"] = measure(app, lambda: None, lambda: False, args.idle_seconds, sampler)
            if cfa == args.cfas[0]:
                out["burst"] = calibration(app, args.idle_seconds, sampler)
            if "open" in args.scenarios:
                print(f"[{label}] open…", flush=True)
                holder: dict = {"old": s.stream}
                out["open"] = measure(app, lambda: (holder.__setitem__("t", time.perf_counter()), w.open_path(path)),
                                      lambda: time.perf_counter() - holder["t"] > 0.3 and opened()
                                      and s.stream is not holder.get("old"), 120, sampler)
                spin(app, 0.5)
            if "playback" in args.scenarios:
                print(f"[{label}] playback…", flush=True)
                w.stream_panel.tfi_check.setChecked(True)
                s.update_params({"speed": "window", "window": 10, "loop": True}, record=False)
                s.set_playing(True)
                spin(app, 1.0)  # warm-up
                t_play = time.perf_counter()
                out["playback"] = measure(app, lambda: None, lambda: time.perf_counter() - t_play > args.play_seconds,
                                          args.play_seconds + 10, sampler)
                out["playback"]["frames_shown_per_s"] = float(c.display_fps())
                s.set_playing(False)
                wait(app, lambda: idle_workers(w))
                spin(app, 0.5)
            if "export" in args.scenarios:
                print(f"[{label}] MP4 export…", flush=True)
                n = min(s.n_frames - 20, args.export_ticks)
                s.set_tick(10)
                s.set_mark_in()
                s.set_tick(10 + n)
                s.set_mark_out()
                s.update_params({"export_format": "mp4", "export_range": "marked", "export_method": "tfp"}, record=False)
                target = tmp / f"stall_{label}.mp4"
                flag: dict = {}
                conn = c.export_state.connect(lambda state, msg: flag.__setitem__("state", state) if state != "running" else None)
                out["export"] = measure(app, lambda: w.export_to(str(target)), lambda: "state" in flag, 600, sampler)
                out["export"]["frames"] = len(w.export_panel.ticks())
                out["export"]["state"] = flag.get("state")
                c.export_state.disconnect(conn)
                s.clear_marks()
                wait(app, lambda: idle_workers(w))
                spin(app, 0.5)
            if "guided" in args.scenarios:
                print(f"[{label}] guided run…", flush=True)
                s.set_tick(s.n_frames // 2)
                wait(app, lambda: idle_workers(w))
                s.update_params({"steps": 2}, record=False)  # warm-up: torch, the prior, once per worker
                run = c.run_guided()
                wait(app, lambda: c.guided_result is not None and c.guided_result.run == run, 900)
                wait(app, lambda: idle_workers(w))
                spin(app, 0.5)
                s.update_params({"steps": args.guided_steps}, record=False)
                steps: list[float] = []
                conn = c.guided_update.connect(lambda u: steps.append(time.perf_counter()) if u.kind == "step" else None)
                gstate: dict = {}
                out["guided"] = measure(app, lambda: gstate.__setitem__("run", c.run_guided()),
                                        lambda: c.guided_result is not None and c.guided_result.run == gstate.get("run")
                                        and idle_workers(w), 900, sampler)
                c.guided_update.disconnect(conn)
                out["guided"]["previews"] = len(steps)
                out["guided"]["run_s"] = float(c.guided_result.elapsed)
                wait(app, lambda: idle_workers(w))
            if "cancel" in args.scenarios:
                print(f"[{label}] Cancel latency…", flush=True)
                res.setdefault("cancel", {})[label] = cancel_latency(app, w, args.cancel_delays)
            for k, r in out.items():
                print(f"  {label:5s} {k:10s} max {r['max']:6.1f} ms  p99 {r['p99']:5.1f}  median {r['median']:4.1f}  "
                      f"n {r['n']}  >50ms {r['over50']}  | GUI CPU per interval max {r['cpu_max']:5.1f} p99 {r['cpu_p99']:4.1f}"
                      f" total {r['cpu_total'] / 1000:.2f} s of {r['seconds']:.1f}", flush=True)
                for gap, seen, cpu in r.get("worst", []):
                    if gap > args.late or cpu > 8:
                        print(f"      stall {gap:.0f} ms (GUI CPU {cpu:.0f} ms):\n" + "\n".join(f"        {n}× {k}" for k, n in seen), flush=True)
        w.close()
        app.processEvents()
    if sampler is not None:
        sampler.stop_flag.set()
    res["load_end"] = load()
    import spikeview

    res["spikeview"] = str(Path(spikeview.__file__).resolve().parent)
    Path(args.json).write_text(json.dumps(res, indent=1), encoding="utf-8")
    return 0


# ------------------------------------------------------------------------------------ driver
def machine() -> str:
    import pyqtgraph
    import PySide6

    flags = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                have = set(line.split(":", 1)[1].split())
                flags = " ".join(f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in have)
                break
    except OSError:
        pass
    return (f"{cpu_model(platform.processor() or 'unknown CPU')} ({flags}), {os.cpu_count()} logical CPUs; "
            f"{platform.system()} {platform.release()}; Python {platform.python_version()}, PySide6 {PySide6.__version__}, "
            f"pyqtgraph {pyqtgraph.__version__}; Qt platform {os.environ.get('QT_QPA_PLATFORM')}")


NAMES = {"idle": "idle window (baseline)", "burst": f"calibration: a {BURST_MS} ms GUI task every 200 ms, nothing else running", "open_first": "opening the file (first in the process: mono cold, RGGB after mono)",
         "open": "opening the file again", "playback": "playback (every window, TFI on)",
         "export": "MP4 export (TFP)", "guided": "guided run (full frame)"}


def report(runs: list[dict], args) -> list[str]:
    labels = list(dict.fromkeys(r["tree"] for r in runs))
    cfas = list(dict.fromkeys(c for r in runs for c in r["scenarios"]))
    loads = [r["load_start"][0] for r in runs if r.get("load_start")] + [r["load_end"][0] for r in runs if r.get("load_end")]
    lines = [
        "# Desktop app at 1000×1000: main-thread stalls (target: no stall over 50 ms)", "",
        f"Produced by `python benchmarks/bench_ui_stalls.py {' '.join(args.argv)}`".rstrip() + " "
        f"({args.size}×{args.size} simulated captures, {args.ticks} ticks, mono and RGGB; playback {args.play_seconds:g} s; "
        f"MP4 export of {args.export_ticks} ticks; guided runs of {args.guided_steps} steps, full frame, a preview every step).", "",
        f"Machine: {machine()}. 1-minute load average "
        f"{min(loads):.1f}–{max(loads):.1f} during these runs (per run below).", "",
        f"Method: a {TIMER_MS} ms precise QTimer in the app's real Qt event loop (the main window, 1600×1000, offscreen); "
        "each interval between two of its ticks is recorded while the work runs: a frozen GUI thread shows as one long "
        f"interval ({TIMER_MS} ms is a perfect score). **wall** = the largest interval / the 99th percentile (ms). "
        "**GUI CPU** = the most CPU time the GUI thread itself used within one interval (`time.thread_time`): its own "
        "work, whatever the load; a wall interval much longer than its GUI CPU is the GUI thread waiting for a core "
        "(load) or for the interpreter lock. **idle** = the same timer in the same process with the window open and "
        "nothing running: the load's effect on the timer by itself. The trees alternate (before, after, before, …); "
        "each cell lists one value per run.", "",
    ]
    for tree in labels:
        rs = [r for r in runs if r["tree"] == tree]
        lines.append(f"- **{tree}** (`{rs[0].get('rev', '')}`): " + "; ".join(
            f"run {i + 1} load {r['load_start'][0] if r['load_start'] else '?'} → {r['load_end'][0] if r['load_end'] else '?'}"
            for i, r in enumerate(rs)))
    lines.append("")
    head = "| capture | during | " + " | ".join(f"{t}: wall max / p99 | {t}: GUI CPU max" for t in labels) + " | ≤ 50 ms (" + labels[-1] + ") |"
    lines += [head, "|---|---|" + "---|---|" * len(labels) + "---|"]
    for cfa in cfas:
        for sc in SCENARIOS:
            cells = []
            last = []
            for tree in labels:
                vals = [r["scenarios"][cfa][sc] for r in runs if r["tree"] == tree and sc in r["scenarios"].get(cfa, {})]
                cells.append(", ".join(f"{v['max']:.0f} / {v['p99']:.0f}" for v in vals) or "—")
                cells.append(", ".join(f"{v.get('cpu_max', float('nan')):.0f}" for v in vals) or "—")
                if tree == labels[-1]:
                    last = vals
            if not last:
                continue
            verdict = "—" if sc in ("idle", "burst") else ("met" if all(v["max"] <= 50 for v in last) else
                                               f"NOT met ({sum(v['max'] > 50 for v in last)} of {len(last)} runs)")
            lines.append(f"| {'mono' if cfa in ('none', None) else cfa} | {NAMES[sc]} | " + " | ".join(cells) + f" | {verdict} |")
    cancels = [(r["tree"], cfa, row) for r in runs for cfa, rows in r.get("cancel", {}).items() for row in rows
               if row.get("by_job_id")]
    if cancels:
        lines += ["", "Cancel of a full-frame guided run (target ≤ 200 ms): ms from Cancel until the worker reports the job "
                  "ended, Cancel pressed d s after Run; at 1000×1000 the first seconds build the window (the neighbouring "
                  "windows' counts and alignment, the plan) before the first step.", "",
                  "| tree | capture | d (s) | stage when cancelled | ms |", "|---|---|---|---|---|"]
        for tree, cfa, row in cancels:
            lines.append(f"| {tree} | {'mono' if cfa in ('none', None) else cfa} | {row['delay_s']:g} | {row['stage']} | "
                         f"{row['latency_ms']:.0f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--ticks", type=int, default=400)
    ap.add_argument("--cfas", nargs="+", default=["none", "RGGB"], help="none = monochrome")
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS[3:]) + ["cancel"], choices=list(SCENARIOS[3:]) + ["cancel"])
    ap.add_argument("--cancel-delays", type=float, nargs="+", default=[0.2, 0.6, 1.2, 3.0],
                    help="cancel a guided run this many seconds after Run (one run each)")
    ap.add_argument("--idle-seconds", type=float, default=4.0)
    ap.add_argument("--play-seconds", type=float, default=8.0)
    ap.add_argument("--export-ticks", type=int, default=200, help="ticks of the marked range exported (Δτ-spaced frames)")
    ap.add_argument("--guided-steps", type=int, default=6)
    ap.add_argument("--tree", action="append", default=[], help="LABEL=DIR: another tree to run first (on PYTHONPATH)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--diagnose", action="store_true", help="sample the GUI thread's stack during stalls")
    ap.add_argument("--late", type=float, default=30.0, help="--diagnose: sample when the timer is this many ms late")
    ap.add_argument("--quick", action="store_true", help="short: 3 s playback, 60-tick export, 2 guided steps")
    ap.add_argument("--data", default=None, help="folder for the simulated captures (kept between runs)")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "ui_stalls.md")
    ap.add_argument("--report-only", type=Path, default=None, help="rewrite the report from this JSON (no runs)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--json", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    raw = list(argv if argv is not None else sys.argv[1:])
    args.argv = []  # the command as run (for the report), without the output options
    skip = False
    for a in raw:
        if skip:
            skip = False
        elif a in ("--json", "--out", "--report-only", "--data"):
            skip = True
        elif not a.startswith(("--json=", "--out=", "--report-only=", "--data=")):
            args.argv.append(a)
    if args.quick:
        args.play_seconds, args.export_ticks, args.guided_steps, args.idle_seconds = 3.0, 60, 2, 2.0
    if args.data is None:
        args.data = str(Path(tempfile.gettempdir()) / "spikeview_ui_stalls")
    Path(args.data).mkdir(parents=True, exist_ok=True)
    args.cfas = [None if c == "none" else c for c in args.cfas]
    if args.child:
        args.cfas = ["none" if c is None else c for c in args.cfas]
        return child(args)

    if args.report_only is not None:
        runs = json.loads(args.report_only.read_text())
        lines = report(runs, args)
        print("\n".join(lines))
        if args.report_only.resolve() != args.out.with_suffix(".json").resolve():
            args.out.with_suffix(".json").write_text(json.dumps(runs, indent=1), encoding="utf-8")
        return write_report(args.out, lines)
    trees = [tuple(t.split("=", 1)) for t in args.tree]
    if "after" not in [label for label, _ in trees]:
        trees.append(("after", str(ROOT)))
    runs: list[dict] = []
    child_args = [a for a in (argv if argv is not None else sys.argv[1:])]
    # drop --tree/--out/--rounds (the driver's) before handing the rest to the children
    keep: list[str] = []
    skip = False
    for a in child_args:
        if skip:
            skip = False
            continue
        if a in ("--tree", "--out", "--rounds"):
            skip = True
            continue
        if a.startswith(("--tree=", "--out=", "--rounds=")):
            continue
        keep.append(a)
    for rnd in range(args.rounds):
        for label, folder in trees:
            with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
                jpath = f.name
            env = dict(os.environ, PYTHONPATH=folder + os.pathsep + os.environ.get("PYTHONPATH", ""))
            print(f"== {label} ({folder}), round {rnd + 1}", flush=True)
            rc = subprocess.call([sys.executable, str(Path(__file__).resolve()), "--child", "--json", jpath,
                                  "--data", args.data, *keep], env=env, cwd=folder)
            if rc != 0:
                print(f"{label}: child failed (exit {rc})", file=sys.stderr)
                continue
            r = json.loads(Path(jpath).read_text())
            os.unlink(jpath)
            r["tree"] = label
            rev = Path(folder) / "REV"
            r["rev"] = rev.read_text().strip() if rev.exists() else subprocess.run(
                ["git", "-C", folder, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
            runs.append(r)
    lines = report(runs, args)
    print("\n".join(lines))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(runs, indent=1), encoding="utf-8")
    return write_report(args.out, lines)


if __name__ == "__main__":
    raise SystemExit(main())
