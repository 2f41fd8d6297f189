"""Where a 1000² guided window's time goes on a GPU machine, and how the clip scales with frames prepared ahead.

Run after (or with) ``benchmarks/gpu_check.py`` on a lent GPU machine (``bash benchmarks/gpu_check.sh`` sets the
path up; this script is run the same way: ``python3 benchmarks/gpu_profile.py --out OUTDIR``). It writes
``OUTDIR/gpu_profile.txt``:

1. one 1000² observation (counting, pooling, interval rates) under cProfile, the GPU synchronised, sorted by
   cumulative and by own time;
2. the same observation's wall time with the pooling's search on the GPU and on the host (numpy);
3. a short 1000² clip through ``reconstruct_windows`` with 1, 4, 8 and 12 frames prepared ahead (frames/s each).

It measures only: nothing here is a target (gpu_check.py has those).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gpu_check import simulate, sync  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--work", default="/tmp/spikeview_gpu_check")
    ap.add_argument("--windows", type=int, default=30)
    ap.add_argument("--depths", default="1,4,8,12")
    ap.add_argument("--switch", default="", help="comma-separated sys.setswitchinterval values (s) for a depth-8 clip each")
    ap.add_argument("--skip-profile", action="store_true")
    a = ap.parse_args(argv)
    out, work = Path(a.out), Path(a.work)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    text: list[str] = []

    def say(*parts: object) -> None:
        line = " ".join(str(p) for p in parts)
        print(line, flush=True)
        text.append(line)
        (out / "gpu_profile.txt").write_text("\n".join(text) + "\n", encoding="utf-8")

    import torch

    import spikeview.guided.temporal as temporal
    import spikeview.guided.video as video
    from spikeview.guided.observation import Observation
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, reconstruct_windows, sampler_params
    from spikeview.recipe import Recipe

    say(f"host: {os.cpu_count()} cores; torch {torch.__version__}; cuda {torch.cuda.is_available()}")
    src = open_source(str(simulate(1000, 10 * a.windows + 80, work)))
    recipe = Recipe().with_values({"run.method": "guided"})
    state = prepare_sequence(src, recipe, warn=False)
    p = sampler_params(recipe, state)

    def once() -> None:
        Observation.from_source(src, 100, p.window, alpha=state.alpha, eta=p.eta, radius=p.temporal_radius, device=p.device)
        sync()

    once()
    if a.skip_profile:
        a_profile = ()
    else:
        a_profile = (("search on the device", False), ("search on the host (numpy)", True))
    for label, host in a_profile:
        saved = p.device
        try:
            if host:
                p = p.replace(device="cpu")
            ts = []
            for _ in range(3):
                t0 = time.perf_counter()
                once()
                ts.append(time.perf_counter() - t0)
            say(f"observation 1000², {label}: median {sorted(ts)[1]:.3f} s ({', '.join(f'{t:.3f}' for t in ts)})")
        finally:
            p = p.replace(device=saved)
    prof = cProfile.Profile()
    prof.enable()
    once()
    prof.disable()
    for key in (() if a.skip_profile else ("cumulative", "tottime")):
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats(key).print_stats(30)
        say(f"--- cProfile of one observation, by {key} ---")
        say(s.getvalue())
    centres = list(range(45, 40 + 10 * a.windows, 10))[:a.windows]
    for depth in [int(d) for d in a.depths.split(",") if d]:
        video.prefetch_depth = lambda d=depth: d  # noqa: B023 - bound per depth
        t0 = time.perf_counter()
        n = sum(1 for _ in reconstruct_windows(src, centres, recipe, state))
        sync()
        wall = time.perf_counter() - t0
        say(f"clip 1000², {depth} ahead: {n} windows in {wall:.1f} s = {n / wall:.2f} frames/s")
    # the main thread's time: waiting for a prepared frame, and sampling (with the observation threads busy)
    from spikeview.guided.sampler import GuidedSampler

    spent = {"wait": 0.0, "sample": 0.0}

    def timed(fn, key):
        def inner(*args, **kw):
            t = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                spent[key] += time.perf_counter() - t
        return inner

    video._Prefetch.get = timed(video._Prefetch.get, "wait")
    GuidedSampler.run = timed(GuidedSampler.run, "sample")
    for sw in [float(v) for v in a.switch.split(",") if v]:
        sys.setswitchinterval(sw)
        video.prefetch_depth = lambda: 8
        spent.update(wait=0.0, sample=0.0)
        t0 = time.perf_counter()
        n = sum(1 for _ in reconstruct_windows(src, centres, recipe, state))
        sync()
        wall = time.perf_counter() - t0
        say(f"clip 1000², 8 ahead, switch interval {sw * 1e3:.1f} ms: {n / wall:.2f} frames/s; main thread waited "
            f"{spent['wait'] / n:.3f} s a frame, sampled {spent['sample'] / n:.3f} s a frame, other {(wall - spent['wait'] - spent['sample']) / n:.3f} s")
    sys.setswitchinterval(0.005)
    say(f"TORCH_ON_CPU={temporal.TORCH_ON_CPU}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
