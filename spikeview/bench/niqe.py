"""NIQE, the "completely blind" image quality score of Mittal, Soundararajan and Bovik (IEEE SPL 2013): lower is better.

:func:`niqe` scores a frame as a viewer sees it (a linear frame scaled to its 99.5th percentile, sRGB-encoded, the
MATLAB luma of an RGB frame, rounded to 0..255); :func:`niqe_gray` scores an image already in 0..255 the way the
official MATLAB release (``computequality.m``) does:

* the image is cropped to whole 96×96 blocks (no overlap);
* MSCN coefficients, ``(I − μ) / (σ + 1)`` with μ, σ the local mean and spread under the release's 7×7 Gaussian
  window (edges replicated);
* per block, 18 features: the generalized Gaussian fit of the coefficients (shape, spread) and the asymmetric
  generalized Gaussian fit (shape, mean, left and right spread) of the products of horizontal, vertical and both
  diagonal neighbours (circular within the block), the shape taken on the grid 0.2:0.001:10 by moment matching;
* the same at half size (MATLAB ``imresize(I, 0.5)``: bicubic with antialiasing, a fixed 8-tap filter for ×0.5,
  symmetric edges), on 48×48 blocks: 36 features per block;
* the distance between the multivariate Gaussian of the blocks' features and the pristine model's,
  ``sqrt((μ₁ − μ₂)ᵀ pinv((Σ₁ + Σ₂)/2) (μ₁ − μ₂))``.

The pristine model ships in ``spikeview/bench/data/niqe_pris_params.npz`` (the release's ``modelparameters.mat``, as
converted by basicsr 1.4.2; its source, the UT Austin notice and the acknowledgement to LIVE/CPS are in
``NIQE_NOTICE.txt`` beside it). This implementation matches basicsr's Python port of the release to ~1e-6.

Caveat: the score is a mean over 96×96 blocks; a 256×256 frame holds only 4 of them, too few for a stable
covariance, so small frames give noisy scores (see :mod:`spikeview.bench.lowlight` for how it ranks there).
"""

from __future__ import annotations

import functools

import numpy as np

from spikeview.errors import ParameterError

#: block side of the release (its recommended and only tested value)
BLOCK = 96
#: the AGGD shape grid of ``estimateaggdparam.m``: 0.2:0.001:10
_SHAPES = 0.2 + 0.001 * np.arange(9801)


@functools.lru_cache(maxsize=1)
def model() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pristine model shipped with the package: mean (36,), covariance (36, 36) and the 7×7 Gaussian window."""
    from importlib.resources import files

    with files("spikeview.bench").joinpath("data", "niqe_pris_params.npz").open("rb") as f:
        d = np.load(f)
        mu, cov, win = (np.array(d[k], dtype=np.float64) for k in ("mu_pris_param", "cov_pris_param", "gaussian_window"))
    for a in (mu, cov, win):
        a.setflags(write=False)
    return mu.reshape(-1), cov, win


@functools.lru_cache(maxsize=1)
def _shape_ratio() -> np.ndarray:
    """Γ(2/γ)² / (Γ(1/γ) Γ(3/γ)) on :data:`_SHAPES`, the moment ratio the fit matches."""
    from scipy.special import gamma

    r = 1.0 / _SHAPES
    return gamma(2 * r) ** 2 / (gamma(r) * gamma(3 * r))


def _aggd(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Asymmetric generalized Gaussian fit of each row of ``v`` (``estimateaggdparam.m``): shape, left and right
    spread. A row without negative or positive values gets NaN spreads and the grid's first shape, as MATLAB's
    ``min`` of a NaN vector gives."""
    from scipy.special import gamma

    neg, pos = v < 0, v > 0
    v2 = v * v
    with np.errstate(invalid="ignore", divide="ignore"):
        left = np.sqrt((v2 * neg).sum(axis=1) / neg.sum(axis=1))
        right = np.sqrt((v2 * pos).sum(axis=1) / pos.sum(axis=1))
        g = left / right
        rhat = np.abs(v).mean(axis=1) ** 2 / v2.mean(axis=1)
        rnorm = rhat * (g ** 3 + 1) * (g + 1) / (g ** 2 + 1) ** 2
    ratio = _shape_ratio()
    idx = np.empty(len(v), dtype=np.intp)
    step = 256  # rows at a time: 256 × 9801 differences, ~20 MB
    for i in range(0, len(v), step):
        # argmin of the squared difference, first minimum, NaN → index 0 (as MATLAB's min)
        idx[i:i + step] = np.argmin((ratio[None, :] - rnorm[i:i + step, None]) ** 2, axis=1)
    alpha = _SHAPES[idx]
    k = np.sqrt(gamma(1 / alpha) / gamma(3 / alpha))
    return alpha, left * k, right * k


def _block_features(mscn: np.ndarray, side: int) -> np.ndarray:
    """The 18 features (``computefeature.m``) of every ``side``×``side`` block of ``mscn``: (blocks, 18)."""
    from scipy.special import gamma

    nh, nw = mscn.shape[0] // side, mscn.shape[1] // side
    b = mscn[:nh * side, :nw * side].reshape(nh, side, nw, side).transpose(0, 2, 1, 3).reshape(nh * nw, side, side)
    alpha, left, right = _aggd(b.reshape(len(b), -1))
    feats = [alpha, (left + right) / 2]
    for shift in ((0, 1), (1, 0), (1, 1), (1, -1)):
        prod = b * np.roll(b, shift, axis=(1, 2))
        alpha, left, right = _aggd(prod.reshape(len(b), -1))
        mean = (right - left) * gamma(2 / alpha) / gamma(1 / alpha)
        feats += [alpha, mean, left, right]
    return np.stack(feats, axis=1)


