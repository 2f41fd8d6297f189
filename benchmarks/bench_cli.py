"""The user's path end to end: ``spikeview reconstruct FILE --method guided --at 100`` in a fresh process.

What a user waits for at full resolution: start-up and imports, the sequence's white point and colour
cast from the data, the ±3 neighbouring windows' counting and alignment, the plan and the sampler, the
output written. Each run is a new process (as the CLI runs); medians of ``--repeats`` runs after one
warm-up run (the OS file cache), with the exact float32 path (``--precision float32``) interleaved in the
same run as the baseline. Captures: a 1000×1000 Bayer demo capture written by ``spikeview simulate``
and, when the spikezoo wheel has been unpacked (``--spikezoo``), a real-format 400×250 monochrome clip
(``--cfa none --flip-vertical``).

    python benchmarks/bench_cli.py [--repeats 3] [--spikezoo /work/data/spikezoo] [--out benchmarks/results]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import machine_words  # noqa: E402
from bench_prior import machine, run_cli, save_results, simulate  # noqa: E402

#: the defaults, the exact float32 path (the baseline), and the mixed policy that ``auto`` picked on every CPU with native
#: bfloat16 before it measured whether bfloat16 pays (on an Intel Xeon without AMX it does not: auto now picks float32 there)
PATHS = {"defaults": [], "--precision float32": ["--precision", "float32"],
         "--precision bfloat16-mixed": ["--precision", "bfloat16-mixed"]}


def bench(path: Path, flags: list[str], repeats: int) -> dict:
    """Per path: the runs' wall seconds, peak MB and the plan rows that say what ran."""
    run_cli(path, flags, "precision")  # warm-up: the file in the OS cache, Python's bytecode compiled
    rows: dict[str, list[dict]] = {k: [] for k in PATHS}
    for r in range(repeats):
        for name, extra in PATHS.items():
            out = run_cli(path, [*flags, *extra], "precision")
            out["load"] = os.getloadavg()[0]
            if out["rc"] != 0:
                raise SystemExit(f"{path}: spikeview reconstruct {' '.join(flags + extra)} failed (exit {out['rc']})")
            rows[name].append(out)
            print(f"  {path.name} {name} run {r + 1}: {out['wall_s']:.2f} s, {out['peak_mb']:.0f} MB (load {out['load']:.1f})", flush=True)
    res = {}
    for name, runs in rows.items():
        res[name] = {"wall_s": [x["wall_s"] for x in runs], "median_s": statistics.median(x["wall_s"] for x in runs),
                     "peak_mb": max(x["peak_mb"] for x in runs), "plan": runs[-1]["row"]}
    res["ratio"] = res["--precision float32"]["median_s"] / res["defaults"]["median_s"]
    return res


def write_report(res: dict, out: Path) -> None:
    m = res["machine"]
    head = f"Machine: {machine_words(m)}; 1-min load {m['load_before']:.1f} before, "
    L = ["# The CLI end to end at full resolution (benchmarks/bench_cli.py)", "", head +
         f"{res['load_after']:.1f} after; {res['repeats']} runs per path after a warm-up, each a fresh process "
         f"(`spikeview reconstruct FILE --method guided --at 100`, wall time and peak RSS of the child, start-up included). "
         "Baseline in the same run: `--precision float32` (the exact float32 path); × = its median / the defaults' median.", "",
         "| capture | path | median wall s | runs (s) | peak MB | × float32 | precision row of the plan |",
         "|---|---|---|---|---|---|---|"]
    for cap, r in res["captures"].items():
        for name in PATHS:
            d = r[name]
            ratio = f"{r['--precision float32']['median_s'] / d['median_s']:.2f}×"
            L.append(f"| {cap} | {name} | {d['median_s']:.2f} | {', '.join(f'{x:.2f}' for x in d['wall_s'])} | "
                     f"{d['peak_mb']:.0f} | {ratio} | {d['plan']} |")
    L.append("")
    out.write_text("\n".join(L) + "\n", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--size", type=int, default=1000, help="side of the simulated Bayer capture (default 1000)")
    p.add_argument("--spikezoo", type=Path, default=None, help="folder holding the unpacked spikezoo wheel (optional)")
    p.add_argument("--out", type=Path, default=None, help="results folder (default: print only)")
    a = p.parse_args(argv)
    t_start = time.time()
    res = {"machine": machine(), "repeats": a.repeats, "captures": {}}
    with tempfile.TemporaryDirectory() as d:
        big = simulate(a.size, Path(d))
        res["captures"][f"{a.size}×{a.size} Bayer (simulated demo)"] = bench(big, [], a.repeats)
    if a.spikezoo is not None:
        clips = sorted(a.spikezoo.glob("**/spike/*.dat"))
        if clips:
            res["captures"][f"400×250 mono (Spike-Zoo {clips[0].stem})"] = bench(
                clips[0], ["--width", "400", "--height", "250", "--cfa", "none", "--flip-vertical"], a.repeats)
        else:
            print(f"note: no Spike-Zoo clips under {a.spikezoo}", file=sys.stderr)
    for cap, r in res["captures"].items():
        print(f"{cap}: defaults {r['defaults']['median_s']:.2f} s, float32 {r['--precision float32']['median_s']:.2f} s "
              f"({r['ratio']:.2f}×), peak {r['defaults']['peak_mb']:.0f} MB")
    return save_results(res, a.out, "cli", write_report, t_start)


if __name__ == "__main__":
    raise SystemExit(main())
