"""``spikeview simulate``: video, images or a still with motion → chromatic spikes + ground truth."""

from __future__ import annotations

import argparse
import glob
import re
import sys
from pathlib import Path

from spikeview.cli._common import add_overwrite_flag, progress
from spikeview.errors import InputFileError, ParameterError

NOISE_TERMS = ("dark_current", "prnu", "threshold_fpn", "shot_noise", "threshold_jitter", "reset_slowdown")


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="INPUT",
                   help="video file, folder or glob of images, or one still image (omit with --demo)")
    p.add_argument("--demo", action="store_true", help="simulate the built-in demo scene (no input file needed)")
    p.add_argument("--out", required=True, metavar="OUT.dat",
                   help="spike file to write; OUT.dat.toml (sidecar) and OUT.gt.npz (ground truth) go beside it")
    p.add_argument("--config", metavar="FILE", help="a TOML simulation config (e.g. the [simulation] table of a sidecar)")
    add_overwrite_flag(p)
    g = p.add_argument_group("sensor")
    g.add_argument("--ticks", type=int, help="number of readouts to simulate (default 2000 = 0.1 s at 20 kHz)")
    g.add_argument("--size", type=int, metavar="N", help="output N x N pixels (--width/--height for other shapes)")
    g.add_argument("--width", type=int, help="output width in pixels (default: the input's)")
    g.add_argument("--height", type=int, help="output height in pixels (default: the input's)")
    g.add_argument("--rate", type=float, help="spikes per tick at intensity 1 (default 0.6)")
    g.add_argument("--cfa", metavar="{RGGB,BGGR,GRBG,GBRG,none}", help="colour filter of the simulated sensor (default RGGB)")
    g.add_argument("--tick-rate", type=float, help="readouts per second (default 20000)")
    g.add_argument("--seed", type=int, help="random seed (same seed, same bytes)")
    g.add_argument("--gt-every", type=int, help="ticks between ground-truth frames (default 50, which keeps the ground truth smaller than the capture)")
    g.add_argument("--fps", type=float, help="frame rate of an image-sequence input (frames per second)")
    g.add_argument("--flip-vertical", action=argparse.BooleanOptionalAction, default=None,
                   help="store rows upside down like the camera toolkits (default on)")
    n = p.add_argument_group("noise (all on by default)")
    n.add_argument("--noise", action=argparse.BooleanOptionalAction, default=None, help="switch every noise term at once")
    for term in NOISE_TERMS:
        n.add_argument(f"--{term.replace('_', '-')}", action=argparse.BooleanOptionalAction, default=None,
                       help=f"{term.replace('_', ' ')} on/off")
    m = p.add_argument_group("synthetic motion of a still image (and the demo)")
    m.add_argument("--pan", type=float, nargs=2, metavar=("VX", "VY"), help="content velocity in pixels per second")
    m.add_argument("--zoom", type=float, help="scale factor per second (1 = none)")
    m.add_argument("--rotation", type=float, help="degrees per second, clockwise")
    m.add_argument("--fan", type=float, metavar="REV_PER_S", help="add a rotating three-blade fan at the centre (revolutions per second)")


#: SimConfig keys set by a flag of their own, and that flag
FLAG_OF = {"n_ticks": "--ticks", "width": "--width", "height": "--height", "rate": "--rate", "cfa": "--cfa",
           "tick_rate": "--tick-rate", "seed": "--seed", "gt_every": "--gt-every", "flip_vertical": "--flip-vertical"}
_SETTING_ERROR = re.compile(r"^Simulation setting '(\w+)' = (.*?) is invalid: (.*)$", re.S)


