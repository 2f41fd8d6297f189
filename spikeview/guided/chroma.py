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
``sigma`` pixels: on the colour wheels of ``benchmarks/bench_colour.py`` this costs 0.13–0.52 dB one-gain PSNR while
their ΔE00 falls by 1.5.

Each channel's mean over the frame is kept: the result is scaled per channel back to the input's means (the sRGB
curve would otherwise move them: smoothing a mostly black frame's colour noise moved its white balance by 0.8°).

The frame is taken as it comes from the sampler, in [0, 1] (no normalisation by its own maximum), and the luma's noise
and the mean-keeping gains can be handed in (``keep``): a frame whose sampler re-ran only a changed region
(:func:`spikeview.guided.video.reconstruct_sequence`) keeps the previous frame's, so that outside that region,
beyond the filter's reach (``REACH × sigma`` pixels), its pixels stay exactly the previous frame's.

It runs in torch on the device the guided path runs on (``device``; the CPU by default): on a GPU the frame goes
there and back (a 1000×1000 frame is 12 MB), on the CPU it uses torch's threads. The arithmetic is float32.

Monochrome frames are returned unchanged; ``sigma = 0`` turns it off.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from spikeview.transfer import srgb_decode, srgb_encode

#: luma → (Y', Cb, Cr) of sRGB-encoded values (BT.601, full range, Cb/Cr centred on 0)
_YCC = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]], dtype=np.float32)
_RGB = np.linalg.inv(_YCC.astype(np.float64)).astype(np.float32)
#: width of the luma range weight, in units of the luma's robust high-pass spread
LUMA_RANGE = 2.5
#: the spatial window reaches this many σ
REACH = 2.0


def _luma_chroma(x: torch.Tensor) -> torch.Tensor:
    """``(H, W, 3)`` linear → ``(3, H, W)`` Y', Cb, Cr of its sRGB encoding (clipped to [0, 1] first)."""
    m = torch.as_tensor(_YCC, device=x.device)
    return torch.einsum("hwc,kc->khw", srgb_encode(torch.clamp(x, 0.0, 1.0)), m)


def _blur1(y: torch.Tensor) -> torch.Tensor:
    """σ = 1 px Gaussian of ``(H, W)``, reflected borders (radius 4)."""
    k = torch.exp(-0.5 * torch.arange(-4, 5, dtype=torch.float32, device=y.device) ** 2)
    k = k / k.sum()
    t = F.pad(y[None, None], (4, 4, 4, 4), mode="reflect")
    t = F.conv2d(t, k.view(1, 1, 1, 9))
    return F.conv2d(t, k.view(1, 1, 9, 1))[0, 0]


def _robust_sigma(y: torch.Tensor) -> float:
    """1.4826 × the median absolute deviation of ``y`` minus its σ = 1 px blur."""
    h = (y - _blur1(y)).flatten()
    return float(1.4826 * torch.median(torch.abs(h - torch.median(h))))


def _tensor(x: np.ndarray, device: "str | torch.device | None") -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(x, dtype=np.float32)).to(device or "cpu")


def smooth_chroma(x: np.ndarray, sigma: float, *, keep: dict | None = None,
                  device: "str | torch.device | None" = None) -> np.ndarray:
    """``x`` ``(H, W, 3)`` (linear, in [0, 1]) with its chroma smoothed over ``sigma`` pixels, luma-guided; float32.

    Each channel's mean over the frame is kept (the sRGB curve would otherwise move it: on a mostly black frame by
    0.8° of white balance): the result is scaled per channel back to the input's means. ``keep``: a dict that, when
    it holds ``luma_range`` and ``gains`` (those of an earlier frame), makes this frame use them; when it does not,
    receives this frame's. ``device``: where it runs (a torch device; None: the CPU). Returns ``x`` itself for
    monochrome frames, ``sigma <= 0`` or a frame too small for the window.
    """
    if x.ndim != 3 or x.shape[-1] != 3 or sigma <= 0:
        return x
    r = max(1, int(np.ceil(REACH * sigma)))
    h, w = x.shape[:2]
    if min(h, w) <= max(r, 4):
        return x
    given = keep is not None and "luma_range" in keep and "gains" in keep
    with torch.no_grad():
        xt = torch.clamp(_tensor(x, device), 0.0, 1.0)
        ycc = _luma_chroma(xt)
        y = ycc[0]
        sy = float(keep["luma_range"]) if given else LUMA_RANGE * _robust_sigma(y)
        inv = -0.5 / max(sy, 1e-6) ** 2
        p = F.pad(ycc[None], (r, r, r, r), mode="reflect")[0]
        num = torch.zeros_like(ycc[1:])
        den = torch.zeros_like(y)
        d = torch.empty_like(y)
        for i in range(-r, r + 1):
            for j in range(-r, r + 1):
                ws = float(np.exp(-(i * i + j * j) / (2.0 * sigma * sigma)))
                q = p[:, r + i:r + i + h, r + j:r + j + w]
                torch.sub(q[0], y, out=d)
                d.square_().mul_(inv).exp_().mul_(ws)
                den += d
                num.addcmul_(q[1:], d.expand_as(num))
        out = torch.cat([y[None], num / den], 0)
        rgb = srgb_decode(torch.clamp(torch.einsum("khw,ck->hwc", out, torch.as_tensor(_RGB, device=y.device)), 0.0, 1.0))
        if given:
            g = torch.as_tensor(np.asarray(keep["gains"], dtype=np.float32), device=y.device)
        else:
            before, after = xt.mean(dim=(0, 1)), rgb.mean(dim=(0, 1))
            g = torch.where(after > 0, before / torch.clamp(after, min=1e-12), torch.ones_like(after))
            if keep is not None:
                keep["luma_range"], keep["gains"] = sy, g.cpu().numpy().astype(np.float64)
        return torch.clamp(rgb * g, 0.0, 1.0).cpu().numpy().astype(np.float32, copy=False)
