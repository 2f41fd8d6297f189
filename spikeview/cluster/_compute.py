"""The one adapter between the batch path and the reconstruction library.

Everything the batch path knows about *how* frames are made is in this file:

* :func:`prepare_state` — the sequence-wide quantities (colour cast α, white point), computed
  **once** before the work is split and handed to every chunk.
* :func:`compute_chunk` — the frames of a run of consecutive windows, given that state.
* :func:`worker_resources` — the source and the guided sampler of a worker process, opened / loaded
  once and cached (workers read the input from its file path; nothing large goes through the
  scheduler).

Settings travel as the *recipe* dict (:meth:`spikeview.recipe.Recipe.to_dict`, the preset's tables),
so they pickle cheaply and are exactly what the store records. Frames come from the one pipeline,
:func:`spikeview.pipeline.reconstruct_windows`, as for every other output.
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

#: windows per chunk when ``--chunk`` is not given
DEFAULT_CHUNK = 16
#: guided reuse / warm-start chains restart every this many windows (independent of the chunk size)
from spikeview.pipeline import KEYFRAME as DEFAULT_KEYFRAME  # noqa: E402  (the pipeline's rule)


def recipe_of(data: dict[str, Any]):
    """The :class:`~spikeview.recipe.Recipe` of a recipe dict (the preset tables)."""
    from spikeview.recipe import Recipe

    return Recipe.from_dict(data, where="the batch recipe")


def method_of(data: dict[str, Any]) -> str:
    """``"tfp"``, ``"tfi"`` or ``"guided"``."""
    return str(data.get("run", {}).get("method", "tfp"))


def chained(data: dict[str, Any]) -> bool:
    """Whether a window's result depends on its predecessor's (guided reuse or warm start)."""
    if method_of(data) != "guided":
        return False
    g = recipe_of(data).guided
    return g.reuse is not False or bool(g.warm_start)


def prepare_state(source, data: dict[str, Any]):
    """The sequence-wide state (:class:`spikeview.pipeline.SequenceState`: one gray-world α over the stream)."""
    from spikeview.pipeline import prepare_sequence

    return prepare_sequence(source, recipe_of(data))


def state_to_attrs(state) -> dict[str, Any]:
    """Plain values of a state (Zarr attributes; what travels to the workers): ``alpha`` and ``white_point``."""
    alpha = getattr(state, "alpha", None)
    white = getattr(state, "white", None)
    exposure = getattr(state, "exposure_white", None)
    out = {"alpha": None if alpha is None else [float(v) for v in np.asarray(alpha).ravel()],
           "white_point": None if white is None else float(white)}
    if exposure is not None:  # a dark capture: the sampler's exposure is set from another white (SequenceState)
        out["exposure_white"] = float(exposure)
    if getattr(state, "keep_balance", False):  # the guided frame keeps the gains' balance (spikeview.guided.balance)
        out["keep_balance"] = True
    reach = getattr(state, "tfi_reach", None)
    if reach is not None:  # a dark capture: TFI searches this far at least (spikeview.pipeline.tfi_half_window)
        out["tfi_reach"] = int(reach)
    return out


def state_from_attrs(attrs: dict[str, Any]):
    """The state of :func:`state_to_attrs` values, exactly as :func:`prepare_state` made it (float64 α, float white)."""
    from spikeview.pipeline import SequenceState

    alpha, white, exposure = attrs.get("alpha"), attrs.get("white_point"), attrs.get("exposure_white")
    return SequenceState(None if alpha is None else np.asarray(alpha, dtype=np.float64),
                         None if white is None else float(white), exposure_white=None if exposure is None else float(exposure),
                         keep_balance=bool(attrs.get("keep_balance", False)),
                         tfi_reach=None if attrs.get("tfi_reach") is None else int(attrs["tfi_reach"]))


def compute_chunk(source, centres: Sequence[int], data: dict[str, Any], state, *,
                  sampler: Any = None, cancel: Any = None, on_window: Any = None) -> np.ndarray:
    """Frames of consecutive windows, the first of which starts a reuse / warm-start chain.

    Args:
        source: the spike stream.
        centres: centre ticks, in output order.
        data: the recipe dict (see the module docstring).
        state: from :func:`prepare_state` on the whole sequence.
        sampler: a guided sampler to reuse (keeps the prior loaded).
        cancel: checked between frames / guided sampler steps.
        on_window: called with the number of windows finished so far, after each one.

    Returns:
        float32 ``(n, H, W, C)``: C = 3 for a Bayer stream, 1 for monochrome.
    """
    from spikeview.pipeline import reconstruct_windows

    frames = []
    for f in reconstruct_windows(source, list(centres), recipe_of(data), state, sampler=sampler, cancel=cancel):
        frames.append(np.asarray(f, dtype=np.float32))
        if on_window is not None:
            on_window(len(frames))
    out = np.stack(frames)
    return out[..., None] if out.ndim == 3 else out


# ------------------------------------------------------------------------- worker-side caches
_CACHE: dict[tuple, Any] = {}  # insertion order = least recently used first
_LOCK = threading.Lock()
#: sources kept open per process (a long-lived worker serves many runs; older ones are closed)
CACHE_SIZE = 4
#: how many times this process opened each input (the batch tests check it is once per worker)
OPENS: dict[str, int] = {}


def _key(*parts: Any) -> tuple:
    return tuple(json.dumps(p, sort_keys=True, default=str) for p in parts) + (threading.get_ident(),)


def worker_resources(path: str, open_kwargs: dict[str, Any], recipe: dict[str, Any]) -> tuple[Any, Any]:
    """``(source, sampler)`` of this process and thread, opened once and reused by every later chunk.

    The source is opened from ``path`` (a file every worker can read); the guided sampler (``None``
    for classical methods) keeps its prior loaded. Torch runs one thread per task, as the workers do.
    """
    st = os.stat(path)  # a file rewritten under the same name is opened again
    key = _key(path, (st.st_size, st.st_mtime_ns), open_kwargs, recipe if method_of(recipe) == "guided" else None)
    with _LOCK:
        hit = _CACHE.pop(key, None)
        if hit is not None:
            _CACHE[key] = hit  # most recently used
    if hit is not None:
        return hit
    from spikeview.io import open_source

    source = open_source(path, **open_kwargs)
    from spikeview.classical.calibration import attach

    attach(source, (recipe.get("stream") or {}).get("camera"))  # the camera profile's corrections, as in-process
    OPENS[path] = OPENS.get(path, 0) + 1
    sampler = None
    if method_of(recipe) == "guided":
        from spikeview.guided import GuidedSampler

        sampler = GuidedSampler(recipe_of(recipe).guided)
    with _LOCK:
        _CACHE[key] = (source, sampler)
        evicted = [_CACHE.pop(k) for k in list(_CACHE)[:-CACHE_SIZE]]
    for old_source, _ in evicted:
        _close(old_source)
    return source, sampler


def _close(source: Any) -> None:
    close = getattr(source, "close", None)
    if close is not None:
        close()


def clear_cache() -> None:
    """Close every cached source (tests, and the in-process driver when it finishes)."""
    with _LOCK:
        items = list(_CACHE.values())
        _CACHE.clear()
    for source, _ in items:
        _close(source)
