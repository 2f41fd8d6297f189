"""Simulator throughput: ticks per second at 256×256 and 1000×1000, noise off and on.

What it measures (after a warm-up run that compiles/loads the numba kernels):

* **sensor only** — :func:`spikeview.sim.simulate` of a static colour image (the scene costs
  nothing), RGGB, noise off (``SimConfig.noiseless``) and all noise on (``SimConfig()``), with one
  thread and with the default thread count for 1000×1000;
* **baseline** in the same process — the obvious vectorised numpy integrate-and-fire (per tick:
  ``v += q``, ``numpy.random`` Poisson shot noise and normal jitter, compare, subtract);
* **demo** — :func:`spikeview.sim.demo_capture` end to end (scene rendered at every tick), and the
  demo scene with key frames at 4 kHz.

Medians of ``--repeats`` runs. Usage::

    python benchmarks/bench_sim.py                 # writes benchmarks/results/sim.md
    python benchmarks/bench_sim.py --quick --out /tmp/sim.md
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _median_time(fn, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU seconds (all threads) of ``fn()``."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def _rates(ticks: int, times: tuple[float, float]) -> tuple[float, float]:
    return ticks / times[0], ticks / times[1]


def _image(size: int) -> np.ndarray:
    return np.random.default_rng(0).uniform(0.05, 1.0, (size, size, 3)).astype(np.float32)


def sensor_only(size: int, ticks: int, noise: bool, threads: int | None, repeats: int) -> tuple[float, float]:
    from spikeview.sim import SimConfig, StaticScene, simulate

    cfg = (SimConfig() if noise else SimConfig.noiseless()).replace(n_ticks=ticks)
    img = _image(size)
    if threads is not None:
        os.environ["SPIKEVIEW_THREADS"] = str(threads)
    try:
        simulate(StaticScene(img), cfg.replace(n_ticks=2))  # warm-up (compile or load the cache)
        return _rates(ticks, _median_time(lambda: simulate(StaticScene(img), cfg), repeats))
    finally:
        os.environ.pop("SPIKEVIEW_THREADS", None)


def numpy_baseline(size: int, ticks: int, noise: bool, repeats: int) -> tuple[float, float]:
    from spikeview.cfa import channel_map
    from spikeview.sim import SimConfig

    cfg = SimConfig()
    img = _image(size)
    chan = channel_map("RGGB", size, size)
    a = (cfg.rate * np.asarray(cfg.spectral_gains)[chan] * np.take_along_axis(img, chan[..., None].astype(np.intp), 2)[..., 0])
    ne = cfg.electrons_per_threshold

    def run() -> None:
        rng = np.random.default_rng(0)
        v = rng.random((size, size))
        out = np.empty((ticks, size, size), np.uint8)
        for t in range(ticks):
            q = a + 0.0051
            if noise:
                q = rng.poisson(q * ne) / ne
                fire = v + q >= 1.0 + rng.normal(0.0, 0.0064, q.shape)
            else:
                fire = v + q >= 1.0
            v += q - fire
            out[t] = fire
    return _rates(ticks, _median_time(run, repeats))


def demo(size: int, ticks: int, render_rate: float | None, repeats: int) -> tuple[float, float]:
    from spikeview.sim import SimConfig, demo_scene, simulate

    simulate(demo_scene(size, render_rate=render_rate), SimConfig(n_ticks=2))
    return _rates(ticks, _median_time(lambda: simulate(demo_scene(size, render_rate=render_rate), SimConfig(n_ticks=ticks)),
                                      repeats))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "sim.md")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="fewer ticks (smoke run)")
    args = ap.parse_args()
    small_ticks, big_ticks = (300, 20) if args.quick else (2000, 100)
    r = args.repeats
    from spikeview.sim._kernels import default_threads

    rows = []
    for noise in (False, True):
        label = "on" if noise else "off"
        rows.append((f"256×256 sensor only, noise {label}", sensor_only(256, small_ticks, noise, 1, r),
                     numpy_baseline(256, small_ticks // 4, noise, r)))
        rows.append((f"1000×1000 sensor only, noise {label}, 1 thread", sensor_only(1000, big_ticks, noise, 1, r),
                     numpy_baseline(1000, big_ticks // 4, noise, r)))
        rows.append((f"1000×1000 sensor only, noise {label}, {default_threads()} threads",
                     sensor_only(1000, big_ticks, noise, None, r), None))
    rows.append(("256×256 demo scene, rendered every tick, noise on", demo(256, small_ticks // 2, None, r), None))
    rows.append(("256×256 demo scene, key frames at 4 kHz, noise on", demo(256, small_ticks // 2, 4000.0, r), None))
    rows.append(("1000×1000 demo scene, key frames at 4 kHz, noise on", demo(1000, big_ticks, 4000.0, r), None))

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    lines = [
        "# Simulator throughput (`benchmarks/bench_sim.py`)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"numpy {np.__version__}; load average at the end {load[0]:.1f} (other jobs share the CPUs).",
        f"Medians of {r} runs after a warm-up; 20,000 ticks = 1 s of capture. 'per CPU-s' divides by the",
        "process CPU time (all threads): for one thread it is what an otherwise idle core would do.",
        "",
        "| case | ticks/s (wall) | ticks per CPU-s | numpy baseline ticks/s (wall / per CPU-s) | ratio (per CPU-s) |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, fast, base in rows:
        ratio = f"{fast[1] / base[1]:.1f}×" if base else "–"
        base_s = "" if base is None else f"{base[0]:,.0f} / {base[1]:,.0f}"
        lines.append(f"| {name} | {fast[0]:,.0f} | {fast[1]:,.0f} | {base_s} | {ratio} |")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
