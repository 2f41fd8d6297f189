"""A knob change on a 256² ROI: how soon the app shows the new x̂₀, and whether the window stalls meanwhile (issue 27).

What it measures (the real :class:`spikeview.gui.main_window.MainWindow`, ``QT_QPA_PLATFORM=offscreen``,
1366×768): a synthetic capture (RGGB and monochrome, ``--size``² pixels, `benchmarks/_common.py`), a 256×256 ROI at
its centre, *Restart on change* on. After a warm-up run, each sample sets the guidance weight s (what its slider does)
and waits for the guided run it starts to finish (the controller's ``guided_done`` for a run newer than the change):

* **latency**: from ``session.set("s", …)`` to that run's result, as the user sees it: the restart's debounce
  (``GUIDED_DEBOUNCE_MS``), the observation, pooling, plan and the sampler on the ROI;
* **worker**: the same run's own seconds in the worker (the job alone: the baseline the debounce and the queue add to);
* **stall**: the largest gap of a 10 ms precise QTimer meanwhile (the event loop; the target is ≤ 50 ms).

Medians over ``--repeats`` samples; the machine, its CPU flags and the load are recorded.

Usage::

    python benchmarks/bench_roi_knob.py                    # writes benchmarks/results/roi_knob.md
    python benchmarks/bench_roi_knob.py --quick --out /tmp/roi.md
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _common import cpu_model, load_average as load, synthetic_capture, wait  # noqa: E402  (benchmarks/_common.py)


def spin(app, seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.001)


def one_capture(app, path: Path, repeats: int) -> dict:
    from PySide6 import QtCore

    from spikeview.gui.main_window import MainWindow

    with tempfile.TemporaryDirectory() as tmp:
        st = QtCore.QSettings(str(Path(tmp) / "s.ini"), QtCore.QSettings.Format.IniFormat)
        w = MainWindow(settings=st)
        w.resize(1366, 768)
        w.show()
        w.open_path(path)
        wait(app, lambda: w.session.stream is not None and w.session.stream.path == path)
        spin(app, 1.0)
        s, c = w.session, w.controller
        s.set_tick(s.n_frames // 2)
        h, wd = s.source.height, s.source.width
        s.set_roi(((wd - 256) // 2, (h - 256) // 2, 256, 256))
        w.guided_panel.live.setChecked(True)
        results: list = []
        c.guided_done.connect(lambda r: results.append((time.perf_counter(), r)))
        run = c.run_guided()  # warm-up: torch, the prior, numba kernels
        wait(app, lambda: any(getattr(r, "run", None) == run for _, r in results), timeout=600)
        spin(app, 1.0)
        lat, work, stalls = [], [], []
        for i in range(repeats):
            before = c.guided_run
            stamps: list[float] = []
            timer = QtCore.QTimer()
            timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
            timer.setInterval(10)
            timer.timeout.connect(lambda: stamps.append(time.perf_counter()))
            timer.start()
            t0 = time.perf_counter()
            s.set("s", 1.0 + 0.05 * ((i % 2) * 2 - 1) * (1 + i // 2))  # the slider: 0.95, 1.10, 0.90, ...
            wait(app, lambda: c.guided_run > before and any(getattr(r, "run", None) == c.guided_run for _, r in results),
                 timeout=600)
            t1, r = next((t, r) for t, r in reversed(results) if getattr(r, "run", None) == c.guided_run)
            timer.stop()
            lat.append(t1 - t0)
            work.append(float(getattr(r, "elapsed", float("nan"))))
            gaps = np.diff(stamps) * 1000 if len(stamps) > 1 else np.array([float("nan")])
            stalls.append(float(np.nanmax(gaps)))
            spin(app, 0.5)
        w.close()
        return {"latency": lat, "worker": work, "stall": stalls}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=1000)
    p.add_argument("--repeats", type=int, default=6)
    p.add_argument("--quick", action="store_true", help="512², 3 repeats")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "roi_knob.md"))
    a = p.parse_args(argv)
    size, repeats = (512, 3) if a.quick else (a.size, a.repeats)
    from PySide6 import QtWidgets

    from spikeview.gui.controller import GUIDED_DEBOUNCE_MS
    from spikeview.guided.precision import cpu_flags

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for cfa in ("RGGB", None):
            path = synthetic_capture(Path(tmp), size, 400, cfa)
            r = one_capture(app, path, repeats)
            rows.append((cfa or "mono", r))
            print(cfa or "mono", {k: [round(x, 3) for x in v] for k, v in r.items()}, flush=True)
    flags = " ".join(f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in cpu_flags()) or "no avx2"
    lines = ["# A knob change on a 256² ROI (issue 27)", "",
             f"Machine: {cpu_model()} ({flags}), {os.cpu_count()} CPU cores; load at the end {load()}. "
             f"Command: `python benchmarks/bench_roi_knob.py{' --quick' if a.quick else ''}` ({size}² capture, 256² ROI at "
             f"its centre, Restart on change, the guidance weight s moved {repeats} times; restart debounce "
             f"{GUIDED_DEBOUNCE_MS} ms).", "",
             "| capture | latency, median (max) s | the run in the worker, median s | largest event-loop gap, median (max) ms | target |",
             "|---|---|---|---|---|"]
    for name, r in rows:
        lat, work, st = r["latency"], r["worker"], r["stall"]
        ok = "met" if statistics.median(lat) <= 1.0 and max(st) <= 50 else "**missed**"
        lines.append(f"| {size}² {name} | {statistics.median(lat):.2f} ({max(lat):.2f}) | {statistics.median(work):.2f} | "
                     f"{statistics.median(st):.0f} ({max(st):.0f}) | ≤ 1 s, ≤ 50 ms: {ok} |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(a.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
