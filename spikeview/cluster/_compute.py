"""The one adapter between the batch path and the reconstruction library.

Everything the batch path knows about *how* frames are made is in this file:

* :func:`prepare_state` — the sequence-wide quantities (colour cast α; a white point once the
  library has one), computed **once** before the work is split and handed to every chunk.
* :func:`compute_chunk` — the frames of a run of consecutive windows, given that state.
* :func:`worker_resources` — the source and the guided sampler of a worker process, opened / loaded
  once and cached (workers read the input from its file path; nothing large goes through the
  scheduler).

Settings travel as the *recipe*: the plain dict of the preset TOML (tables ``run``, ``stream``,
``classical`` or ``guided``, ``export``), so they pickle cheaply and are exactly what the store
records. When the library's single pipeline lands, only this file changes.
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

#: windows per chunk when ``--chunk`` is not given
DEFAULT_CHUNK = 16
#: guided reuse / warm-start chains restart every this many windows (independent of the chunk size)
DEFAULT_KEYFRAME = 16


@dataclasses.dataclass(frozen=True)
class SequenceState:
    """What every chunk of a sequence shares, resolved once before dispatch.

    Attributes:
        alpha: gray-world gains ``[α_R, α_G, α_B]`` (``None``: monochrome stream or no colour cast).
        white_point: display white point, linear units (``None`` until the library estimates one).
    """

    alpha: tuple[float, ...] | None = None
    white_point: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"alpha": None if self.alpha is None else list(self.alpha), "white_point": self.white_point}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SequenceState:
        alpha = data.get("alpha")
        return cls(alpha=None if alpha is None else tuple(float(v) for v in alpha), white_point=data.get("white_point"))


def method_of(recipe: dict[str, Any]) -> str:
    """``"tfp"``, ``"tfi"`` or ``"guided"``."""
    return str(recipe.get("run", {}).get("method", "tfp"))


def _classical(recipe: dict[str, Any]):
    from spikeview.classical.reconstruct import ClassicalConfig

    return ClassicalConfig.from_dict({**recipe.get("classical", {}), "method": method_of(recipe)}, where="recipe [classical]")


def _guided(recipe: dict[str, Any]):
    from spikeview.guided import GuidedConfig

    return GuidedConfig.from_dict(dict(recipe.get("guided", {})), where="recipe [guided]")


def window_length(recipe: dict[str, Any]) -> int:
    """Ticks of one window (TFP window, TFI span, guided window)."""
    if method_of(recipe) == "guided":
        return int(_guided(recipe).window)
    cfg = _classical(recipe)
    return int(cfg.window if cfg.method == "tfp" else 2 * cfg.tfi_half_window)


def chained(recipe: dict[str, Any]) -> bool:
    """Whether a window's result depends on its predecessor's (guided reuse or warm start)."""
    if method_of(recipe) != "guided":
        return False
    p = _guided(recipe)
    return p.reuse is not False or bool(p.warm_start)


def prepare_state(source, recipe: dict[str, Any]) -> SequenceState:
    """The sequence-wide state of ``recipe`` on ``source`` (one gray-world estimate over the stream)."""
    if method_of(recipe) == "guided":
        from spikeview.guided import resolve_alpha

        alpha = resolve_alpha(source, _guided(recipe))
    else:
        from spikeview.classical.reconstruct import resolve_alpha

        alpha = resolve_alpha(source, _classical(recipe))
    return SequenceState(alpha=None if alpha is None else tuple(float(v) for v in np.asarray(alpha).ravel()))


def compute_chunk(source, centres: Sequence[int], recipe: dict[str, Any], state: SequenceState, *,
                  sampler: Any = None, cancel: Any = None) -> np.ndarray:
    """Frames of consecutive windows, the first of which starts a reuse / warm-start chain.

    Args:
        source: the spike stream.
        centres: centre ticks, in output order.
        recipe: the preset tables (see the module docstring).
        state: from :func:`prepare_state` on the whole sequence.
        sampler: a guided sampler to reuse (keeps the prior loaded).
        cancel: checked between guided sampler steps.

    Returns:
        float32 ``(n, H, W, C)``: C = 3 for a Bayer stream, 1 for monochrome.
    """
    alpha = None if state.alpha is None else np.asarray(state.alpha, dtype=np.float64)
    if method_of(recipe) == "guided":
        from spikeview.guided import reconstruct_sequence

        frames = list(reconstruct_sequence(source, list(centres), _guided(recipe), alpha=alpha, sampler=sampler,
                                           cancel=cancel))
    else:
        from spikeview.classical.reconstruct import reconstruct_frames

        cfg = _classical(recipe)
        if alpha is None:
            cfg = cfg.replace(colour_cast=False)  # monochrome, or the cast was off when the state was made
        frames = list(reconstruct_frames(source, list(centres), cfg, alpha=alpha))
    out = np.stack([np.asarray(f, dtype=np.float32) for f in frames])
    return out[..., None] if out.ndim == 3 else out


# ------------------------------------------------------------------------- worker-side caches
_CACHE: dict[tuple, Any] = {}
_LOCK = threading.Lock()


def _key(*parts: Any) -> tuple:
    return tuple(json.dumps(p, sort_keys=True, default=str) for p in parts) + (threading.get_ident(),)


def worker_resources(path: str, open_kwargs: dict[str, Any], recipe: dict[str, Any]) -> tuple[Any, Any]:
    """``(source, sampler)`` of this process and thread, opened once and reused by every later chunk.

    The source is opened from ``path`` (a file every worker can read); the guided sampler (``None``
    for classical methods) keeps its prior loaded. Torch runs one thread per task, as the workers do.
    """
    key = _key(path, open_kwargs, recipe.get("guided") if method_of(recipe) == "guided" else None)
    with _LOCK:
        hit = _CACHE.get(key)
    if hit is not None:
        return hit
    from spikeview.io import open_source

    source = open_source(path, **open_kwargs)
    sampler = None
    if method_of(recipe) == "guided":
        from spikeview.guided import GuidedSampler

        sampler = GuidedSampler(_guided(recipe))
    with _LOCK:
        _CACHE[key] = (source, sampler)
    return source, sampler


def clear_cache() -> None:
    """Close every cached source (tests, and the in-process driver when it finishes)."""
    with _LOCK:
        items = list(_CACHE.values())
        _CACHE.clear()
    for source, _ in items:
        close = getattr(source, "close", None)
        if close is not None:
            close()
