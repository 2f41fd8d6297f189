"""TFI (texture from interval): intensity from the inter-spike interval containing a tick.

A photosite that fires every ``k`` ticks sees an intensity proportional to ``1/k``. TFI estimates
it at tick ``t`` from the interval between the last spike at or before ``t`` and the first spike
after ``t`` (the SpikeCV convention):

* ``prev`` = last tick in ``[t - half_window, t]`` with a spike,
* ``next`` = first tick in ``[t + 1, t + half_window]`` with a spike,
* ``interval = next - prev`` (``1 <= interval <= 2·half_window``), output ``1 / interval``.

If either spike is missing within ``half_window`` ticks (a dark photosite), the interval is **capped at**
``2·half_window``, the longest interval the search could have found, as SpikeCV does. So the output is always
finite, lies in ``[1/(2·half_window), 1]`` and a photosite with no spike at all reads ``1/(2·half_window)`` rather
than 0.

Near the ends of the stream the search range is cut at the stream boundary (not shifted: ``t`` is the instant being
imaged). Where the cut, not the photosite, leaves one side without a spike, the interval containing ``t`` began
before the stream or ends after it: TFI takes the nearest whole interval on the other side (the two spikes after
``t`` at the start, the two before it at the end, searched ``2·half_window`` ticks deep, as far as an interval in
the stream's middle may span), and the cap only where that side has fewer than two spikes within reach. The spikes
on both sides of ``t`` are searched ``half_window`` ticks deep there as everywhere, and an interval longer than
``2·half_window`` is capped as everywhere. (SpikeCV caps at the ends too: a capture's first and last frames came out
black or flat, a Spike-Zoo clip's last frame at 0.03 where the frames before it read 0.45.)

Like TFP, TFI works per photosite and never mixes neighbours (mosaicked output on a Bayer sensor).
"""

from __future__ import annotations

import numba
import numpy as np

from spikeview.errors import ParameterError
from spikeview.io.source import SpikeSource

from spikeview.classical.config import DEFAULT_HALF_WINDOW  # noqa: E402  (one home: the settings)


