"""The benchmark's scores: PSNR/SSIM (:mod:`spikeview.metrics`) after a per-channel least-squares gain,
shared by the error-against-run-time benchmark (:mod:`spikeview.bench.guided`) and the sequences
benchmark (:mod:`spikeview.bench.temporal`)."""

from __future__ import annotations

import numpy as np


def fit_gain(out: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-channel least-squares gain ``g_c = Σ x_c t_c / Σ x_c²`` of ``out`` to ``gt`` (1 where ``out`` is 0)."""
    x = out.reshape(-1, out.shape[-1] if out.ndim == 3 else 1).astype(np.float64)
    t = gt.reshape(x.shape).astype(np.float64)
    den = (x * x).sum(axis=0)
    return np.where(den > 0, (x * t).sum(axis=0) / np.maximum(den, 1e-30), 1.0)


def score(out: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    """PSNR, SSIM of ``out`` (a bounded frame in [0, 1]) after the least-squares gain, against ``gt``."""
    from spikeview.metrics import psnr, ssim

    g = fit_gain(out, gt)
    x = (out.astype(np.float64) * (g if out.ndim == 3 else g[0])).astype(np.float32)
    gt = gt.astype(np.float32)
    return psnr(x, gt, data_range=1.0), ssim(x, gt, data_range=1.0)


def clipped_fraction(out: np.ndarray) -> float:
    """Fraction of values at or above full scale in a bounded frame."""
    return float((np.asarray(out) >= 1.0 - 1e-6).mean())
