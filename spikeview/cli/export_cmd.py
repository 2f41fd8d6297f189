"""``spikeview export OUT.zarr --out clip.mp4 | frames_%04d.exr | frames.npy``: a batch store to the usual formats.

The export settings (fps, levels, compression…) come from the recipe stored in the Zarr store;
flags given on the command line override them. The store holds linear frames; each output maps them by
the store's white point exactly as ``spikeview reconstruct`` does (``.npy`` clipped to [0, 1], PNG/MP4
full scale at the white point, EXR linear), so an export equals the plain run's file. The store is
checked first (:func:`spikeview.cluster.store.check_store`); frames are read chunk by chunk (bounded
memory), a damaged chunk is named with its windows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spikeview.cli._common import add_overwrite_flag, preset_path, progress, require_extra
from spikeview.errors import ParameterError

EPILOG = "example:\n  spikeview export clip.zarr --out clip.mp4 --fps 30\n"


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", metavar="STORE", help="a .zarr store written by spikeview reconstruct … --out STORE.zarr")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output: .mp4, .npy, or an .exr/.png pattern with a frame number such as frame_%%04d.exr")
    p.add_argument("--fps", type=float, help="output frame rate of .mp4 files (default: the store's recipe)")
    p.add_argument("--compression", choices=["zip", "piz", "none"], help="EXR compression (default: the store's recipe)")
    add_overwrite_flag(p)


def run(args: argparse.Namespace) -> int:
    require_extra()
    import tomllib

    from spikeview.cluster.store import check_store
    from spikeview.export import ExportMetadata, describe_slow_motion, open_exporter, slow_motion_factor
    from spikeview.recipe import Recipe

    store = Path(args.store)
    if store.suffix.lower() != ".zarr":
        raise ParameterError(f"{store}: spikeview export reads a .zarr store; other files are exported by spikeview reconstruct.")
    check = check_store(store)  # layout, arrays, every attribute and their consistency, before anything is read
    group, attrs, done = check.group, check.attrs, check.done
    if check.markers_lost or check.unreadable:
        which = "are missing or cannot be read" if check.markers_lost else (
            f"of chunk(s) {', '.join(map(str, check.unreadable))} cannot be read")
        raise ParameterError(f"{store.name}: its completion markers {which}; finish it with {check.rerun()} "
                             "(it recomputes those chunks).")
    if not done.all():
        raise ParameterError(f"{store.name} is incomplete ({int(done.sum())} of {done.size} chunks done); "
                             f"finish it with spikeview reconstruct {attrs.get('input', 'INPUT')} --out {store} --resume.")
    recipe = Recipe.from_dict(tomllib.loads(attrs["recipe"]), where=f"{store.name} (its recipe)")
    overrides = {f"export.{k}": getattr(args, k) for k in ("fps", "compression") if getattr(args, k) is not None}
    if overrides:
        recipe = recipe.with_values(overrides, names={f"export.{k[7:]}": f"--{k[7:]}" for k in overrides})
    ecfg = recipe.export
    method = attrs["method"]
    windows = group["window"][:]
    centres = group["centre_tick"][:]
    step = int(attrs["step"])
    meta = ExportMetadata(source=attrs["input"], method=method, tick_rate=float(attrs["tick_rate"]),
                          window=tuple(int(v) for v in windows[0]), centre_tick=int(centres[0]), step_ticks=step,
                          params=recipe.to_dict())
    frames = group["frames"]
    n, h, w, c = frames.shape
    shape = (h, w, 3) if c == 3 else (h, w)
    out = Path(args.out)
    from spikeview._files import check_writable
    from spikeview.export.base import check_output_folder

    # the output's folder and the files it would replace, before any informational line (as reconstruct does)
    check_output_folder(out)
    if "%" not in out.name:
        check_writable(out, bool(args.overwrite), [store])
    check_writable(preset_path(out), bool(args.overwrite), [store], owner=None if "%" in out.name else out)
    if out.suffix.lower() == ".mp4":
        print(f"{n} frames, one per {step} ticks, at {ecfg.fps:g} fps: "
              f"{describe_slow_motion(slow_motion_factor(float(attrs['tick_rate']), step, ecfg.fps))}", file=sys.stderr)
    chunk = int(attrs["chunk"])
    from spikeview.cluster._compute import state_from_attrs
    from spikeview.pipeline import exposure_mapping, white_point_line

    # the store holds linear frames; the output maps them by the white point, as reconstruct does
    state = state_from_attrs(attrs)
    ecfg, expose = exposure_mapping(recipe, state, out)
    print(white_point_line(recipe, state, f"recorded in {store.name}"), file=sys.stderr)
    for i in range(check.n_chunks):  # every chunk decodes before the first frame is written (no partial output)
        check.read_chunk(i)
    with open_exporter(out, n, shape, ecfg, meta, overwrite=args.overwrite, inputs=[store],
                       extra_outputs=[preset_path(out)]) as ex, progress(n, f"{store.name} → {out.name}") as bar:
        for lo in range(0, n, chunk):
            block = check.read_chunk(lo // chunk)  # a damaged chunk: one sentence naming it and its windows
            for i, f in enumerate(block):
                ex.write(expose(f if c == 3 else f[..., 0]), window=tuple(int(v) for v in windows[lo + i]),
                         centre_tick=int(centres[lo + i]))
                bar.update(1)
    recipe.save(preset_path(out), header=f"# spikeview reconstruct preset for {attrs['input']}")
    print(f"wrote {n} frame{'s' if n != 1 else ''} to {out}; settings in {preset_path(out)}")
    return 0