def _cubic(x: np.ndarray) -> np.ndarray:
    """MATLAB's bicubic kernel (a = −0.5)."""
    a = np.abs(x)
    return np.where(a <= 1, 1.5 * a ** 3 - 2.5 * a ** 2 + 1,
                    np.where(a <= 2, -0.5 * a ** 3 + 2.5 * a ** 2 - 4 * a + 2, 0.0))


def half_size(img: np.ndarray) -> np.ndarray:
    """MATLAB ``imresize(img, 0.5)`` (bicubic, antialiased) of a 2-D image with even sides: for a factor of 0.5 the
    kernel is ``0.5·cubic(0.5·d)`` at the 8 input pixels d = ±0.5 … ±3.5 from each output's centre, normalised,
    edges mirrored (edge pixel repeated); rows first, then columns, as MATLAB orders equal factors."""
    d = np.arange(3.5, -4.0, -1.0)
    w = 0.5 * _cubic(0.5 * d)
    w /= w.sum()

    def along0(a: np.ndarray) -> np.ndarray:
        n = (a.shape[0] + 1) // 2
        p = np.pad(a, ((4, 4), (0, 0)), mode="symmetric")
        # output o sits at input 2o + 0.5; its taps are inputs 2o − 3 … 2o + 4, i.e. padded rows 2o + 1 + k
        return sum(w[k] * p[1 + k:1 + k + 2 * n:2] for k in range(8))

    return along0(along0(np.asarray(img, dtype=np.float64)).T).T


def niqe_gray(img: np.ndarray) -> float:
    """NIQE of a 2-D image in 0..255 (gray or the luma of YCbCr; the release rounds it to integers first, as
    :func:`niqe` does). Lower is better; pristine natural photographs score ~3-5."""
    from scipy.ndimage import convolve

    a = np.asarray(img, dtype=np.float64)
    if a.ndim != 2:
        raise ParameterError(f"NIQE scores a 2-D gray image; got an array of shape {a.shape}.")
    if not np.isfinite(a).all():
        raise ParameterError("NIQE cannot score an image with NaN or infinite values; score a finite frame.")
    h, w = (a.shape[0] // BLOCK) * BLOCK, (a.shape[1] // BLOCK) * BLOCK
    if h == 0 or w == 0:
        raise ParameterError(f"NIQE needs an image of at least {BLOCK}×{BLOCK} pixels (its block size); "
                             f"got {a.shape[1]}×{a.shape[0]}.")
    mu_p, cov_p, win = model()
    a = a[:h, :w]
    feats = []
    for side in (BLOCK, BLOCK // 2):
        mu = convolve(a, win, mode="nearest")
        sigma = np.sqrt(np.abs(convolve(a * a, win, mode="nearest") - mu * mu))
        feats.append(_block_features((a - mu) / (sigma + 1), side))
        if side == BLOCK:
            a = half_size(a / 255.0) * 255.0
    f = np.concatenate(feats, axis=1)
    ok = ~np.isnan(f).any(axis=1)
    if ok.sum() < 2:
        raise ParameterError(f"NIQE needs at least two {BLOCK}×{BLOCK} blocks with texture; this "
                             f"{w}×{h} crop has {int(ok.sum())}: score a larger or less "
                             "flat frame.")
    mu_d = np.nanmean(f, axis=0)  # no column is all NaN: at least two rows are NaN-free
    cov_d = np.cov(f[ok], rowvar=False)
    diff = mu_p - mu_d
    return float(np.sqrt(diff @ np.linalg.pinv((cov_p + cov_d) / 2) @ diff))


def to_display_luma(x: np.ndarray) -> np.ndarray:
    """A linear frame as a viewer sees it, in 0..255 integers: scaled by its 99.5th percentile, clipped to [0, 1],
    sRGB-encoded; an RGB frame's MATLAB luma (``16 + 65.481 R + 128.553 G + 24.966 B``), a mono frame's value × 255;
    rounded (half up, as MATLAB)."""
    from spikeview.transfer import srgb_encode

    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 3 and a.shape[-1] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[-1] == 3)):
        raise ParameterError(f"NIQE scores a mono (H, W) or RGB (H, W, 3) frame; got an array of shape {a.shape}.")
    if not np.isfinite(a).all():
        raise ParameterError("NIQE cannot score a frame with NaN or infinite values; score a finite frame.")
    if min(a.shape[:2]) < BLOCK:
        raise ParameterError(f"NIQE needs a frame of at least {BLOCK}×{BLOCK} pixels (its block size); "
                             f"got {a.shape[1]}×{a.shape[0]}.")
    white = float(np.quantile(a, 0.995))
    if white <= 0:
        raise ParameterError("NIQE cannot score a black frame (its 99.5th percentile is not above 0).")
    v = srgb_encode(np.clip(a / white, 0.0, 1.0))
    y = 16.0 + v @ np.array([65.481, 128.553, 24.966]) if v.ndim == 3 else 255.0 * v
    return np.floor(y + 0.5)


def niqe(x: np.ndarray) -> float:
    """NIQE (lower is better) of a linear-light frame, mono (H, W) or RGB (H, W, 3), whose white is its own 99.5th
    percentile, as a viewer sees it (:func:`to_display_luma`, then :func:`niqe_gray`). At least 96×96 pixels."""
    return niqe_gray(to_display_luma(x))
