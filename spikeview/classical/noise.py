"""How noisy a window is, and the demosaic that rule picks: shared by the classical reconstructions
and the guided plan (:mod:`spikeview.guided.plan`), so ``demosaic = "auto"`` means the same everywhere.

* :func:`haar_noise_variance` — a robust noise variance of one Bayer plane from its finest diagonal
  Haar detail (trimmed, because TFP values are quantised);
* :func:`choose_demosaic` — bilinear where noise dominates, Malvar-2004 where the window is clean or
  a prior denoises afterwards (except for sparse counts).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: noise σ (max over channels, fraction of 1) of the bilinear TFP estimate at or below which a window
#: counts as clean, so a sharper demosaic pays off for an output that is not denoised afterwards
DEMOSAIC_CLEAN_SIGMA = 8.0 / 255.0
#: mean spikes per photosite per window below which counts are "sparse" (isolated single spikes)
SPARSE_COUNT = 0.3


def choose_demosaic(sigma: float, requested: str = "auto", *, denoised: bool = False,
                    mean_count: float | None = None, shape: tuple[int, int] | None = None,
                    count_words: Callable[[float], str] | None = None) -> tuple[str, str]:
    """The demosaic for a window with noise ``sigma``, and the reason (``requested`` other than
    ``"auto"`` is used as set).

    * ``denoised`` (the guided start estimate and the one-pass input: the prior removes the noise
      afterwards): ``malvar2004``, sharper, whose amplified noise the prior takes out — except for
      sparse counts (``mean_count``, spikes per photosite per window, below :data:`SPARSE_COUNT`),
      where Malvar turns isolated spikes into ringing the prior keeps: ``bilinear`` (on the
      tuning scenes at 128×128: +1.3 dB on the low-key scene, 0.16 spikes per photosite; Malvar
      +0.1 to +0.4 dB on the others, 0.43 to 2.1 spikes);
    * an output that is not denoised (TFP/TFI frames, the TFP fallback): ``bilinear`` where noise
      dominates (``sigma > DEMOSAIC_CLEAN_SIGMA``) — Malvar/Menon sharpen the noise: on 10- to
      200-tick windows of the benchmark scenes bilinear was ahead by 0.5–3.3 dB at σ >= 14/255,
      Malvar ahead by at most 0.25 dB (one scene, 41–100 ticks) —, ``malvar2004`` where it is clean.

    ``count_words`` words ``mean_count`` in the reason (e.g. a pooled count); default "… per window".
    """
    if requested != "auto":
        return requested, f"set by demosaic={requested}"
    if shape is not None and min(shape) < 3:
        return "bilinear", f"a {shape[0]}x{shape[1]} frame is too small for Malvar-2004 (3x3 at least)"
    if denoised and mean_count is not None and mean_count < SPARSE_COUNT:
        words = count_words(mean_count) if count_words is not None else f"{mean_count:.2f} spikes per photosite per window"
        return "bilinear", (f"sparse counts ({words} < {SPARSE_COUNT:g}): "
                            "Malvar would ring around isolated spikes, bilinear averages them")
    if denoised:
        return "malvar2004", "the prior denoises afterwards: the sharper Malvar-2004 start, its amplified noise is removed"
    if sigma <= DEMOSAIC_CLEAN_SIGMA:
        return "malvar2004", f"clean window (noise σ {255 * sigma:.1f}/255 <= {255 * DEMOSAIC_CLEAN_SIGMA:.0f}/255): the sharper Malvar-2004"
    return "bilinear", (f"noise dominates (σ {255 * sigma:.1f}/255 > {255 * DEMOSAIC_CLEAN_SIGMA:.0f}/255): "
                        "Malvar/Menon would sharpen it, bilinear averages it")


def haar_noise_variance(plane: np.ndarray, keep: float = 0.9) -> float | None:
    """Robust noise variance of a 2-D plane from its finest diagonal Haar detail.

    ``HH = (a - b - c + d) / 2`` over non-overlapping 2×2 blocks has the noise's variance for white
    noise and is nearly blind to smooth content. Edges give large ``HH``, so the largest
    ``1 − keep`` of ``HH²`` are dropped and the trimmed mean is divided by its Gaussian value
    (``E[z² | z² <= q] · keep`` for the ``keep`` quantile ``q`` of χ²₁, 0.623 for keep = 0.9).
    A trimmed mean, not Donoho's median, because TFP values are quantised (multiples of 1/Δτ),
    which makes the median of ``|HH|`` jump between levels.

    Returns:
        The variance, or ``None`` for planes smaller than 2×2 (no block).
    """
    h, w = plane.shape
    h2, w2 = h - h % 2, w - w % 2
    if h2 < 2 or w2 < 2:
        return None
    p = plane[:h2, :w2].astype(np.float64)
    hh2 = np.sort((((p[0::2, 0::2] - p[0::2, 1::2] - p[1::2, 0::2] + p[1::2, 1::2]) / 2.0) ** 2).ravel())
    n_keep = max(1, int(np.ceil(keep * hh2.size)))
    return float(hh2[:n_keep].sum() / hh2.size) / trim_factor(keep)


def trim_factor(keep: float) -> float:
    """``E[z² · 1{z² <= q}]`` for ``z ~ N(0, 1)`` and ``q`` the ``keep`` quantile of ``z²``."""
    import math

    from scipy.special import ndtri  # the normal quantile, without importing scipy.stats (0.3 s)

    a = float(ndtri(0.5 + keep / 2.0))
    return keep - 2.0 * a * math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi)
