"""What the sub-commands share: progress, the overwrite flag, the geometry flags, opening a source,
reading a recipe from the flags, and the optional-extra check.

Light on purpose (argparse only at import): every command module imports from here, never from
another command, so the CLI has no import circles (:mod:`spikeview.cli.commands` is the registry).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import typing
from pathlib import Path
from typing import Any

#: what a command whose ``GEOMETRY`` is true accepts besides the ``[stream]`` table's flags
TAG_CHECK_HELP = ("raw 1000x1000 streams: match the full tag sequence (default) or only the frame-start tag and "
                  "valid line numbers")


def progress(total: int, desc: str, unit: str = "frame"):
    """A tqdm progress bar on stderr (hidden for a single item and when stderr is not a terminal)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True,
                disable=total <= 1 or not sys.stderr.isatty())


def add_overwrite_flag(p: argparse.ArgumentParser) -> None:
    """``--overwrite``: replace existing outputs (inputs are never replaced)."""
    p.add_argument("--overwrite", action="store_true",
                   help="replace output files that already exist (an input file is never replaced)")


def add_geometry_flags(p: argparse.ArgumentParser) -> None:
    """One flag per field of the recipe's ``[stream]`` table (:class:`~spikeview.recipe.StreamTable`),
    plus ``--tag-check`` for raw 1000×1000 streams."""
    from spikeview.recipe import StreamTable

    g = p.add_argument_group("stream geometry (override the sidecar; needed for files without one)")
    hints = typing.get_type_hints(StreamTable)
    for f in dataclasses.fields(StreamTable):
        flag, meta = "--" + f.name.replace("_", "-"), f.metadata
        kind = next(a for a in typing.get_args(hints[f.name]) if a is not type(None))
        if kind is bool:
            g.add_argument(flag, action=argparse.BooleanOptionalAction, default=None, help=meta["help"])
        elif "choices" in meta:
            g.add_argument(flag, choices=list(meta["choices"]), help=meta["help"])
        else:
            g.add_argument(flag, type=kind, metavar=meta.get("metavar"), help=meta["help"])
    g.add_argument("--tag-check", choices=["sequence", "lenient"], help=TAG_CHECK_HELP)
    g.add_argument("--keep-geometry", action="store_true",
                   help="write frames at the given --width/--height even where the firing rates say the rows are sheared "
                        "and point to another frame size (refused without it)")


def open_source_from_args(args: argparse.Namespace, recipe: Any = None, *, show_warnings: bool = True,
                          writes: bool = False):
    """The source ``args.input`` names, read with the geometry flags (or ``recipe``'s ``[stream]``, flags
    already folded in); the stream's warnings (a truncated file, a doubtful width or CFA) are said on
    stderr before the work unless ``show_warnings`` is false (``info`` lists them itself).

    ``writes``: the command writes what it reads (frames, a profile): a width whose rows the firing rates show
    sheared, where another frame size lines them up (``info.likely_size``), is refused in one sentence naming the
    size and ``--keep-geometry`` (nothing is written)."""
    from spikeview.io import open_source
    from spikeview.recipe import StreamTable

    names = [f.name for f in dataclasses.fields(StreamTable) if f.name != "camera"]
    given = ({k: getattr(args, k, None) for k in names} if recipe is None else recipe.stream.open_kwargs())
    kwargs = {k: v for k, v in given.items() if v is not None or k != "cfa"}
    kwargs["tag_check"] = getattr(args, "tag_check", None)
    src = open_source(args.input, **kwargs)
    camera = getattr(args, "camera", None) if recipe is None else recipe.stream.camera
    # the profile's corrections travel with the source (spikeview.classical.calibration); without one, the capture's
    # own hot photosites (spikeview.classical.defects)
    from spikeview.classical.calibration import attach

    try:
        likely = src.info.likely_size
        if writes and likely is not None and not getattr(args, "keep_geometry", False):
            from spikeview.errors import ParameterError

            name = src.info.path.name if src.info.path else args.input
            raise ParameterError(
                f"{name}: the rows do not line up at {src.width}x{src.height} (the frames would come out sheared); judging "
                f"by the spikes the frames are {likely[0]}x{likely[1]}: run with --width {likely[0]} --height {likely[1]} "
                "(or add --keep-geometry to write them as given).")
        attach(src, camera)
    except BaseException:
        src.close()
        raise
    if show_warnings:
        for note in src.info.warnings:
            print(f"spikeview: warning: {src.info.path.name if src.info.path else args.input}: {note}", file=sys.stderr)
    return src