@numba.njit(cache=True, nogil=True)
def _nearest(flat: np.ndarray, ti: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    # Frame-major passes with "last write wins": scanning from the far end towards ti, every
    # spike overwrites the distance, so the nearest spike's distance remains. Branch-free and
    # contiguous, which vectorises (about 10x faster than scanning each pixel's time line).
    t_len, n = flat.shape
    none = np.int32(1 << 30)
    dprev = np.full(n, none, dtype=np.int32)  # ti - (last spike tick <= ti)
    dnext = np.full(n, none, dtype=np.int32)  # (first spike tick > ti) - ti
    for k in range(0, ti + 1):
        frame = flat[k]
        d = np.int32(ti - k)
        for i in range(n):
            dprev[i] = d if frame[i] != 0 else dprev[i]
    for k in range(t_len - 1, ti, -1):
        frame = flat[k]
        d = np.int32(k - ti)
        for i in range(n):
            dnext[i] = d if frame[i] != 0 else dnext[i]
    return dprev, dnext


@numba.njit(cache=True, nogil=True)
def _tfi_kernel(spikes: np.ndarray, ti: int, cap: int) -> np.ndarray:  # pragma: no cover - compiled
    t_len, h, w = spikes.shape
    n = h * w
    none = np.int32(1 << 30)
    dprev, dnext = _nearest(spikes.reshape(t_len, n), ti)
    out = np.empty(n, dtype=np.float32)
    capped = np.float32(1.0) / np.float32(cap)
    for i in range(n):
        interval = np.int64(dprev[i]) + np.int64(dnext[i])  # >= 1; >= 2**30 when a spike is missing
        out[i] = capped if interval >= none else np.float32(1.0) / np.float32(interval)
    return out.reshape(h, w)


@numba.njit(cache=True, nogil=True)
def _tfi_kernel_ends(spikes: np.ndarray, ti: int, cap: int, cut_lo: bool, cut_hi: bool) -> np.ndarray:  # pragma: no cover - compiled
    # _tfi_kernel where the stream's end cuts the search (the first and last half_window ticks only: the block reaches
    # 2·half_window on the other side, and the second-nearest spikes are kept for its whole interval)
    t_len, h, w = spikes.shape
    n = h * w
    flat = spikes.reshape(t_len, n)
    none = np.int32(1 << 30)
    dprev, dnext = _nearest(flat, ti)
    dprev2 = np.full(n, none, dtype=np.int32)  # the spike before the last one
    dnext2 = np.full(n, none, dtype=np.int32)  # the spike after the next one
    # then the second nearest: the nearest beyond the first (one store a pass, so these vectorise too)
    for k in range(0, ti + 1):
        frame = flat[k]
        d = np.int32(ti - k)
        for i in range(n):
            dprev2[i] = d if (frame[i] != 0) & (d > dprev[i]) else dprev2[i]
    for k in range(t_len - 1, ti, -1):
        frame = flat[k]
        d = np.int32(k - ti)
        for i in range(n):
            dnext2[i] = d if (frame[i] != 0) & (d > dnext[i]) else dnext2[i]
    out = np.empty(n, dtype=np.float32)
    capped = np.float32(1.0) / np.float32(cap)
    half = cap // 2  # the search reaches half_window ticks each way (the block may hold more: the deeper side)
    for i in range(n):
        p = dprev[i] if dprev[i] <= half else none
        q = dnext[i] if dnext[i] <= half else none
        interval = np.int64(p) + np.int64(q)  # >= 1; >= 2**30 when a spike is missing
        if interval >= none:
            # the stream's end cut the search: the nearest whole interval on the other side (2·half_window deep)
            if cut_lo and p >= none and dnext2[i] < none:
                interval = np.int64(dnext2[i]) - np.int64(dnext[i])
            elif cut_hi and q >= none and dprev2[i] < none:
                interval = np.int64(dprev2[i]) - np.int64(dprev[i])
        out[i] = capped if interval >= cap else np.float32(1.0) / np.float32(interval)
    return out.reshape(h, w)


def _kernel(block: np.ndarray, ti: int, hw: int, cut_lo: bool, cut_hi: bool) -> np.ndarray:
    """TFI of ``block`` at its tick ``ti``: the branch-free kernel inside the stream, the ends' rule where it is cut."""
    block = np.ascontiguousarray(block, dtype=np.uint8)
    if cut_lo or cut_hi:
        return _tfi_kernel_ends(block, ti, 2 * hw, cut_lo, cut_hi)
    return _tfi_kernel(block, ti, 2 * hw)


def _block(t: int, hw: int, n: int) -> tuple[int, int, bool, bool]:
    """The ticks ``[lo, hi)`` TFI reads at ``t`` and whether the stream cuts the search before / after ``t``: where it
    does, the other side reaches ``2·half_window`` ticks (the longest interval the search finds inside the stream)."""
    cut_lo, cut_hi = t - hw < 0, t + hw + 1 > n
    lo = max(0, t - hw - (hw if cut_hi else 0))
    hi = min(n, t + hw + 1 + (hw if cut_lo else 0))
    return lo, hi, cut_lo, cut_hi


def _check_half_window(half_window: int) -> int:
    if isinstance(half_window, bool) or not isinstance(half_window, (int, np.integer)) or half_window < 1:
        raise ParameterError(f"half_window must be a whole number of ticks >= 1, got {half_window!r}; pass e.g. {DEFAULT_HALF_WINDOW}.")
    return int(half_window)


def tfi_array(spikes: np.ndarray, t: int, half_window: int = DEFAULT_HALF_WINDOW) -> np.ndarray:
    """TFI at index ``t`` of an in-memory spike block.

    Args:
        spikes: ``(T, H, W)`` array of 0/1 (uint8 or bool), in ticks.
        t: tick index into ``spikes`` (``0 <= t < T``) at which to estimate the intensity.
        half_window: search at most this many ticks before and after ``t``; ticks outside
            ``spikes`` count as "no spike" (see the module docstring for the cap).

    Returns:
        ``(H, W)`` float32 in ``[1/(2·half_window), 1]``: ``1 / interval`` in spikes per tick.
    """
    spikes = np.asarray(spikes)
    if spikes.ndim != 3:
        raise ParameterError(f"spikes must have shape (T, H, W), got shape {spikes.shape}; pass a spike block.")
    hw = _check_half_window(half_window)
    t_len = spikes.shape[0]
    if not 0 <= int(t) < t_len:
        raise ParameterError(f"t={t} is outside the spike block, which holds ticks [0, {t_len}); choose a tick inside it.")
    t = int(t)
    lo, hi, cut_lo, cut_hi = _block(t, hw, t_len)
    block = spikes[lo:hi]
    return _kernel(block, t - lo, hw, cut_lo, cut_hi)


def tfi(source: SpikeSource, center: int, half_window: int = DEFAULT_HALF_WINDOW) -> np.ndarray:
    """TFI of ``source`` at tick ``center``.

    Reads ticks ``[center - half_window, center + half_window]`` (cut at the stream's ends) and
    applies the rule of the module docstring.

    Args:
        source: any spike source (flips applied; mosaicked output for a Bayer CFA).
        center: the tick to image, ``0 <= center < n_frames``.
        half_window: search half-window in ticks (default 32); the cap is ``2·half_window``.

    Returns:
        ``(H, W)`` float32 in ``[1/(2·half_window), 1]`` (an SFR-like rate in spikes per tick).

    Raises:
        ParameterError: ``center`` outside the stream or ``half_window < 1``.
    """
    hw = _check_half_window(half_window)
    n = source.n_frames
    if isinstance(center, bool) or not isinstance(center, (int, np.integer)) or not 0 <= center < n:
        raise ParameterError(f"center tick {center!r} is outside the stream, which holds ticks [0, {n}); choose a tick inside it.")
    center = int(center)
    lo, hi = tfi_span(center, hw, n)
    return tfi_block(source.read(lo, hi), lo, center, hw, n)


def tfi_span(t: int, half_window: int, n_frames: int) -> tuple[int, int]:
    """The ticks ``[lo, hi)`` TFI at ``t`` reads in a stream of ``n_frames`` ticks (see the module docstring)."""
    lo, hi, _, _ = _block(int(t), _check_half_window(half_window), int(n_frames))
    return lo, hi


def tfi_block(block: np.ndarray, start: int, t: int, half_window: int, n_frames: int) -> np.ndarray:
    """TFI at stream tick ``t`` from ``block``, the stream's ticks ``[start, start + len(block))``, which must cover
    :func:`tfi_span` (a preview reads one block for TFP and TFI): the stream's own ends decide the cut, not the
    block's."""
    hw = _check_half_window(half_window)
    lo, hi, cut_lo, cut_hi = _block(int(t), hw, int(n_frames))
    if start > lo or start + len(block) < hi:
        raise ParameterError(f"the block of ticks [{start}, {start + len(block)}) does not cover TFI's span [{lo}, {hi}) "
                             f"at tick {t}; read that span.")
    return _kernel(np.asarray(block[lo - start:hi - start]), int(t) - lo, hw, cut_lo, cut_hi)