def _in_user_words(e: ParameterError, args: argparse.Namespace, given: dict[str, object]) -> ParameterError:
    """Name the flag (``--ticks 0``) or the config file the user wrote, not the internal key."""
    m = _SETTING_ERROR.match(str(e))
    if not m:
        return e
    key, value, fix = m.groups()
    if key in given and key in FLAG_OF:
        flag = FLAG_OF[key]
        if key in ("width", "height") and getattr(args, "size", None) is not None and getattr(args, key, None) is None:
            flag = "--size"  # the user typed --size N, not --width/--height
        return ParameterError(f"{flag} {given[key]} is not valid: {fix}")
    if args.config:
        return ParameterError(f"{args.config}: '{key}' = {value} is not valid: {fix}")
    return e


def _config(args: argparse.Namespace):
    from spikeview.sim import SimConfig

    if args.config:
        from spikeview.config import load_toml

        data = load_toml(args.config)
        if not data:
            raise ParameterError(f"{args.config}: the simulation config is empty; add settings such as "
                                 "n_ticks = 2000, or drop --config.")
        try:
            # a capture's sidecar holds the settings in its [simulation] table
            cfg = SimConfig.load(args.config, table="simulation") if isinstance(data.get("simulation"), dict) \
                else SimConfig.load(args.config)
        except ParameterError as e:
            raise _in_user_words(e, args, {}) from None
    else:
        cfg = SimConfig()
    changes: dict[str, object] = {}
    if args.size is not None:
        changes["width"] = changes["height"] = args.size
    for flag, key in (("ticks", "n_ticks"), ("width", "width"), ("height", "height"), ("rate", "rate"),
                      ("tick_rate", "tick_rate"), ("seed", "seed"), ("gt_every", "gt_every"),
                      ("flip_vertical", "flip_vertical")):
        value = getattr(args, flag)
        if value is not None:
            changes[key] = value
    if args.cfa is not None:
        changes["cfa"] = args.cfa
    if args.noise is not None:
        changes.update({t: args.noise for t in NOISE_TERMS})
    for term in NOISE_TERMS:
        value = getattr(args, term)
        if value is not None:
            changes[term] = value
    try:
        return SimConfig.from_dict({**cfg.to_dict(), **changes}, where="simulation settings")
    except ParameterError as e:
        raise _in_user_words(e, args, changes) from None


def _check_motion(args: argparse.Namespace) -> None:
    """The synthetic-motion flags are finite numbers (``--zoom`` above 0), or one sentence naming the flag."""
    import math

    values = [("--pan", v) for v in (args.pan or ())] + [
        (flag, getattr(args, name)) for flag, name in (("--zoom", "zoom"), ("--rotation", "rotation"), ("--fan", "fan"))
        if getattr(args, name) is not None]
    for flag, v in values:
        if not math.isfinite(v):
            raise ParameterError(f"{flag} {v:g} is not valid: give a finite number.")
    if args.zoom is not None and args.zoom <= 0:
        raise ParameterError(f"--zoom {args.zoom:g} is not valid: the scale factor per second must be above 0 "
                             "(1 = no zoom).")


def _scene(args: argparse.Namespace, cfg):
    from spikeview.sim import Fan, MotionScene, demo_scene, open_scene

    motion = args.pan is not None or args.zoom is not None or args.rotation is not None or args.fan is not None
    _check_motion(args)
    if args.demo:
        if args.input:
            raise ParameterError("give either an INPUT file or --demo, not both.")
        if motion:
            raise ParameterError("the demo scene has its own motion: --pan/--zoom/--rotation/--fan move a still image "
                                 "INPUT; leave them out with --demo.")
        size = cfg.width or cfg.height or 256
        if cfg.width and cfg.height and cfg.width != cfg.height:
            raise ParameterError("the demo scene is square: give --size N (or equal --width and --height).")
        return demo_scene(size=size, seed=cfg.seed)
    if not args.input:
        raise ParameterError("no input: give a video, an image folder/glob or an image, or use --demo.")
    path = Path(args.input)
    if not path.exists() and not glob.has_magic(str(args.input)):
        raise InputFileError(f"{path}: not found; check the path of the video, image or image folder.")
    if path.is_file() and path.suffix.lower() in (".dat", ".raw", ".npy", ".npz", ".bin"):
        raise ParameterError(f"{path}: is a spike capture, not a scene; simulate reads a video, an image or a folder "
                             f"of images (spikeview info {path.name} describes a capture).")
    if motion:
        if not path.is_file():
            raise ParameterError(f"{path}: synthetic motion (--pan/--zoom/--rotation/--fan) needs one still image "
                                 "file, not a folder or pattern.")
        size = (cfg.height, cfg.width) if cfg.width and cfg.height else None
        fans = [Fan(rev_per_s=args.fan)] if args.fan is not None else []
        return MotionScene(path, size, pan=tuple(args.pan or (0.0, 0.0)), zoom=1.0 if args.zoom is None else args.zoom,
                           rotation=args.rotation or 0.0, fans=fans)
    if path.is_dir():
        return _image_folder(path, args.fps)
    return open_scene(path, fps=args.fps)


