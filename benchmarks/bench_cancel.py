"""Cancel latency of a guided run at full resolution (issue 15, item 3: "Cancel stops it within 0.2 s").

A guided run (``GuidedSampler.run``, default recipe values, packaged FFDNet, ``torch.set_num_threads(2)``)
on a 1000×1000 window of a simulated uniform capture (RGGB and monochrome) runs in a worker thread, as
in the app; once step 1 has been reported, the main thread waits ``d`` seconds (so the flag falls inside
step 2's prior pass), sets the cancel flag and measures the time until the worker has caught
:class:`~spikeview.errors.Cancelled`. Three delays per layout, median reported, plus where the run
stopped (the exception's message). Also notes the CPU model and the 1-minute load before and after.

Usage::

    python benchmarks/bench_cancel.py [--size 1000] [--delays 0.25 0.75 1.25]

Run against an older tree with ``PYTHONPATH=<old tree> python benchmarks/bench_cancel.py`` for the
"before" figure (the script uses only the public API).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402


def latency(sampler, obs, params, delay: float) -> tuple[float, str, float]:
    """(seconds from flag to Cancelled, the exception message, seconds of step 1)."""
    from spikeview.errors import Cancelled

    flag, step1 = threading.Event(), threading.Event()
    box: dict[str, object] = {}
    t_start = time.perf_counter()

    def cb(step, _total, _preview):
        if step == 1:
            box["t1"] = time.perf_counter()
            step1.set()

    def work():
        try:
            sampler.run(obs, params, callback=cb, cancel=flag)
            box["end"], box["msg"] = time.perf_counter(), "finished (not cancelled)"
        except Cancelled as e:
            box["end"], box["msg"] = time.perf_counter(), str(e)
        finally:
            step1.set()

    th = threading.Thread(target=work, name="guided")
    th.start()
    step1.wait()
    time.sleep(delay)
    t_set = time.perf_counter()
    flag.set()
    th.join()
    return float(box["end"]) - t_set, str(box["msg"]), float(box.get("t1", t_start)) - t_start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--delays", type=float, nargs="+", default=[0.25, 0.75, 1.25])
    ap.add_argument("--layouts", nargs="+", default=["RGGB", "mono"])
    args = ap.parse_args(argv)

    import torch

    import spikeview
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.io.source import ArraySource

    torch.set_num_threads(2)
    print(f"spikeview from {Path(spikeview.__file__).parent}; {cpu_model()}; torch {torch.__version__}; "
          f"load before {os.getloadavg()[0]:.1f}")
    n = args.size
    for layout in args.layouts:
        cfa = None if layout == "mono" else layout
        rng = np.random.default_rng(0)
        src = ArraySource(rng.random((40, n, n), dtype=np.float32) < 0.3, cfa=cfa)
        obs = Observation.from_source(src, 20, 10, alpha=np.ones(3) if cfa else None, eta=2.0, radius=0)
        sampler = GuidedSampler(GuidedConfig())
        rows = []
        for d in args.delays:
            lat, msg, t1 = latency(sampler, obs, GuidedConfig(), d)
            rows.append(lat)
            print(f"  {layout} {n}x{n}: flag {d:.2f} s after step 1 (step 1 took {t1:.1f} s incl. plan) -> "
                  f"stopped {lat * 1000:.0f} ms later: {msg}", flush=True)
        print(f"{layout} {n}x{n}: cancel latency median {statistics.median(rows) * 1000:.0f} ms "
              f"(runs: {', '.join(f'{r * 1000:.0f}' for r in rows)} ms; precision {sampler.info.precision})", flush=True)
    print(f"load after {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
