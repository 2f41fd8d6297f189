"""TFP (texture from playback): spike firing rate over a window of ticks.

``SFR = count / Δτ``: the number of spikes each photosite fired in the ``Δτ``-tick window around
the centre tick, divided by ``Δτ``. Values lie in ``{0, 1/Δτ, 2/Δτ, …, 1}``. TFP works per
photosite and never mixes neighbours, so on a Bayer sensor it returns the mosaicked SFR (demosaic
it afterwards with :func:`spikeview.classical.demosaic.demosaic`).
"""

from __future__ import annotations

import numpy as np

from spikeview.classical.windows import window_range
from spikeview.errors import ParameterError, check_cancelled
from spikeview.io.source import SpikeSource

#: ``SpikeSource.count`` returns uint16, so longer ranges are counted in chunks of this many ticks.
_MAX_COUNT_CHUNK = 65_535


def window_counts(source: SpikeSource, a: int, b: int) -> np.ndarray:
    """Spike counts per photosite over ticks ``[a, b)`` of ``source``.

    Uses ``source.count`` (file readers count packed bits without unpacking). Ranges longer than
    65,535 ticks, whose counts could overflow ``count``'s uint16, are counted in chunks.

    Returns:
        ``(H, W)`` array of counts in ``[0, b - a]``: uint16 when ``b - a <= 65535``, else uint32.

    A job's Cancel (:func:`spikeview.errors.cancel_scope`) stops it before the count: building a guided
    window's observation counts a dozen windows, the sequence's α and white point hundreds.
    """
    check_cancelled("while counting spikes")
    if b - a <= _MAX_COUNT_CHUNK:
        return source.count(a, b)
    total = np.zeros((source.height, source.width), dtype=np.uint32)
    for start in range(a, b, _MAX_COUNT_CHUNK):
        total += source.count(start, min(start + _MAX_COUNT_CHUNK, b))
    return total


def tfp(source: SpikeSource, center: int, window: int = 10) -> np.ndarray:
    """TFP of the ``window``-tick window around tick ``center``.

    Args:
        source: any spike source; its flips are already applied, so the result has the
            orientation (and CFA phase ``source.cfa``) of ``source.read``.
        center: centre tick; the ticks read are ``window_range(center, window, n_frames)``
            (centred, shifted inside the stream at its edges so every window has ``window`` ticks).
        window: Δτ in ticks (10 ticks = 0.5 ms at 20 kHz, the SpikeDiff observation).

    Returns:
        ``(H, W)`` float32 SFR in ``[0, 1]``: per-photosite (mosaicked for a Bayer sensor),
        ``count / window``.

    Raises:
        ParameterError: bad ``center``/``window`` (see :func:`window_range`).
    """
    a, b = window_range(center, window, source.n_frames)
    return counts_to_sfr(window_counts(source, a, b), b - a)


def counts_to_sfr(counts: np.ndarray, window: int) -> np.ndarray:
    """``counts / window`` as float32 (``(H, W)`` counts over a ``window``-tick window → SFR in [0, 1])."""
    if window < 1:
        raise ParameterError(f"window must be at least 1 tick, got {window}; pass a positive window length.")
    out = np.asarray(counts, dtype=np.float32)
    return np.multiply(out, np.float32(1.0 / window), dtype=np.float32)


def tfp_array(spikes: np.ndarray) -> np.ndarray:
    """TFP of a whole in-memory spike block: mean over time.

    Args:
        spikes: ``(T, H, W)`` array of 0/1 (any integer or bool dtype), ``T >= 1``.

    Returns:
        ``(H, W)`` float32 SFR in ``[0, 1]``.
    """
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or spikes.shape[0] < 1:
        raise ParameterError(f"spikes must have shape (T, H, W) with T >= 1, got shape {spikes.shape}; pass a spike block.")
    counts = np.count_nonzero(spikes, axis=0)
    return counts_to_sfr(counts, spikes.shape[0])
