"""Parameter presets: the session's :class:`~spikeview.recipe.Recipe` as the TOML file the CLI reads.

A preset is a recipe (tables ``run``, ``stream``, ``classical``, ``guided``, ``export``; see
:mod:`spikeview.recipe`), the same file ``spikeview reconstruct`` writes beside its outputs
(``<out>.preset.toml``) and reads with ``--preset``: the app and the command line give the same
pixels for the same preset.

Saving fills ``[run]`` from the session (the current tick, or the marked range with one window per
step) and ``[stream]`` from the open capture. Loading a preset sets every control and keeps every
other field of the file (a field without a control, such as ``guided.data_steps``, is saved back
unchanged); its ``[stream]`` and ``[run]`` ticks are not applied to the open capture (the Stream
settings dialog changes the CFA and flip).

Settings only the app has (playback speed, loop, per-level residual view, the export format, which
the CLI takes from the output's suffix) are remembered in the app's settings, not in presets.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from spikeview.io import FORMATS
from spikeview.session.model import Session
from spikeview.recipe import Recipe, StreamTable


def session_recipe(session: Session) -> Recipe:
    """The session's recipe with ``[run]`` (tick or marked range) and ``[stream]`` (open capture) filled in."""
    recipe = session.recipe()
    values: dict[str, Any] = {}
    src = session.source
    if src is not None:
        if session.get("export_range") == "marked":
            lo, hi = session.marked_range()
            values.update({"run.at": None, "run.range": f"{lo}:{hi + 1}:{recipe.span()}"})
        else:
            values.update({"run.at": int(session.tick), "run.range": None})
        info = src.info
        if info.format in FORMATS:
            stream = StreamTable.from_info(info, recipe.stream.layout)
            values.update({f"stream.{k}": v for k, v in stream.to_dict().items()})
    if not values:
        return recipe
    # cached per (recipe, values): the export panel asks on every change, on the GUI thread (≈20 ms a build)
    key = repr(sorted(values.items()))
    cached = getattr(session, "_session_recipe_cache", None)
    if cached is not None and cached[0] is recipe and cached[1] == key:
        return cached[2]
    full = recipe.with_values(values)
    session._session_recipe_cache = (recipe, key, full)
    return full


def save_preset(session: Session, path: str | os.PathLike[str]) -> Path:
    """Write the session's recipe to ``path`` as TOML (atomically)."""
    return session_recipe(session).save(
        path, header="# spikeview parameter preset (read by the app and by `spikeview reconstruct --preset`)")


def load_preset(session: Session, path: str | os.PathLike[str]) -> None:
    """Load a preset (:meth:`Recipe.load <spikeview.recipe.Recipe.load>`, the CLI's ``--preset``) into the
    session as one undo step (nothing changes if any value is invalid)."""
    session.load_recipe(Recipe.load(path), label=f"Load preset {Path(path).name}")
