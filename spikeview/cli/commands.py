"""Sub-commands of the ``spikeview`` CLI. Each has ``add_args(parser)`` and ``run(args) -> int``.

Heavy modules are imported inside ``run`` only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spikeview.errors import ParameterError


def geometry(fn):
    """Mark an ``add_args`` function whose command reads a spike file (adds the geometry flags)."""
    fn.geometry = True
    return fn


def progress(total: int, desc: str, unit: str = "frame"):
    """A tqdm progress bar on stderr (hidden for a single item and when stderr is not a terminal)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True,
                disable=total <= 1 or not sys.stderr.isatty())


def add_overwrite_flag(p: argparse.ArgumentParser) -> None:
    """``--overwrite``: replace existing outputs (inputs are never replaced)."""
    p.add_argument("--overwrite", action="store_true",
                   help="replace output files that already exist (an input file is never replaced)")


# ----------------------------------------------------------------------------------- info
@geometry
def add_info_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="FILE", help="spike file (.dat, raw camera stream, .npy/.npz)")
    p.add_argument("--sample-windows", type=int, default=64,
                   help="number of windows spread over the file used for firing-rate statistics (default 64)")


def run_info(args: argparse.Namespace) -> int:
    from spikeview.cli.info import describe

    from spikeview.cli.main import _open_from_args

    args._shows_warnings = True
    with _open_from_args(args) as src:
        print(describe(src, sample_windows=args.sample_windows))
    return 0


# ------------------------------------------------------------------------------ reconstruct
@geometry
def add_reconstruct_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="INPUT", help="spike file (.dat, raw camera stream, .npy/.npz)")
    when = p.add_mutually_exclusive_group()
    when.add_argument("--at", type=int, metavar="T", help="reconstruct the one window centred on tick T")
    when.add_argument("--range", metavar="A:B[:STEP]",
                      help="windows centred on A, A+STEP, ... below B (STEP defaults to the window length)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output: .npy, .mp4, or an .exr/.png pattern with a frame number such as frame_%%04d.exr")
    p.add_argument("--preset", metavar="FILE",
                   help="a recipe TOML (written beside earlier outputs, or saved by the app) to re-run; flags given override it")
    add_overwrite_flag(p)
    from spikeview.recipe import add_flags

    add_flags(p, ("run", "classical", "guided", "export"))
    from spikeview.cli.batch import add_args as add_batch_args

    add_batch_args(p)


def run_reconstruct(args: argparse.Namespace) -> int:
    from spikeview.cli.reconstruct import run

    return run(args)


# ----------------------------------------------------------------------------------- export
def add_export_args(p: argparse.ArgumentParser) -> None:
    from spikeview.cli.export_cmd import add_args

    add_args(p)


def run_export(args: argparse.Namespace) -> int:
    from spikeview.cli.export_cmd import run

    return run(args)


# ------------------------------------------------------------------------------- simulate
def add_simulate_args(p: argparse.ArgumentParser) -> None:
    from spikeview.cli.simulate import add_args

    add_args(p)


def run_simulate(args: argparse.Namespace) -> int:
    from spikeview.cli.simulate import run

    return run(args)


# ------------------------------------------------------------------------------------ app
def add_app_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="FILE", help="capture to open (default: the built-in demo capture)")


def run_app(args: argparse.Namespace) -> int:
    try:
        from spikeview.gui.app import run_app as _run
    except ImportError as e:
        raise ParameterError(f"the desktop app is not available in this installation ({e}); use the sub-commands (spikeview --help).") from None
    return _run(args.input)


# ---------------------------------------------------------------------------------- bench
def add_bench_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="64x64, 2 scenes, fewer steps: a smoke run (minutes, not written unless --out)")
    p.add_argument("--size", type=int, help="frame size of the synthetic set (default 256)")
    p.add_argument("--frames", type=int, default=2, help="windows per scene (default 2)")
    p.add_argument("--out", metavar="DIR", help="folder for guided.md, guided.json and guided_pareto.png (default benchmarks/results)")


def run_bench(args: argparse.Namespace) -> int:
    from spikeview.bench.guided import main as bench_main

    argv = ["--frames", str(args.frames)]
    if args.quick:
        argv.append("--quick")
    if args.size:
        argv += ["--size", str(args.size)]
    if args.out:
        if not Path(args.out).is_dir():
            raise ParameterError(f"--out {args.out}: folder not found; create it first.")
        argv += ["--out", args.out]
    return bench_main(argv)


COMMANDS = {
    "app": ("open the desktop app (the default when no command is given)", add_app_args, run_app),
    "info": ("describe a spike file: format, geometry, duration, per-channel firing rates", add_info_args, run_info),
    "simulate": ("simulate a chromatic spike capture (with ground truth) from a video, images or the demo scene",
                 add_simulate_args, run_simulate),
    "reconstruct": ("reconstruct frames from spikes and export them (.npy, .exr, .png, .mp4)", add_reconstruct_args, run_reconstruct),
    "export": ("export a .zarr store of a long capture to .mp4, .npy, .exr or .png", add_export_args, run_export),
    "bench": ("error against run time of TFP, TFI, the strong baseline and the guided sampler (PSNR/SSIM vs. ground truth)",
              add_bench_args, run_bench),
}

EPILOGS = {
    "info": "example:\n  spikeview info capture.dat --width 1000 --height 1000 --cfa BGGR\n",
    "reconstruct": (
        "examples:\n"
        "  spikeview reconstruct demo.dat --method tfp --at 1000 --out frame.png\n"
        "  spikeview reconstruct demo.dat --method tfi --range 0:2000:20 --out frames/f_%04d.exr\n"
        "  spikeview reconstruct demo.dat --range 0:4000:10 --out clip.mp4 --fps 30\n"
        "  spikeview reconstruct demo.dat --method guided --at 1000 --out guided.exr\n"
        "  spikeview reconstruct demo.dat --method guided --guidance dps --s 0.5 --steps 20 --range 0:400:40 --out g_%04d.exr\n"
        "  spikeview reconstruct demo.dat --preset guided.exr.preset.toml --out again.exr\n"
        "  spikeview reconstruct demo.dat --range 0:40000:20 --out clip.zarr --cluster local:2   (then --resume)\n"
    ),
    "export": "example:\n  spikeview export clip.zarr --out clip.mp4 --fps 30\n",
}
