"""``spikeview calibrate [--dark DARK] [--flat FLAT] [geometry flags] --out PROFILE.toml``: a camera profile.

From a dark capture (lens capped) and/or a flat capture (a uniform white or gray target, not saturated) of the same
camera, read with the same geometry flags, it writes the profile (TOML, with its per-photosite maps in an ``.npz``
beside it) that ``--camera PROFILE.toml`` applies on ``info`` and ``reconstruct``: the dark rate and hot pixels,
the flat field and the colour response (:mod:`spikeview.classical.calibration`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

#: the command reads spike files: the geometry flags are added (they apply to both captures)
GEOMETRY = True
EPILOG = ("examples:\n  spikeview calibrate --dark dark.dat --flat flat.dat --out cam.toml\n"
          "  spikeview reconstruct capture.dat --camera cam.toml --white-balance profile --out frame.png\n")


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dark", metavar="DARK", help="a capture with the lens capped (dark rate, hot pixels)")
    p.add_argument("--flat", metavar="FLAT", help="a capture of a uniform white or gray target, out of focus and not "
                                                  "saturated (flat field, colour response)")
    p.add_argument("--out", required=True, metavar="PROFILE.toml",
                   help="the profile to write (its maps go to PROFILE.npz beside it)")
    from spikeview.cli._common import add_overwrite_flag

    add_overwrite_flag(p)


def run(args: argparse.Namespace) -> int:
    from spikeview._files import check_writable
    from spikeview.classical.calibration import measure
    from spikeview.cli._common import open_source_from_args
    from spikeview.errors import ParameterError

    if getattr(args, "camera", None) is not None:
        raise ParameterError("spikeview calibrate makes a camera profile: --camera applies a profile on info and "
                             "reconstruct; leave it out here.")
    if args.dark is None and args.flat is None:
        raise ParameterError("spikeview calibrate needs a dark capture (--dark DARK) and/or a flat capture (--flat FLAT).")
    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise ParameterError(f"--out {out}: a camera profile is a .toml file (e.g. --out camera.toml).")
    from spikeview.export.base import check_output_folder

    check_output_folder(out)
    inputs = [Path(p) for p in (args.dark, args.flat) if p is not None]
    for path in (out, out.with_suffix(".npz")):
        check_writable(path, bool(args.overwrite), inputs)
    sources = {}
    try:
        for name in ("dark", "flat"):
            path = getattr(args, name)
            if path is not None:
                args.input = path
                sources[name] = open_source_from_args(args, writes=True)
        profile = measure(sources.get("dark"), sources.get("flat"))
    finally:
        for s in sources.values():
            s.close()
    profile.save(out)
    st = profile.stats
    if "dark" in sources:
        print(f"dark: {st['dark_rate_mean']:.4g} spikes/tick on average (σ {st['dark_rate_sigma']:.2g}), "
              f"{st['hot_pixels']} hot pixel(s) above {st['hot_limit']:.3g} spikes/tick", file=sys.stderr)
    if "flat" in sources:
        rates = ", ".join(f"{k} {v:.3f}" for k, v in st["flat_rate"].items())
        print(f"flat: {rates} spikes/tick; gain σ {st['gain_std']:.3g} across photosites", file=sys.stderr)
    print(profile.describe())
    print(f"wrote {out} and {out.with_suffix('.npz').name}; use it with --camera {out}")
    return 0
