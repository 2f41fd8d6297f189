"""Guided reconstruction of a sequence: one window per output time, one colour cast per sequence.

:func:`reconstruct_sequence` is what the CLI and the GUI call::

    for frame in reconstruct_sequence(source, centers, params, callback=cb, cancel=event):
        ...

* α (the colour cast) is resolved **once** before the first frame (``alpha`` argument,
  ``params.alpha``, or a gray-world estimate over the whole stream), so colours do not drift.
* Each output time gets its own ``params.window``-tick window and its own plan. With
  ``params.reuse`` not False, a window whose counts match the previous window within their noise
  returns the previous result; when only some 16×16 blocks changed (and their bounding box covers
  less than half the frame) only that box (plus a 16-pixel margin, with the CFA phase kept) is
  sampled and pasted into the previous result.
* ``params.temporal_radius``: each window pools the photons of up to that many aligned
  neighbouring windows on each side where the motion allows (:mod:`spikeview.guided.temporal`),
  read from the source at absolute ticks, so a frame never depends on the frames around it in the
  output (chunks, ``--at``).
* ``params.warm_start``: every window after the first starts from the previous result re-noised to
  ``t_start`` instead of from its own TFP estimate (the data term still comes from its own window).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np

from spikeview.errors import ParameterError
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import BLOCK, make_plan
from spikeview.guided.sampler import GuidedSampler
from spikeview.guided.temporal import WindowCache
from spikeview.guided.window import crop_to_roi, observe_window, same_window
from spikeview.io.source import SpikeSource

#: margin (pixels) around changed blocks when only a region is re-sampled
MARGIN = 16

#: ``callback(frame_index, n_frames, step, n_steps, preview)``
SequenceCallback = Callable[[int, int, int, int, np.ndarray], Any]


def resolve_alpha(source: SpikeSource, params: GuidedConfig, alpha: np.ndarray | list[float] | None = None) -> np.ndarray | None:
    """The sequence's gains α: ``alpha``, else ``params.alpha``, else one gray-world estimate of the stream.

    Returns ``None`` for a monochrome stream. A channel without spikes warns
    (:class:`~spikeview.classical.colour_cast.ColourCastWarning`) and falls back to the mean of the
    others (never a division by zero).
    """
    if source.cfa is None:
        return None
    if alpha is not None:
        return np.asarray(alpha, dtype=np.float64).reshape(3)
    if params.alpha is not None:
        return np.asarray(params.alpha, dtype=np.float64)
    from spikeview.classical.colour_cast import estimate_alpha

    return np.asarray(estimate_alpha(source, window=min(params.window, source.n_frames), max_windows=params.alpha_max_windows),
                      dtype=np.float64)


def reconstruct_frame(source, center: int, params: GuidedConfig | None = None, *, alpha: np.ndarray | None = None,
                      callback: Any = None, cancel: Any = None, sampler: GuidedSampler | None = None) -> np.ndarray:
    """Guided reconstruction of the window of ``source`` centred on tick ``center``.

    Args:
        source: a :class:`~spikeview.io.source.SpikeSource`.
        center: centre tick.
        params: settings (defaults if ``None``).
        alpha: the sequence's gray-world gains; ``None`` uses ``params.alpha`` or estimates them over
            the whole stream (:func:`spikeview.classical.colour_cast.estimate_alpha`).
        callback, cancel: see :meth:`GuidedSampler.run`.
        sampler: reuse a sampler (and its loaded prior).

    Returns:
        ``(H, W, 3)`` float32 in [0, 1] (``(H, W)`` for monochrome).
    """
    p = params if params is not None else GuidedConfig()
    w = observe_window(source, center, p, resolve_alpha(source, p, alpha))
    return (sampler or GuidedSampler(p)).run(w.obs, p, callback, cancel, plan=w.plan)


def _crop_box(changed: np.ndarray, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """Even-aligned ``(y0, y1, x0, x1)`` box of the changed blocks, or None if it is too large to pay off."""
    rows, cols = np.nonzero(changed)
    y0, y1 = rows.min() * BLOCK, min((rows.max() + 1) * BLOCK, shape[0])
    x0, x1 = cols.min() * BLOCK, min((cols.max() + 1) * BLOCK, shape[1])
    if (y1 - y0) * (x1 - x0) > 0.5 * shape[0] * shape[1]:
        return None
    return int(y0), int(y1), int(x0), int(x1)


def _crop_obs(obs: Observation, y0: int, y1: int, x0: int, x1: int) -> Observation:
    return obs.crop(y0, y1, x0, x1)


def reconstruct_sequence(source: SpikeSource, centers: Iterable[int], params: GuidedConfig | None = None, *,
                         alpha: np.ndarray | list[float] | None = None, callback: SequenceCallback | None = None,
                         cancel: Any = None, sampler: GuidedSampler | None = None,
                         infos: list | None = None, roi: tuple[int, int, int, int] | None = None,
                         resolve: bool = True, first: Observation | None = None) -> Iterator[np.ndarray]:
    """Guided frames at each centre tick (see the module docstring).

    Args:
        source: the spike stream.
        centers: centre ticks, in output order.
        params: settings (defaults if ``None``).
        alpha: gains to use instead of ``params.alpha`` / the gray-world estimate.
        callback: ``callback(frame_index, n_frames, step, n_steps, preview)`` after every sampler step
            (``n_frames`` is -1 when ``centers`` has no length).
        cancel: threading.Event-like or callable; checked before every step (raises
            :class:`~spikeview.errors.Cancelled`).
        sampler: a sampler to reuse (keeps the prior loaded).
        infos: if given, the :class:`~spikeview.guided.sampler.RunInfo` of every frame is appended.
        roi: ``(x, y, w, h)``: sample only this region (its origin rounded down to even pixels so
            the CFA phase is kept); frames are the region's size.
        resolve: estimate α when ``alpha`` is None (False: ``alpha=None`` means no colour cast, as
            :func:`spikeview.pipeline.prepare_sequence` decided).
        first: the first centre's observation when the caller built it already (the CLI prints its
            plan before the run): used when it is that window's, at these settings (its neighbours'
            counting and alignment are not done twice), else ignored.

    Yields:
        ``(H, W, 3)`` float32 frames in [0, 1] (``(H, W)`` for monochrome).
    """
    from spikeview.guided.chroma import smooth_chroma

    p = params if params is not None else GuidedConfig()
    a = resolve_alpha(source, p, alpha) if resolve else (None if alpha is None else np.asarray(alpha, dtype=np.float64))
    smp = sampler if sampler is not None else GuidedSampler(p)
    centers = list(centers)
    n = len(centers)
    prev: np.ndarray | None = None
    chroma_keep: dict = {}
    chroma_device = _chroma_device(p)
    # neighbouring windows are shared by consecutive frames; in low light a static tile reads up to ±LOW_LIGHT_RADIUS
    from spikeview.guided.temporal import LOW_LIGHT_RADIUS

    depth = prefetch_depth() if (n > 1 and _on_gpu(p)) else 0
    # every window the frames in flight may pool (the prepared ones too: each is a frame further on)
    cache = WindowCache(2 * max(2 * p.temporal_radius, LOW_LIGHT_RADIUS if p.temporal_radius else 0) + 6 + depth)

    def observe(fi: int, c: int) -> tuple[Observation, Any]:
        """Frame ``fi``'s observation (counts, pooling) and plan: they depend on the capture and the
        settings only, never on an earlier frame's result."""
        if fi == 0 and first is not None and same_window(first, c, p, a):
            o = first if roi is None else crop_to_roi(first, roi)
            return o, make_plan(o, p)
        w = observe_window(source, c, p, a, roi=roi, previous=fi > 0 and p.reuse is not False, cache=cache)
        return w.obs, w.plan

    # on a GPU the next windows' counting, pooling and plan (CPU work, and small GPU work) run in threads of their own
    # while this window samples: the same observations, results in frame order (the cache has its lock)
    ahead = _Prefetch(observe, centers, depth) if depth else None
    for fi, c in enumerate(centers):
        obs, plan = ahead.get(fi) if ahead is not None else observe(fi, c)
        cb = None
        if callback is not None:
            def cb(step: int, total: int, preview: np.ndarray, _fi: int = fi) -> None:
                callback(_fi, n, step, total, preview)
        init = prev if (p.warm_start and prev is not None and plan.diffusion) else None
        out = None
        if (prev is not None and plan.diffusion and not plan.reuse and plan.changed is not None
                and plan.changed.any()):
            box = _crop_box(plan.changed, obs.shape)
            if box is not None:
                out = _resample_region(smp, obs, p, box, prev, cb, cancel, init, plan.sigma)
                if out is not None:
                    smp.info.plan = plan  # report the frame's plan (with its changed blocks)
        if out is None:
            out = smp.run(obs, p, cb, cancel, init=init, previous=prev, plan=plan)
        if infos is not None:
            infos.append(smp.info)
        prev = out  # unsmoothed: a reused or warm-started window smooths exactly once, as a fresh one
        if smp.info.mode != "region":  # a re-sampled region keeps the frame's luma range and mean-keeping gains
            chroma_keep = {}
        yield smooth_chroma(out, p.chroma, keep=chroma_keep, device=chroma_device)


