"""Desktop app responsiveness, offscreen: playback display rate and slider-to-preview latency.

What it measures (the real :class:`spikeview.gui.main_window.MainWindow`, ``QT_QPA_PLATFORM=offscreen``,
1600×1000 window, every panel visible):

* **display rate** — frames shown per second while playing a 1000×1000 RGGB plain ``.dat`` file
  (opened through :func:`spikeview.io.open_source`, sidecar present) in "every window" mode
  (Δτ = 10 ticks), the firing-rate histograms throttled as in the app (≤ 4 per second). With the
  TFI preview on and off. Baseline in the same process: the same frames computed in a plain loop
  with no window (``spikeview.session.core.stream_frames``) — the ceiling the display can reach.
* **k → preview latency** — from ``session.set("k", …)`` (what a k-slider move does) to the
  degradation panel having shown *and painted* the new Q(C M X) of a 512×512 window. Baseline: the
  degradation job alone (``spikeview.session.jobs.degradation_job``), same process.

* **event-loop stalls** (``--stall``) — the largest gap and the 99th percentile of a 10 ms QTimer's
  intervals during a full-frame guided run, playback and an MP4 export, at 256×256 and 1000×1000.

Warm-up first (numba kernels, torch import, first paints). Medians over ``--seconds`` of playback
(per-second rates) and ``--repeats`` latency samples. The machine and its load are recorded.

Usage::

    python benchmarks/bench_gui.py                    # writes benchmarks/results/gui.md
    python benchmarks/bench_gui.py --quick --out /tmp/gui.md
    python benchmarks/bench_gui.py --stall            # writes benchmarks/results/gui_stall.md
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _common import cpu_model, load_average as load, synthetic_capture as _capture, wait  # noqa: E402  (benchmarks/_common.py)


def synthetic_capture(folder: Path, size: int, ticks: int, seed: int = 0) -> Path:
    """A moving RGGB scene as a plain .dat with sidecar (benchmarks/_common.py)."""
    return _capture(folder, size, ticks, "RGGB", seed)



# ------------------------------------------------------------------------------------ data
# ------------------------------------------------------------------------------------ helpers
def machine() -> str:
    model = cpu_model(platform.processor() or "unknown CPU")
    import pyqtgraph
    import PySide6

    return (f"{model}, {os.cpu_count()} logical CPUs; {platform.system()} {platform.release()}; "
            f"Python {platform.python_version()}, PySide6 {PySide6.__version__}, pyqtgraph {pyqtgraph.__version__}; "
            f"Qt platform {os.environ.get('QT_QPA_PLATFORM')}")


def spin(app, seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.001)


def make_window(app, settings_path: Path):
    from PySide6 import QtCore

    from spikeview.gui.main_window import MainWindow

    st = QtCore.QSettings(str(settings_path), QtCore.QSettings.Format.IniFormat)
    st.clear()
    w = MainWindow(settings=st)
    w.resize(1600, 1000)
    w.show()
    return w


def open_and_wait(app, w, path: Path) -> None:
    w.open_path(path)
    wait(app, lambda: w.session.stream is not None and w.session.stream.path == path)
    wait(app, lambda: w.controller.last_frames is not None and w.degradation_panel.last is not None)
    wait(app, lambda: w.controller.alpha is not None)
    spin(app, 0.5)


# ------------------------------------------------------------------------------------ display rate
def display_rate(app, w, seconds: float, tfi: bool) -> dict[str, float]:
    s = w.session
    w.stream_panel.tfi_check.setChecked(tfi)
    s.update_params({"speed": "window", "window": 10, "loop": True}, record=False)
    shown: list[float] = []
    rates: list[int] = []
    tfis: list[int] = []
    on_frames = lambda f: shown.append(time.perf_counter())
    on_rates = lambda r: rates.append(r.tick)
    on_tfi = lambda t, img, shape: tfis.append(t)
    w.controller.frames_ready.connect(on_frames)
    w.controller.rates_ready.connect(on_rates)
    w.controller.tfi_ready.connect(on_tfi)
    s.set_playing(True)
    spin(app, 2.0)  # warm-up
    shown.clear()
    rates.clear()
    tfis.clear()
    t0 = time.perf_counter()
    spin(app, seconds)
    dur = time.perf_counter() - t0
    s.set_playing(False)
    w.controller.frames_ready.disconnect(on_frames)
    w.controller.rates_ready.disconnect(on_rates)
    w.controller.tfi_ready.disconnect(on_tfi)
    spin(app, 0.5)
    per_second = [sum(1 for x in shown if t0 + i <= x < t0 + i + 1) for i in range(int(dur))]
    return {"fps_median": statistics.median(per_second) if per_second else 0.0, "fps_mean": len(shown) / dur,
            "fps_min": min(per_second) if per_second else 0.0, "rates_per_s": len(rates) / dur, "tfi_per_s": len(tfis) / dur}


def compute_only_rate(source, params: dict, alpha, seconds: float, tfi: bool) -> float:
    from spikeview.session import core

    n = source.n_frames
    t = 5
    core.stream_frames(source, t, params, alpha, want_tfi=tfi)
    count, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        core.stream_frames(source, t, params, alpha, want_tfi=tfi)
        t = (t + 10) % n
        count += 1
    return count / (time.perf_counter() - t0)


# ------------------------------------------------------------------------------------ latency
def k_latency(app, w, repeats: int) -> list[float]:
    s, panel = w.session, w.degradation_panel
    s.set("show_pyramid", False)
    spin(app, 1.0)
    samples: list[float] = []
    state: dict[str, float] = {}

    def shown(view) -> None:  # connected after the panel's own slot: the panel has the new images
        if "t0" in state and f"k = {state['k']:g}" in panel.info.text():
            panel.repaint()  # the new pixels are painted
            samples.append(time.perf_counter() - state.pop("t0"))

    w.controller.degradation_ready.connect(shown)
    values = [20.0, 80.0]
    for i in range(repeats + 3):
        k = values[i % 2] + 0.5 * (i // 2)
        state["k"] = k
        state["t0"] = time.perf_counter()
        s.set("k", k)  # what the slider does
        wait(app, lambda: "t0" not in state)
        spin(app, 0.15)
    w.controller.degradation_ready.disconnect(shown)
    return samples[3:]


def job_only_latency(w, repeats: int) -> list[float]:
    from spikeview.session import jobs

    out = []
    for i in range(repeats):
        req = w.controller._request()
        req.params["k"] = 30.0 + i
        t0 = time.perf_counter()
        jobs.degradation_job(req, None)
        out.append(time.perf_counter() - t0)
    return out


# ------------------------------------------------------------------------------------ event-loop stalls
def measure_stall(app, start, done, timeout: float) -> dict[str, float]:
    """Gaps between ticks of a 10 ms precise QTimer in a real event loop while ``start()``'s work runs.

    The loop runs until ``done()`` (checked on every tick) or ``timeout`` seconds. Returns the
    largest gap, the 99th percentile and the median (ms) and the number of intervals.
    """
    from PySide6 import QtCore

    stamps: list[float] = []
    loop = QtCore.QEventLoop()
    t_end = time.perf_counter() + timeout

    def tick() -> None:
        stamps.append(time.perf_counter())
        if done() or stamps[-1] > t_end:
            loop.quit()

    timer = QtCore.QTimer()
    timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    timer.setInterval(10)
    timer.timeout.connect(tick)
    timer.start()
    start()
    loop.exec()
    timer.stop()
    gaps = np.diff(stamps) * 1000 if len(stamps) > 1 else np.array([float("inf")])
    return {"max": float(gaps.max()), "p99": float(np.percentile(gaps, 99)), "median": float(np.median(gaps)),
            "n": len(gaps), "timed_out": stamps[-1] > t_end if stamps else True}


def stall_scenarios(app, w, tmp: Path, size: int, seconds: float, guided_steps: int) -> dict[str, dict[str, float]]:
    """The three scenarios of issue 10 at one frame size: a full-frame guided run, playback, an MP4 export."""
    s, c = w.session, w.controller
    out: dict[str, dict[str, float]] = {}
    w.stream_panel.tfi_check.setChecked(True)
    s.set_tick(s.n_frames // 2)
    wait(app, lambda: not c.preview.is_active() and not c.tfi.is_active())
    # baseline, same process: the window open and idle (what the machine's load alone does to the timer)
    out["idle window (baseline)"] = measure_stall(app, lambda: None, lambda: False, timeout=min(seconds, 5.0))
    # guided: warm-up (torch, the prior load once per worker), then the measured run
    s.update_params({"steps": 2}, record=False)
    run = c.run_guided()
    wait(app, lambda: c.guided_result is not None and c.guided_result.run == run, timeout=1800)
    s.update_params({"steps": guided_steps}, record=False)
    state: dict[str, int] = {}
    out["guided run"] = measure_stall(app, lambda: state.__setitem__("run", c.run_guided()),
                                      lambda: c.guided_result is not None and c.guided_result.run == state.get("run"),
                                      timeout=seconds * 6)
    c.cancel_guided()
    wait(app, lambda: not c.guided.is_active())
    # playback, every window, TFI on (its pane refreshed 5×/s), rates throttled
    s.update_params({"speed": "window", "window": 10, "loop": True}, record=False)
    t_play: dict[str, float] = {}
    out["playback"] = measure_stall(app, lambda: (t_play.__setitem__("t0", time.perf_counter()), s.set_playing(True)),
                                    lambda: time.perf_counter() - t_play["t0"] > seconds, timeout=seconds + 5)
    s.set_playing(False)
    wait(app, lambda: not c.preview.is_active() and not c.tfi.is_active())
    # MP4 export of a marked range (TFP), as the Export panel starts it
    n = min(s.n_frames - 20, 600)
    s.set_tick(10)
    s.set_mark_in()
    s.set_tick(10 + n)
    s.set_mark_out()
    s.update_params({"export_format": "mp4", "export_range": "marked", "export_method": "tfp"}, record=False)
    target = tmp / f"stall_{size}.mp4"
    done_flag: dict[str, bool] = {}
    c.export_done.connect(lambda paths: done_flag.__setitem__("done", True))
    out["MP4 export"] = measure_stall(app, lambda: w.export_to(str(target)), lambda: "done" in done_flag,
                                      timeout=seconds * 12)
    out["MP4 export"]["frames"] = len(w.export_panel.ticks())
    s.clear_marks()
    return out


def stall_main(args) -> int:
    from spikeview.gui.app import make_application

    app = make_application()
    load_start = load()
    results: dict[int, dict[str, dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        w = make_window(app, tmp / "settings.ini")
        w.ask_overwrite = lambda out, existing: True
        for size in args.stall_sizes:
            print(f"writing the {size}×{size} capture…", flush=True)
            path = synthetic_capture(tmp, size, 400 if size > 512 else 1200)
            open_and_wait(app, w, path)
            print(f"stalls at {size}×{size}…", flush=True)
            steps = args.guided_steps if size <= 512 else max(2, args.guided_steps // 3)
            results[size] = stall_scenarios(app, w, tmp, size, args.seconds, steps)
            for k, r in results[size].items():
                print(f"  {k}: largest gap {r['max']:.0f} ms, p99 {r['p99']:.0f} ms, median {r['median']:.1f} ms, "
                      f"{r['n']} intervals", flush=True)
        w.close()
        app.processEvents()
    load_end = load()
    rows = []
    for size, res in results.items():
        for k, r in res.items():
            verdict = "—" if k.startswith("idle") else ("met" if r["max"] <= 50 else "NOT met")
            rows.append(f"| {size}×{size} | {k} | {r['max']:.0f} | {r['p99']:.0f} | {r['median']:.1f} | {r['n']} | {verdict} |")
    text = f"""# Desktop app: event-loop stalls (target: no gap over 50 ms)

