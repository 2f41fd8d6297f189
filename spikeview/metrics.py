"""Image-quality metrics: one PSNR, one SSIM and one ground-truth alignment for the app and the benchmark.

Conventions (scikit-image's): every metric takes ``data_range`` explicitly (the distance between the
smallest and largest value the images can take; frames in [0, 1] have ``data_range = 1``); images are
``(H, W)`` or ``(H, W, C)`` float arrays, the reference second.

* :func:`psnr`: ``10·log10(data_range² / MSE)``.
* :func:`ssim`: Wang et al. (2004) exactly as ``skimage.metrics.structural_similarity`` with its
  defaults (7×7 uniform window, K1 = 0.01, K2 = 0.03, sample covariances, a border of 3 pixels
  excluded from the mean, channels averaged) — computed with torch, which releases the interpreter
  lock, so the app's guided worker can score every step without stalling the window.
* :func:`align_ground_truth`: the simulator's linear ground truth expressed in the reconstruction's
  colour normalisation (one least-squares gain per channel).
"""

from __future__ import annotations

import math

import numpy as np

from spikeview.errors import ParameterError

#: SSIM window (scikit-image's default)
WIN = 7


def _check(x: np.ndarray, ref: np.ndarray, data_range: float) -> None:
    if np.shape(x) != np.shape(ref):
        raise ParameterError(f"image shape {np.shape(x)} differs from the reference {np.shape(ref)}.")
    if not (math.isfinite(data_range) and data_range > 0):
        raise ParameterError(f"data_range = {data_range!r}: pass the positive value range of the images, e.g. 1.0.")


def psnr(x: np.ndarray, ref: np.ndarray, data_range: float) -> float:
    """PSNR in dB of ``x`` against ``ref`` (``inf`` for identical images)."""
    _check(x, ref, data_range)
    d = np.asarray(x, dtype=np.float64) - np.asarray(ref, dtype=np.float64)
    mse = float(np.mean(d * d))
    return math.inf if mse == 0 else 10.0 * math.log10(data_range ** 2 / mse)


def ssim(x: np.ndarray, ref: np.ndarray, data_range: float) -> float:
    """Mean SSIM of ``x`` against ``ref`` (scikit-image's defaults; see the module docstring).

    Frames smaller than 7×7 use the largest odd window that fits (NaN below 3×3).
    """
    import torch
    import torch.nn.functional as F

    _check(x, ref, data_range)
    a = torch.from_numpy(np.asarray(x, dtype=np.float64))
    b = torch.from_numpy(np.asarray(ref, dtype=np.float64))
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    a = a.permute(2, 0, 1)[:, None]  # (C, 1, H, W): channels as a batch
    b = b.permute(2, 0, 1)[:, None]
    win = min(WIN, min(a.shape[-2:]) - (1 - min(a.shape[-2:]) % 2))
    if win < 3:
        return float("nan")
    n = win * win
    cov_norm = n / (n - 1.0)

    def filt(v: torch.Tensor) -> torch.Tensor:
        # the window's mean, 'valid': exactly the pixels skimage keeps after cropping the border
        # (average pooling: the same numbers as a float64 7×7 box convolution within 1e-15, ~10× faster,
        # which at 1000×1000 RGB took 3.4 s per guided step of the app)
        return F.avg_pool2d(v, win, stride=1)

    ux, uy = filt(a), filt(b)
    vx = cov_norm * (filt(a * a) - ux * ux)
    vy = cov_norm * (filt(b * b) - uy * uy)
    vxy = cov_norm * (filt(a * b) - ux * uy)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    return float(s.mean(dim=(1, 2, 3)).mean())


def psnr_ssim(x: np.ndarray, ref: np.ndarray, data_range: float = 1.0) -> tuple[float, float]:
    """``(psnr, ssim)`` of ``x`` against ``ref``; PSNR capped at 100 dB for identical images (plots)."""
    p = psnr(x, ref, data_range)
    return (100.0 if math.isinf(p) else p), ssim(x, ref, data_range)


