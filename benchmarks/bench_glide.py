"""Cost of the dim-frame glide (``spikeview.guided.temporal.frame_velocity`` and the moved windows) in ``pool_counts``.

For each capture (simulated, 0.03 spikes per tick, 400 ticks, camera; static and panning a photosite a window, mono
and RGGB), times ``pool_counts`` of the window at tick 200 with the glide as shipped against the same call with
the velocity measurement switched off (the previous behaviour), interleaved, medians of ``--repeats``; prints the
CPU flags beside the timings.

    python benchmarks/bench_glide.py [--size 1000] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def _flags() -> str:
    try:
        text = open("/proc/cpuinfo").read()
    except OSError:
        return "unknown"
    model = next((ln.split(":", 1)[1].strip() for ln in text.splitlines() if ln.startswith("model name")), "unknown")
    flags = next((ln.split(":", 1)[1].split() for ln in text.splitlines() if ln.startswith("flags")), [])
    keep = [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_tile", "amx_bf16") if f in flags]
    return f"{model} ({' '.join(keep)})"


def main() -> None:
    import skimage.data
    from skimage.transform import resize

    import spikeview.guided.temporal as T
    from spikeview.sim import MotionScene, SimConfig, simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    n = args.size
    img = resize(skimage.data.camera().astype(np.float32) / 255.0, (max(n, 512),) * 2, anti_aliasing=True)
    img = np.repeat(img[..., None], 3, axis=-1).astype(np.float32)
    print(f"CPU: {_flags()}; {n}x{n}, 0.03 spikes per tick, pool_counts at tick 200 (radius 3), medians of {args.repeats}")
    print("| capture | glide | previous (no velocity measured) | ratio | pooling said |")
    print("|---|---|---|---|---|")
    off = lambda *a, **k: None  # noqa: E731
    for cfa in (None, "RGGB"):
        for pan in ((0.0, 0.0), (2000.0, 0.0)):
            cap = simulate(MotionScene(img, size=(n, n), pan=pan, srgb=False),
                           SimConfig(n_ticks=400, seed=2, cfa=cfa or "none", rate=0.03, gt_every=400))
            new, old, said = [], [], ""
            for _ in range(args.repeats):
                for which in ("new", "old"):
                    fv = T.frame_velocity
                    if which == "old":
                        T.frame_velocity = off
                    t = time.perf_counter()
                    _, pool = T.pool_counts(cap, 195, 205, 3, cfa)
                    dt = time.perf_counter() - t
                    T.frame_velocity = fv
                    (new if which == "new" else old).append(dt)
                    if which == "new":
                        said = pool.kind + (f", glides {pool.glide[1]:+.2f} px a window" if pool.glide else "")
            a, b = statistics.median(new), statistics.median(old)
            print(f"| {cfa or 'mono'} {'pan 1 px a window' if pan[0] else 'static'} | {a:.2f} s | {b:.2f} s | "
                  f"{a / b:.2f}x | {said} |")


if __name__ == "__main__":
    main()