def recipe_from_args(args: argparse.Namespace, base: Any = None):
    """Defaults (or ``base``) ← ``--preset`` ← the geometry flags ← the recipe flags given ← ``--at``/``--range``
    (errors name the flag or the file)."""
    from spikeview.recipe import Recipe, StreamTable, apply_flags

    if base is not None:
        recipe = base
    elif getattr(args, "preset", None):
        recipe = preset_for_input(Recipe.load(args.preset), Path(args.preset), args)
    else:
        recipe = Recipe()
    names = [f.name for f in dataclasses.fields(StreamTable)]
    stream = {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
    if stream:
        recipe = recipe.with_values({f"stream.{k}": v for k, v in stream.items()})
    recipe = apply_flags(recipe, args)
    if getattr(args, "at", None) is not None or getattr(args, "range", None) is not None:
        recipe = recipe.with_values({"run.at": args.at, "run.range": args.range})
    return recipe


def preset_for_input(recipe: Any, preset: Path, args: argparse.Namespace):
    """A preset's ``[stream]`` table checked against the input it is now used on.

    The geometry flags given win over everything. A preset written for this file (its header line
    names a file of the input's name) is used as recorded: it re-runs exactly. A preset written for
    another file (or naming none) whose ``[stream]`` disagrees with the input's own sidecar describes
    another file: the sidecar wins, said in one note with the flags that choose otherwise. Without a
    sidecar the preset's table reads the file, with a note when the preset names another file.
    """
    import math

    from spikeview.cfa import cfa_to_str, parse_cfa
    from spikeview.io.sidecar import read_sidecar
    from spikeview.recipe import StreamTable

    table = recipe.stream.open_kwargs()
    table.pop("layout", None)
    flags = {k for k in table if getattr(args, k, None) is not None}
    mine = {k: v for k, v in table.items() if k not in flags}
    src = Path(getattr(args, "input", "") or "")
    if not mine or not src.is_file():
        return recipe
    try:
        first = preset.read_text(errors="replace").splitlines()[0]
    except (OSError, IndexError):
        first = ""
    marker = "preset for "
    named = Path(first.split(marker, 1)[1].strip()).name if marker in first else ""
    if named == src.name:
        return recipe  # this file's own preset: how it was read then (flags may have overridden the sidecar)
    side = read_sidecar(src)  # a damaged sidecar says so itself, naming it
    if side is not None and side.stream is not None:
        def same(k: str, a: Any, b: Any) -> bool:
            if k == "cfa":
                return cfa_to_str(parse_cfa(a)) == cfa_to_str(parse_cfa(b))
            if k == "tick_rate":
                return math.isclose(float(a), float(b), rel_tol=1e-9)
            return a == b

        diff = {k: (v, getattr(side.stream, k)) for k, v in mine.items() if not same(k, v, getattr(side.stream, k))}
        if diff:
            there = ", ".join(f"{k} = {a!r}" for k, (a, _) in diff.items())
            here = ", ".join(f"{k} = {b!r}" for k, (_, b) in diff.items())
            wins = " ".join("--" + k.replace("_", "-") for k in diff)
            print(f"note: {preset.name}'s [stream] table describes another file ({there}), not {src.name}, whose "
                  f"sidecar says {here}; {src.name} is read by its sidecar (give {wins} to choose otherwise).",
                  file=sys.stderr)
            return dataclasses.replace(recipe, stream=dataclasses.replace(recipe.stream, **{k: None for k in diff}))
        return recipe
    if named:
        shown = ", ".join(f"{k} = {v!r}" for k, v in mine.items())
        print(f"note: {preset.name} was written for {named}; its [stream] table ({shown}) is used to read "
              f"{src.name}, which has no sidecar (give the geometry flags, e.g. --width/--height/--cfa, if "
              f"{src.name} differs).", file=sys.stderr)
    return recipe


def preset_path(out: Path) -> Path:
    """``clip.mp4`` → ``clip.mp4.preset.toml``; ``frames/f_%04d.exr`` → ``frames/f.exr.preset.toml``."""
    from spikeview.export.base import strip_frame_field

    return out.with_name(strip_frame_field(out.name) + ".preset.toml")


def require_extra() -> None:
    """Stop with one sentence naming ``pip install spikeview[cluster]`` when dask/zarr are missing."""
    from spikeview.cluster.reconstruct import require_extra as require

    require()
