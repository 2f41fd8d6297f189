"""Chroma smoothing of a guided colour frame: the colour noise the prior leaves, removed without touching luma.

At Δτ = 10 ticks a Bayer photosite's colour rests on one or two spikes, and the prior (FFDNet, a denoiser of
sRGB-like photographs at a given noise level) leaves low-amplitude, blotchy colour noise of a few pixels: on a gray
scene a mean chroma C*ab of 4–5 where the truth has 0, most of the ΔE00 that remains with a camera profile
(``benchmarks/results/colour.md``, section 5). Every camera pipeline removes it the same way, by smoothing the
chroma more than the luma, since the eye resolves colour more coarsely than brightness.

The frame is encoded with the sRGB curve (where the prior's noise is roughly even across levels), split into luma
Y' and chroma Cb, Cr (BT.601), and Cb, Cr are averaged with a **cross-bilateral** weight guided by the luma:
a Gaussian of σ = ``sigma`` pixels in space times a Gaussian in luma difference whose width is
:data:`LUMA_RANGE` times the luma's own noise (the robust spread of Y' minus its σ = 1 px blur), so colour does not
leak across a luma edge. Y' is kept as it is; the frame goes back through the inverse transform and the sRGB
curve at its own scale. A colour edge without a luma edge (an iso-luminant hue boundary) is softened over about
``sigma`` pixels: on the bench's colour wheel this costs 0.3–0.5 dB one-gain PSNR while its ΔE00 falls 1.5.

The frame is taken as it comes from the sampler, in [0, 1] (no normalisation by its own maximum), and the luma's
noise can be handed in (``luma_range``): a frame whose sampler re-ran only a changed region
(:func:`spikeview.guided.video.reconstruct_sequence`) keeps the previous frame's range, so that outside that region,
beyond the filter's reach (``REACH × sigma`` pixels), its pixels stay exactly the previous frame's.

Monochrome frames are returned unchanged; ``sigma = 0`` turns it off.
"""

from __future__ import annotations

import numpy as np

#: luma → (Y', Cb, Cr) of sRGB-encoded values (BT.601, full range, Cb/Cr centred on 0)
_YCC = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]], dtype=np.float32)
_RGB = np.linalg.inv(_YCC.astype(np.float64)).astype(np.float32)
#: width of the luma range weight, in units of the luma's robust high-pass spread
LUMA_RANGE = 2.5
#: the spatial window reaches this many σ
REACH = 2.0


def _robust_sigma(a: np.ndarray) -> float:
    """1.4826 × the median absolute deviation of ``a`` minus its σ = 1 px Gaussian blur."""
    from scipy.ndimage import gaussian_filter

    h = a - gaussian_filter(a, 1.0, mode="reflect")
    return float(1.4826 * np.median(np.abs(h - np.median(h))))


def _luma_chroma(x: np.ndarray) -> np.ndarray:
    from spikeview.transfer import srgb_encode

    return srgb_encode(np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)).astype(np.float32) @ _YCC.T


def luma_range(x: np.ndarray) -> float:
    """The width of the luma weight for frame ``x`` ``(H, W, 3)``: :data:`LUMA_RANGE` × its luma's robust noise."""
    return LUMA_RANGE * _robust_sigma(np.ascontiguousarray(_luma_chroma(x)[..., 0]))


def smooth_chroma(x: np.ndarray, sigma: float, *, luma_range: float | None = None) -> np.ndarray:
    """``x`` ``(H, W, 3)`` (linear, in [0, 1]) with its chroma smoothed over ``sigma`` pixels, luma-guided; float32.

    ``luma_range``: the luma weight's width (None: :func:`luma_range` of ``x``). Returns ``x`` itself for
    monochrome frames, ``sigma <= 0`` or a frame too small for the window.
    """
    from spikeview.transfer import srgb_decode

    if x.ndim != 3 or x.shape[-1] != 3 or sigma <= 0:
        return x
    r = max(1, int(np.ceil(REACH * sigma)))
    h, w = x.shape[:2]
    if min(h, w) <= r:
        return x
    ycc = _luma_chroma(x)
    y = np.ascontiguousarray(ycc[..., 0])
    cb, cr = ycc[..., 1], ycc[..., 2]
    sy = LUMA_RANGE * _robust_sigma(y) if luma_range is None else float(luma_range)
    inv = np.float32(-0.5 / max(sy, 1e-6) ** 2)
    py = np.pad(y, r, mode="reflect")
    pb = np.pad(cb, r, mode="reflect")
    pr = np.pad(cr, r, mode="reflect")
    num_b = np.zeros_like(y)
    num_r = np.zeros_like(y)
    den = np.zeros_like(y)
    d = np.empty_like(y)
    for i in range(-r, r + 1):
        for j in range(-r, r + 1):
            ws = np.float32(np.exp(-(i * i + j * j) / (2.0 * sigma * sigma)))
            sl = (slice(r + i, r + i + h), slice(r + j, r + j + w))
            np.subtract(py[sl], y, out=d)
            np.multiply(d, d, out=d)
            np.multiply(d, inv, out=d)
            np.exp(d, out=d)
            d *= ws
            den += d
            num_b += d * pb[sl]
            num_r += d * pr[sl]
    out = np.stack([y, num_b / den, num_r / den], axis=-1) @ _RGB.T
    return srgb_decode(np.clip(out, 0.0, 1.0)).astype(np.float32)
