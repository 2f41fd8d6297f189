"""TFP throughput on a 1000×1000 plain ``.dat`` file: packed counting vs. unpack-and-sum.

What it measures, over consecutive non-overlapping 10-tick windows covering the whole file (TFP's
SpikeDiff setting; frames/s = ticks covered per second of wall time):

* **fast, batched** — :meth:`PlainDatSource.count_windows` on batches of ``--batch`` windows
  into one reused output buffer (threads split the windows);
* **fast, per window** — :meth:`PlainDatSource.count` once per window (threads split the rows):
  what ``spikeview.classical.tfp`` calls;
* **baseline** — the straightforward single-threaded numpy path, in the same process:
  ``np.unpackbits(..., bitorder="little")`` of each window's frames, ``sum(axis=0)``, vertical
  flip (as a view, which favours the baseline).

The output is uint16 counts (TFP = counts / 10 is a cheap elementwise scale done by the caller).
The file (random spikes at about 30 % density, generated from random bytes) is written to a
temporary folder, read once to warm the page cache and the memory map, and deleted at the end.
Repeats alternate between the methods so that load from other processes hits them alike; medians
of wall-clock times are reported, with the CPU time (all threads) beside them.

Usage::

    python benchmarks/bench_tfp.py                      # writes benchmarks/results/tfp.md
    python benchmarks/bench_tfp.py --frames 1000 --repeats 3 --out /tmp/tfp.md
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

H = W = 1000
FB = H * W // 8
WINDOW = 10


def make_file(path: Path, n_frames: int, seed: int = 0) -> float:
    """Write ``n_frames`` random 1000×1000 frames; returns the measured spike density."""
    rng = np.random.default_rng(seed)
    ones = 0
    with open(path, "wb") as f:
        for start in range(0, n_frames, 100):
            n = min(100, n_frames - start) * FB
            r = [np.frombuffer(rng.bytes(n), dtype=np.uint8) for _ in range(6)]
            # P(bit) = 1 - (1 - 1/4)(1 - 1/16) ≈ 0.297
            chunk = (r[0] & r[1]) | (r[2] & r[3] & r[4] & r[5])
            if start == 0:
                ones = int(np.unpackbits(chunk[:FB * 10]).sum())
            f.write(chunk.tobytes())
    return ones / (FB * 8 * 10)


def baseline_pass(mm: np.ndarray, n_windows: int) -> np.ndarray:
    last = None
    for w in range(n_windows):
        packed = mm[w * WINDOW * FB:(w + 1) * WINDOW * FB].reshape(WINDOW, FB)
        bits = np.unpackbits(packed, axis=1, bitorder="little").reshape(WINDOW, H, W)
        last = bits.sum(axis=0, dtype=np.uint16)[::-1]
    return last


def fast_batched_pass(src, n_windows: int, batch: int, out: np.ndarray) -> np.ndarray:
    for w0 in range(0, n_windows - n_windows % batch, batch):
        src.count_windows(w0 * WINDOW, (w0 + batch) * WINDOW, WINDOW, out=out)
    rest = n_windows % batch
    if rest:
        a = (n_windows - rest) * WINDOW
        src.count_windows(a, a + rest * WINDOW, WINDOW)
    return out[-1]


def fast_single_pass(src, n_windows: int) -> np.ndarray:
    last = None
    for w in range(n_windows):
        last = src.count(w * WINDOW, (w + 1) * WINDOW)
    return last


def timed(fn) -> tuple[float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def measure(path: Path, n_windows: int, batch: int, repeats: int) -> dict[str, list[tuple[float, float]]]:
    """Check that the methods agree, then time them (alternating); ``{method: [(wall_s, cpu_s), ...]}``."""
    from spikeview.io import PlainDatSource

    n_frames = n_windows * WINDOW
    src = PlainDatSource(path, W, H)
    mm = np.memmap(path, dtype=np.uint8, mode="r")
    out = np.empty((batch, H, W), np.uint16)

    # warm-up: compile/load the kernel, fault in the memory maps, check the results agree
    ref = baseline_pass(mm, n_windows)
    np.testing.assert_array_equal(fast_single_pass(src, n_windows), ref)
    np.testing.assert_array_equal(src.count_windows(0, n_frames, WINDOW)[-1], ref)
    fast_batched_pass(src, n_windows, batch, out)
    for w in (0, n_windows // 2):
        bits = np.unpackbits(mm[w * WINDOW * FB:(w + 1) * WINDOW * FB].reshape(WINDOW, FB), axis=1,
                             bitorder="little").reshape(WINDOW, H, W)
        np.testing.assert_array_equal(src.count(w * WINDOW, (w + 1) * WINDOW), bits.sum(0)[::-1])

    methods = {
        "fast, batched (count_windows)": lambda: fast_batched_pass(src, n_windows, batch, out),
        "fast, per window (count)": lambda: fast_single_pass(src, n_windows),
        "baseline (unpackbits + sum, 1 thread)": lambda: baseline_pass(mm, n_windows),
    }
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in methods}
    for _ in range(repeats):
        for name, fn in methods.items():
            times[name].append(timed(fn))
    src.close()
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=4000, help="frames in the generated file (default 4000)")
    ap.add_argument("--repeats", type=int, default=5, help="timed passes per method (default 5)")
    ap.add_argument("--batch", type=int, default=8, help="windows per count_windows call (default 8)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "tfp.md")
    ap.add_argument("--tmp", type=Path, default=None, help="folder for the temporary file")
    args = ap.parse_args(argv)

    from spikeview.io import _packed

    n_windows = args.frames // WINDOW
    n_frames = n_windows * WINDOW
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(dir=args.tmp) as d:
        path = Path(d) / "bench.dat"
        t0 = time.perf_counter()
        density = make_file(path, n_frames)
        gen_s = time.perf_counter() - t0
        times = measure(path, n_windows, args.batch, args.repeats)
    load_after = os.getloadavg()

    med = {k: (statistics.median(t[0] for t in v), statistics.median(t[1] for t in v)) for k, v in times.items()}
    base_fps = n_frames / med["baseline (unpackbits + sum, 1 thread)"][0]
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    import numba

    lines = [
        "# TFP throughput: packed counting vs. unpack-and-sum",
        "",
        f"1000×1000 plain `.dat`, {n_frames} frames ({n_frames * FB / 1e6:.0f} MB, spike density {density:.2f}), "
        f"consecutive {WINDOW}-tick windows over the whole file, uint16 counts per window, vertical flip applied. "
        f"Medians of {args.repeats} passes (methods alternated); frames/s = ticks covered per wall-clock second. "
        f"CPU s / wall s below the thread count means other processes took CPU time during the run; frames per "
        f"CPU-second (all threads) is the throughput that contention affects least.",
        "",
        "| method | frames/s | vs. baseline | ms per window | CPU s / wall s | frames per CPU-second |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, (wall, cpu) in med.items():
        fps = n_frames / wall
        lines.append(f"| {name} | {fps:,.0f} | {fps / base_fps:.2f}× | {wall / n_windows * 1e3:.3f} | "
                     f"{cpu / wall:.2f} | {n_frames / cpu:,.0f} |")
    fast_wall, fast_cpu = med["fast, batched (count_windows)"]
    fast_fps = n_frames / fast_wall
    per_cpu = n_frames / fast_cpu
    threads = _packed.default_threads()
    ratio = fast_fps / base_fps
    verdict = "both met" if fast_fps >= 20_000 and ratio >= 2.5 else (
        "ratio met, rate not met in this run" if ratio >= 2.5 else "not met in this run")
    lines += [
        "",
        f"Targets: ≥ 20,000 frames/s and ≥ 2.5× the baseline. Batched fast path: {fast_fps:,.0f} frames/s, "
        f"{ratio:.2f}× the baseline ({verdict}). "
        f"It got {fast_cpu / fast_wall:.2f} CPUs of its {threads} threads on average; "
        f"at its measured cost of {1e6 / per_cpu:.0f} µs of CPU per frame, {threads} uncontended cores would give "
        f"about {threads * per_cpu:,.0f} frames/s.",
        "",
        "Machine and conditions:",
        "",
        f"- {platform.platform()}, {platform.processor() or platform.machine()}, os.cpu_count() = {os.cpu_count()}, "
        f"usable CPUs = {usable}, counting threads = {threads}",
        f"- Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}",
        f"- load average (1/5/15 min) before: {load_before[0]:.2f}/{load_before[1]:.2f}/{load_before[2]:.2f}, "
        f"after: {load_after[0]:.2f}/{load_after[1]:.2f}/{load_after[2]:.2f} (other processes share the CPUs)",
        f"- test file generated in {gen_s:.1f} s, read from the page cache through a memory map",
        "",
        f"Command: `python benchmarks/bench_tfp.py --frames {args.frames} --repeats {args.repeats} "
        f"--batch {args.batch}`",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
