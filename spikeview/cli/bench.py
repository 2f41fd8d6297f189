"""``spikeview bench``: error against run time of every method (:mod:`spikeview.bench`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from spikeview.errors import ParameterError


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="64x64, 2 scenes, fewer steps: a smoke run (minutes, not written unless --out)")
    p.add_argument("--size", type=int, help="frame size of the synthetic set (default 256)")
    p.add_argument("--frames", type=int, default=2, help="windows per scene (default 2)")
    p.add_argument("--out", metavar="DIR", help="folder for guided.md, guided.json and guided_pareto.png (default benchmarks/results)")
    p.add_argument("--real", nargs="+", metavar="FILE",
                   help="score real captures (no truth): detail against the capture's long exposure, patchiness, "
                        "residual noise and NIQE (no-reference, lower is better; the long exposure's too) of TFP, TFI and "
                        "the guided default, through `spikeview reconstruct` (spikeview.bench.lowlight)")
    p.add_argument("--low-light", action="store_true",
                   help="simulated scenes at 3 light levels and 2 pans (mono and RGGB) with truth: PSNR, detail, patchiness, "
                        "residual noise and NIQE, with the truth's NIQE beside them (spikeview.bench.lowlight)")
    p.add_argument("--sequences", action="store_true",
                   help="only the sequences benchmark: back-to-back windows of static, slow and fast scenes, PSNR/SSIM and temporal error (temporal.md)")


#: the frame sizes the benchmark's scenes can be made at (smaller: too few pixels for the prior's tiles and the
#: scores' windows; larger: more memory than a bench needs)
SIZE_RANGE = (32, 4096)


def run(args: argparse.Namespace) -> int:
    from spikeview.bench.guided import main as bench_main

    if args.frames < 1:
        raise ParameterError(f"--frames {args.frames} is not valid: give 1 or more windows per scene.")
    if args.size is not None and not (SIZE_RANGE[0] <= args.size <= SIZE_RANGE[1] and args.size % 2 == 0):
        raise ParameterError(f"--size {args.size} is not valid: give an even frame size from {SIZE_RANGE[0]} to "
                             f"{SIZE_RANGE[1]} pixels.")

    if getattr(args, "real", None) or getattr(args, "low_light", False):
        return _lowlight(args)
    argv = ["--frames", str(args.frames)]
    if args.quick:
        argv.append("--quick")
    if getattr(args, "sequences", False):
        argv.append("--sequences")
    if args.size is not None:
        argv += ["--size", str(args.size)]
    if args.out:
        if not Path(args.out).is_dir():
            raise ParameterError(f"--out {args.out}: folder not found; create it first.")
        argv += ["--out", args.out]
    return bench_main(argv)


def _lowlight(args: argparse.Namespace) -> int:
    from spikeview.bench.lowlight import report, run_low_light, run_real

    if args.out and not Path(args.out).is_dir():
        raise ParameterError(f"--out {args.out}: folder not found; create it first.")
    text = []
    if args.real:
        for f in args.real:
            if not Path(f).is_file():
                raise ParameterError(f"--real {f}: file not found; name a spike capture (.dat, .npy, .npz).")
        text.append(report(run_real(list(args.real)), "Real captures (reference: the capture's long exposure)"))
    if args.low_light:
        text.append(report(run_low_light(size=args.size or 256), "Simulated low light (static scenes, reference: the truth)"))
    out = "\n\n".join(text)
    print(out)
    if args.out:
        import os
        import platform

        from spikeview.bench.lowlight import __doc__ as how
        from spikeview.guided.device import cpu_model
        from spikeview.guided.precision import cpu_flags

        flags = " ".join(f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in cpu_flags()) or "no avx2"
        head = ("# Low light and real captures: scores a blur cannot win\n\n"
                f"Machine: {cpu_model()} ({flags}), {os.cpu_count()} CPU cores, Python {platform.python_version()}. "
                f"Command: `spikeview bench{' --low-light' if args.low_light else ''}"
                f"{' --real ' + ' '.join(Path(f).name for f in args.real) if args.real else ''} --out DIR`.\n\n"
                + "**What runs" + how.split("**What runs", 1)[1].rstrip() + "\n\n")
        out = head + out
        (Path(args.out) / "lowlight.md").write_text(out + "\n", encoding="utf-8")
    return 0