def _chroma_device(p: GuidedConfig) -> Any:
    """Where the chroma smoothing runs: the guided path's GPU, else the CPU (None)."""
    if not _on_gpu(p):
        return None
    from spikeview.guided.device import resolve_device

    return resolve_device(p.device)


def _on_gpu(p: GuidedConfig) -> bool:
    """The pixel-space guided path runs on a CUDA device (``guided.device`` resolved)."""
    if p.device == "cpu" or p.prior == "sd":
        return False
    from spikeview.guided.device import resolve_device

    return resolve_device(p.device).type == "cuda"


#: fewest frames whose observation and plan are prepared ahead on a GPU (each in a thread of its own)
PREFETCH = 2
#: most frames prepared ahead (a host's cores beyond this sit idle; each frame in flight holds its windows' arrays)
PREFETCH_MAX = 8


def prefetch_depth() -> int:
    """Frames prepared ahead on a GPU: half the host's cores, within :data:`PREFETCH` … :data:`PREFETCH_MAX`. A window's
    counting and pooling is CPU work (numpy and numba release the GIL for most of it: two threads on two cores give
    1.4× one), ~1 s at 1000² on one core, against ~0.1 s of sampling on an H100: the GPU waits on the host's cores."""
    import os

    return int(np.clip((os.cpu_count() or 2) // 2, PREFETCH, PREFETCH_MAX))


class _Prefetch:
    """``fn(i, centres[i])`` for every frame in order, :data:`PREFETCH` frames ahead, in worker threads
    (see reconstruct_sequence); results come back in frame order."""

    def __init__(self, fn: Callable[[int, int], Any], centres: list[int], depth: int = PREFETCH):
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        self._fn, self._centres = fn, centres
        self._pool = ThreadPoolExecutor(max(1, depth), thread_name_prefix="spikeview-observe")
        self._queue: Any = deque(self._pool.submit(fn, j, centres[j]) for j in range(min(max(1, depth), len(centres))))
        self._submitted = len(self._queue)

    def get(self, i: int) -> Any:
        try:
            out = self._queue.popleft().result()
        except BaseException:
            self._pool.shutdown(wait=False, cancel_futures=True)
            raise
        if self._submitted < len(self._centres):
            j = self._submitted
            self._queue.append(self._pool.submit(self._fn, j, self._centres[j]))
            self._submitted += 1
        if not self._queue:
            self._pool.shutdown(wait=False)
        return out

    def __del__(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


def _resample_region(smp: GuidedSampler, obs: Observation, p: GuidedConfig, box: tuple[int, int, int, int],
                     prev: np.ndarray, cb: Any, cancel: Any, init: np.ndarray | None, sigma: np.ndarray) -> np.ndarray | None:
    """Sample only the changed box (plus margin) and paste it into the previous result; ``sigma`` is the
    noise the frame's plan measured on the whole window (more samples than the box holds)."""
    y0, y1, x0, x1 = box
    h, w = obs.shape
    # margins rounded to even offsets so the crop keeps the CFA phase
    cy0, cx0 = max(0, y0 - MARGIN) & ~1, max(0, x0 - MARGIN) & ~1
    cy1, cx1 = min(h, y1 + MARGIN), min(w, x1 + MARGIN)
    if cy1 - cy0 < 8 or cx1 - cx0 < 8:
        return None
    sub = _crop_obs(obs, cy0, cy1, cx0, cx1)
    sub_plan = make_plan(sub, p.replace(reuse=False))
    sub_plan.sigma = sigma
    sub_init = None if init is None else init[cy0:cy1, cx0:cx1]
    part = smp.run(sub, p, cb, cancel, init=sub_init, plan=sub_plan)
    if part.ndim != prev.ndim:
        raise ParameterError("the region plan disagrees with the frame plan on colour; set use_mosaic explicitly.")
    out = prev.copy()
    out[y0:y1, x0:x1] = part[y0 - cy0:y1 - cy0, x0 - cx0:x1 - cx0]
    smp.info.mode = "region"
    return out
