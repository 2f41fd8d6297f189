"""``spikeview reconstruct``: spikes → frames → export, with a reproducible preset.

The settings are one :class:`~spikeview.recipe.Recipe`: the defaults, then ``--preset FILE`` (a
recipe TOML, e.g. the ``<out>.preset.toml`` every run writes beside its outputs, or one the app
saved), then the flags given on the command line (generated from :data:`spikeview.recipe.PARAMS`).
The frames come from :func:`spikeview.pipeline.write_sequence`, the same function the app's export
calls, so the same recipe gives the same pixels in both.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from spikeview.recipe import BY_PATH, PARAMS, Recipe, StreamTable, apply_flags, given_flags

_PATTERN = re.compile(r"[_.\-]?%0?\d*d")
#: geometry flags that fill the recipe's ``[stream]`` table
STREAM_FLAGS = ("format", "width", "height", "cfa", "flip_vertical", "flip_horizontal", "tick_rate", "layout")


def preset_path(out: Path) -> Path:
    """``clip.mp4`` → ``clip.mp4.preset.toml``; ``frames/f_%04d.exr`` → ``frames/f.exr.preset.toml``."""
    return out.with_name(_PATTERN.sub("", out.name) + ".preset.toml")


def recipe_from_args(args: argparse.Namespace, base: Recipe | None = None) -> Recipe:
    """Defaults (or ``base``) ← ``--preset`` ← the flags given (errors name the flag or the file)."""
    if base is not None:
        recipe = base
    else:
        recipe = Recipe.load(args.preset) if getattr(args, "preset", None) else Recipe()
    stream = {k: getattr(args, k) for k in STREAM_FLAGS if getattr(args, k, None) is not None}
    if stream:
        recipe = recipe.with_values({f"stream.{k}": v for k, v in stream.items()})
    recipe = apply_flags(recipe, args)
    if getattr(args, "at", None) is not None or getattr(args, "range", None) is not None:
        recipe = recipe.with_values({"run.at": args.at, "run.range": args.range})
    return recipe


def open_stream(args: argparse.Namespace, recipe: Recipe):
    """The source, read with the recipe's ``[stream]`` (flags already folded in)."""
    from spikeview.cli.main import _open_from_args

    for key, value in recipe.stream.open_kwargs().items():
        setattr(args, key, value)
    return _open_from_args(args)


def inactive_notes(recipe: Recipe, args: argparse.Namespace, source: Any, centre: int, state: Any) -> list[str]:
    """One sentence for every flag the user gave that cannot act on this run (and why)."""
    given = given_flags(args)
    notes = []
    if recipe.run.method != "guided":
        for path in sorted(given):
            if path.startswith("guided."):
                notes.append(f"{BY_PATH[path].flag} applies to --method guided only; it is ignored by --method {recipe.run.method}.")
        return notes
    from spikeview.guided import Observation, make_plan
    from spikeview.guided.knobs import knob_status

    obs = Observation.from_source(source, centre, recipe.guided.window, alpha=state.alpha, eta=recipe.guided.eta)
    plan = make_plan(obs, recipe.guided)
    print(plan, file=sys.stderr)
    for path, why in knob_status(recipe.guided, plan).items():
        if why and path in given:
            notes.append(f"{BY_PATH[path].flag} has no effect here: {why}.")
    return notes


def run(args: argparse.Namespace) -> int:
    from spikeview.cli.batch import run_zarr, wants_zarr

    if wants_zarr(args):  # a .zarr output: the chunked, resumable batch path
        return run_zarr(args)
    from spikeview.cli.commands import progress
    from spikeview.export import describe_slow_motion, slow_motion_factor
    from spikeview.pipeline import prepare_sequence, recipe_for_state, window_centres, write_sequence

    recipe = recipe_from_args(args)
    out = Path(args.out)
    src = open_stream(args, recipe)
    with src:
        recipe = recipe.with_values({f"stream.{k}": v for k, v in StreamTable.from_info(src.info, getattr(args, "layout", None)).to_dict().items()})
        centres, step = window_centres(recipe, src.n_frames)
        if recipe.run.range is not None:
            a, b, _ = _parse(recipe.run.range, step)
            if b > src.n_frames:
                print(f"note: --range {recipe.run.range} ends past the stream's last tick ({src.n_frames - 1}); "
                      f"the last window is centred on tick {centres[-1]}.", file=sys.stderr)
        state = prepare_sequence(src, recipe)
        recipe = recipe_for_state(recipe, state)
        how = "set by --white" if "export.white" in given_flags(args) else (
            "from the preset" if getattr(args, "preset", None) and state.white is not None and
            recipe.export.white != state.white else "the 99.9th percentile of the sequence's corrected rates")
        print(f"white point {recipe.export.white:.4g} ({how}): EXR keeps values above it, npy/PNG/MP4 map it to full scale.",
              file=sys.stderr)
        for note in inactive_notes(recipe, args, src, centres[0], state):
            print(f"note: {note}", file=sys.stderr)
        if out.suffix.lower() == ".mp4":
            factor = slow_motion_factor(src.tick_rate, step, recipe.export.fps)
            print(f"{len(centres)} frames, one per {step} ticks, at {recipe.export.fps:g} fps: {describe_slow_motion(factor)}",
                  file=sys.stderr)
        guided = recipe.run.method == "guided"
        total = len(centres) * (max(1, recipe.guided.steps) if guided else 1)
        with progress(total, f"{recipe.run.method} → {out.name}", unit="step" if guided else "frame") as bar:
            def on_step(fi: int, n: int, step_i: int, steps: int, preview: Any) -> None:
                bar.update(1)

            write_sequence(src, recipe, centres, out, state=state, step=step, callback=on_step,
                           overwrite=bool(getattr(args, "overwrite", False)), inputs=[getattr(args, "preset", None)],
                           extra_outputs=[preset_path(out)], announce=lambda text: print(text, file=sys.stderr))
        _write_preset(out, recipe, src)
    print(f"wrote {len(centres)} frame{'s' if len(centres) != 1 else ''} to {out}; settings in {preset_path(out)}")
    return 0


def _parse(text: str, step: int) -> tuple[int, int, int]:
    from spikeview.pipeline import parse_range

    return parse_range(text, step)


def _write_preset(out: Path, recipe: Recipe, src: Any) -> Path:
    """The recipe beside the output (``<out>.preset.toml``; checked with the output before any work:
    never an input, replaced only with ``--overwrite``); ``--preset`` re-runs it exactly."""
    path = preset_path(out)
    return recipe.save(path, header=f"# spikeview reconstruct preset for {src.info.path}")


__all__ = ["PARAMS", "preset_path", "recipe_from_args", "run"]