def align_ground_truth(gt: np.ndarray, y: np.ndarray, cfa: str | None, alpha: np.ndarray | None,
                       eta: float) -> np.ndarray:
    """Express the simulator's linear ground truth in the reconstruction's colour normalisation.

    Reconstructions are gray-world corrected (``Y·α/η``), so their per-channel scale differs from
    the scene's linear RGB by the unknown sensor gain. Each channel of ``gt`` is scaled by the
    least-squares gain that maps it onto the corrected observation ``y·α_c/η`` at that channel's
    photosites (one gain per channel, the same for every method and step of a run), then clipped
    to [0, 1]. Without this, PSNR measures the colour normalisation rather than the reconstruction.

    Args:
        gt: ``(H, W, 3)`` or ``(H, W)`` float linear ground truth.
        y: ``(H, W)`` mosaicked TFP of the same window.
        cfa, alpha, eta: the observation's CFA, gains and range parameter.
    """
    from spikeview.cfa import channel_map

    gt = np.asarray(gt, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if gt.ndim == 2 or cfa is None:
        g = gt if gt.ndim == 2 else gt.mean(axis=-1)
        gain = float((y * g).sum() / max((g * g).sum(), 1e-12))
        # a monochrome reconstruction is one channel: so is the ground truth it is scored against
        return np.clip((g if cfa is None else gt) * gain, 0, 1).astype(np.float32)
    out = np.empty_like(gt)
    cmap = channel_map(cfa, *y.shape)
    scale = np.ones(3) if alpha is None else np.asarray(alpha, dtype=np.float64) / eta
    for c in range(3):
        m = cmap == c
        obs_c = y[m] * scale[c]
        g_c = gt[..., c][m]
        gain = float((obs_c * g_c).sum() / max((g_c * g_c).sum(), 1e-12))
        out[..., c] = gt[..., c] * gain
    return np.clip(out, 0, 1).astype(np.float32)


def colour_scores(x: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    """The colour errors a per-channel gain hides, for linear frames ``x`` and ``ref`` (``(H, W, 3)`` or ``(H, W)``):

    * ``psnr_1gain``: PSNR (data range 1) after ONE least-squares gain for all channels (the exposure), not one per
      channel, so a colour cast costs;
    * ``delta_e00``: mean CIEDE2000 of the two through the sRGB curve (both clipped to [0, 1] after that gain);
    * ``wb_angle``: angle in degrees between their mean RGB vectors (the white balance; 0 for monochrome).

    Monochrome frames get ``psnr_1gain`` and 0 for the other two.
    """
    xs = np.asarray(x, dtype=np.float64)
    rs = np.asarray(ref, dtype=np.float64)
    _check(xs, rs, 1.0)
    den = float((xs * xs).sum())
    g = float((xs * rs).sum()) / den if den > 0 else 1.0
    y = np.clip(xs * g, 0.0, 1.0)
    out = {"psnr_1gain": psnr(y.astype(np.float32), rs.astype(np.float32), data_range=1.0), "delta_e00": 0.0, "wb_angle": 0.0}
    if xs.ndim == 3 and xs.shape[-1] == 3:
        from skimage.color import deltaE_ciede2000, rgb2lab

        from spikeview.transfer import srgb_encode

        lab_x = rgb2lab(srgb_encode(y))
        lab_r = rgb2lab(srgb_encode(np.clip(rs, 0.0, 1.0)))
        out["delta_e00"] = float(np.mean(deltaE_ciede2000(lab_x, lab_r)))
        a, b = xs.reshape(-1, 3).mean(axis=0), rs.reshape(-1, 3).mean(axis=0)
        na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        if na > 0 and nb > 0:
            out["wb_angle"] = float(np.degrees(np.arccos(np.clip(a @ b / (na * nb), -1.0, 1.0))))
    return out


def _gray(x: np.ndarray) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    return a.mean(axis=-1) if a.ndim == 3 else a


def detail_kept(x: np.ndarray, ref: np.ndarray) -> float:
    """How much of the reference's detail ``x`` keeps, in [−1, 1]: after ONE least-squares gain of ``x`` to ``ref``
    (the exposure), the band-pass images (difference of Gaussians of σ 1 and 3 pixels, of the luminance; a border
    of 6 pixels left out) give ``Σ x_b·r_b / max(Σ x_b², Σ r_b²)``. 1 = all the reference's detail at its amplitude;
    a blur that keeps a fraction ``a`` of the band-pass amplitude scores ``a`` (a plain correlation would keep ~1:
    it is blind to amplitude); noise of ``k`` times the detail's energy scores ``1/(1 + k)``. PSNR and SSIM alone rank
    a blur first at low light; this does not. Against a noisy reference (a real capture's long exposure) every
    method's score is lowered alike: compare methods on the same reference."""
    from scipy.ndimage import gaussian_filter

    a, b = _gray(x), _gray(ref)
    _check(a, b, 1.0)
    m = 6
    if min(a.shape) <= 2 * m + 2:
        raise ParameterError(f"detail_kept needs an image larger than {2 * m + 2} pixels a side, not {a.shape}.")
    den = float((a * a).sum())
    a = a * (float((a * b).sum()) / den if den > 0 else 1.0)
    ba = (gaussian_filter(a, 1.0) - gaussian_filter(a, 3.0))[m:-m, m:-m].ravel()
    bb = (gaussian_filter(b, 1.0) - gaussian_filter(b, 3.0))[m:-m, m:-m].ravel()
    ba, bb = ba - ba.mean(), bb - bb.mean()
    norm = max(float((ba * ba).sum()), float((bb * bb).sum()))
    return float((ba * bb).sum() / norm) if norm > 0 else 0.0


def patchiness(x: np.ndarray, ref: np.ndarray | None = None, tile: int = 16, flat: float = 0.5,
               truth: bool = False) -> float:
    """Unevenness of the denoising: over the flat ``tile``×``tile`` tiles, the 95th percentile of the high-pass
    residual's spread divided by its median (luminance; high-pass = the image minus its Gaussian σ = 2 blur). ~1
    means evenly denoised; patches of raw noise left in a smooth frame make it large. Flat tiles: the ``flat``
    fraction of tiles with the least band-pass energy in ``ref`` (the truth, or a capture's long exposure), or in
    ``x`` itself without one. ``truth``: ``ref`` is the clean truth, and the residual is that of the error
    ``g·x − ref`` (one global gain ``g``): the scene's own texture then cancels and only what the reconstruction
    left (noise, patches) is measured; otherwise the residual is ``x``'s own (a clean frame's texture counts)."""
    from scipy.ndimage import gaussian_filter

    a = _gray(x)
    r = a if ref is None else _gray(ref)
    _check(a, r, 1.0)
    if truth and ref is not None:
        den = float((a * a).sum())
        a = a * (float((a * r).sum()) / den if den > 0 else 1.0) - r
    hp = a - gaussian_filter(a, 2.0)
    br = np.abs(gaussian_filter(r, 1.0) - gaussian_filter(r, 4.0))
    h, w = a.shape
    th, tw = h // tile, w // tile
    if th * tw < 4:
        raise ParameterError(f"patchiness needs at least 4 tiles of {tile} pixels, not a {w}x{h} image.")
    cut = lambda v: v[:th * tile, :tw * tile].reshape(th, tile, tw, tile).swapaxes(1, 2).reshape(th * tw, -1)  # noqa: E731
    spread = cut(hp).std(axis=1)
    energy = cut(br).mean(axis=1)
    keep = energy <= np.quantile(energy, flat)
    s = spread[keep]
    med = float(np.median(s))
    return float(np.quantile(s, 0.95) / med) if med > 0 else 1.0