Produced by `python benchmarks/bench_gui.py --stall` ({args.seconds:g} s of playback, guided runs of
{args.guided_steps} steps at ≤ 512 px and {max(2, args.guided_steps // 3)} at 1000 px, full frame).

Machine: {machine()}.
Load average (1/5/15 min) at start {load_start}, at end {load_end}. The machine is shared with other
jobs, so a gap can also be the operating system running someone else's process.

Method: a 10 ms precise QTimer in a real Qt event loop (the app's window, offscreen, 1600×1000);
every interval between its ticks is recorded while the work runs. A frozen GUI thread shows as one
long interval; 10 ms is a perfect score. "Idle window" is the same measurement with nothing running,
in the same process just before: the gaps the machine's load causes by itself.

| frames | during | largest gap (ms) | p99 (ms) | median (ms) | intervals | ≤ 50 ms |
|---|---|---|---|---|---|---|
{chr(10).join(rows)}
"""
    out = args.out if args.out != ROOT / "benchmarks" / "results" / "gui.md" else ROOT / "benchmarks" / "results" / "gui_stall.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    print(text)
    return 0


# ------------------------------------------------------------------------------------ main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0, help="playback seconds measured per setting")
    ap.add_argument("--repeats", type=int, default=30, help="latency samples")
    ap.add_argument("--quick", action="store_true", help="3 s of playback and 8 latency samples")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "gui.md")
    ap.add_argument("--stall", action="store_true",
                    help="measure event-loop stalls (largest gap, p99) during a guided run, playback and an MP4 export")
    ap.add_argument("--stall-sizes", type=int, nargs="+", default=[256, 1000], help="frame sizes for --stall")
    ap.add_argument("--guided-steps", type=int, default=6, help="guided steps for --stall (a third at 1000 px)")
    args = ap.parse_args(argv)
    if args.quick:
        args.seconds, args.repeats = 3.0, 8
    if args.stall:
        return stall_main(args)

    from spikeview.gui.app import make_application

    app = make_application()
    load_start = load()
    rows: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print("writing the 1000×1000 capture…", flush=True)
        big = synthetic_capture(tmp, 1000, 400)
        print("writing the 512×512 capture…", flush=True)
        mid = synthetic_capture(tmp, 512, 200)

        w = make_window(app, tmp / "settings.ini")
        open_and_wait(app, w, big)
        src, params, alpha = w.session.source, dict(w.session.params), w.controller.alpha
        results = {}
        for tfi in (True, False):
            print(f"display rate, TFI {'on' if tfi else 'off'}…", flush=True)
            results[tfi] = display_rate(app, w, args.seconds, tfi)
            results[tfi]["compute"] = compute_only_rate(src, params | {"window": 10}, alpha, min(args.seconds, 5.0), tfi)
        open_and_wait(app, w, mid)
        print("k → preview latency at 512×512…", flush=True)
        w.stream_panel.tfi_check.setChecked(True)
        lat = k_latency(app, w, args.repeats)
        base = job_only_latency(w, max(5, args.repeats // 3))
        w.close()
        app.processEvents()
    load_end = load()

    ms = lambda xs: f"{1000 * statistics.median(xs):.0f}"
    p90 = lambda xs: f"{1000 * float(np.percentile(xs, 90)):.0f}"
    for tfi in (True, False):
        r = results[tfi]
        rows.append(f"| 1000×1000, TFI {'on ' if tfi else 'off'} | {r['fps_median']:.0f} | {r['fps_mean']:.1f} | {r['fps_min']:.0f} | "
                    f"{r['compute']:.1f} | {r['fps_mean'] / max(r['compute'], 1e-9):.2f} | {r['rates_per_s']:.1f} | "
                    f"{r['tfi_per_s']:.1f} |")
    verdict_fps = "met" if results[False]["fps_median"] >= 30 else "NOT met"
    verdict_lat = "met" if statistics.median(lat) <= 0.100 else "NOT met"
    text = f"""# Desktop app: display rate and slider latency

Produced by `python benchmarks/bench_gui.py` ({'quick run' if args.quick else f'{args.seconds:g} s per setting, {args.repeats} latency samples'}).

Machine: {machine()}.
Load average (1/5/15 min) at start {load_start}, at end {load_end} — the machine is shared, so
absolute numbers move with the other work on it; the ratios to the same-process baselines move less.

## Playback display rate (target ≥ 30 fps)

Playing a 1000×1000 RGGB plain `.dat` (sidecar, packed-bit reader) in "every window" mode, Δτ = 10
ticks, raw spike frame + TFP (+ TFI) panes, firing-rate histograms throttled, window 1600×1000 offscreen.
"Frames shown" are previews that reached the screen; the display never queues frames (back-pressure:
the next window is requested only when the last one is shown).

| stream | median fps (per-second counts) | mean fps | worst second | compute-only frames/s (no window, same process) | shown / compute | rate updates /s | TFI updates /s |
|---|---|---|---|---|---|---|---|
{chr(10).join(rows)}

Target ≥ 30 fps (TFI off): **{verdict_fps}**. The compute-only baseline computes raw + TFP (+ TFI)
for every window in one loop. In the app the TFI pane (±32 ticks searched per pixel, the costly one at
1000×1000) runs on its own thread and is refreshed at most 5 times a second during playback, so with
TFI on the raw and TFP panes still play at the rate shown and the TFI pane trails them (its title says
which tick it shows); paused, every pane shows the same tick.

## k-slider → updated degradation preview (target ≤ 100 ms)

512×512 window, X = classical TFP reconstruction, M, C, Q of `spikeview.ops`, residual; measured from
`session.set("k", …)` (a slider move) to the panel's new Q(C M X) painted.

| | median | 90th percentile | max | samples |
|---|---|---|---|---|
| slider → painted preview | {ms(lat)} ms | {p90(lat)} ms | {1000 * max(lat):.0f} ms | {len(lat)} |
| degradation job alone (baseline, no window) | {ms(base)} ms | {p90(base)} ms | {1000 * max(base):.0f} ms | {len(base)} |

Target ≤ 100 ms (median): **{verdict_lat}**.
"""
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