def _image_folder(folder: Path, fps: float | None):
    """An image sequence from the image files of ``folder`` (by suffix), saying which files were skipped."""
    from spikeview.sim.images import list_image_files
    from spikeview.sim.scenes import ImageSequenceScene

    if fps is None:
        raise ParameterError(f"{folder}: an image sequence needs its frame rate; pass --fps (frames per second).")
    files = list_image_files(folder)  # only image suffixes; an error naming the folder when there are none
    used = set(files)
    by_suffix: dict[str, int] = {}
    for f in files:
        by_suffix[f.suffix.lower()] = by_suffix.get(f.suffix.lower(), 0) + 1
    if len(by_suffix) > 1:
        # frames of one sequence share a format; a different one is usually an export written there
        main = max(by_suffix, key=lambda k: (by_suffix[k], k))
        files = [f for f in files if f.suffix.lower() == main]
        used = set(files)
    skipped = sorted(f.name for f in folder.iterdir() if f.is_file() and f not in used and not f.name.startswith("."))
    if skipped:
        shown = ", ".join(skipped[:5]) + (f" and {len(skipped) - 5} more" if len(skipped) > 5 else "")
        print(f"spikeview: note: {folder}: read {len(files)} {files[0].suffix.lower()} images and skipped "
              f"{len(skipped)} other file{'s' if len(skipped) != 1 else ''}: {shown}", file=sys.stderr)
    return ImageSequenceScene(files, fps=fps)


def run(args: argparse.Namespace) -> int:
    from spikeview.sim import simulate_to_file

    cfg = _config(args)
    scene = _scene(args, cfg)
    out = Path(args.out)
    if out.suffix.lower() != ".dat":
        raise ParameterError(f"--out {out}: the simulator writes plain packed spike files; give a name ending in .dat.")
    bar = progress(cfg.n_ticks, f"simulate → {out.name}", unit="tick")
    last = [0]

    def on_progress(done: int, total: int) -> None:
        bar.update(done - last[0])
        last[0] = done

    inputs = [args.input, args.config] if args.input else [args.config]

    def announce(sentence: str) -> None:
        print(f"spikeview: {sentence}", file=sys.stderr)

    with bar:
        files = simulate_to_file(scene, cfg, out, progress=on_progress, overwrite=args.overwrite,
                                 inputs=inputs, announce=announce)
    info = files.info
    from spikeview._files import human_bytes

    print(f"wrote {files.dat} ({info.width}x{info.height}, {info.n_frames} ticks = {info.duration_s * 1e3:.1f} ms, "
          f"CFA {info.cfa or 'none'}, {human_bytes(files.dat.stat().st_size)}), sidecar {files.sidecar.name}, "
          f"ground truth {files.ground_truth.name} ({human_bytes(files.ground_truth.stat().st_size)})",
          file=sys.stdout)
    if info.cfa is not None and info.width % 2:  # written as asked, but no Bayer sensor has an odd width
        from spikeview.io.geometry import odd_width_warning

        print(f"spikeview: warning: {odd_width_warning(info.cfa, info.width)}", file=sys.stderr)
    return 0
