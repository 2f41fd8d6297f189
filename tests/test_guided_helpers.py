"""Shared helpers of the guided-reconstruction tests (tiny scenes, a stand-in denoiser); holds no tests itself."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from spikeview.cfa import channel_map
from spikeview.io.source import ArraySource


class BlurDenoiser(torch.nn.Module):
    """A tiny differentiable stand-in for FFDNet: blends ``x`` towards a 3×3 box blur by ``σ/(σ + 0.05)``.

    Has the :class:`~spikeview.guided.priors.base.DenoiserPrior` interface (``channels``,
    ``sigma_max``, ``denoise(x, sigma)`` with a float, ``(N, C)`` or ``(N, C, H, W)`` sigma).
    """

    sigma_max = 75.0 / 255.0

    def __init__(self, channels: int = 3):
        super().__init__()
        self.channels = channels

    def denoise(self, x: torch.Tensor, sigma) -> torch.Tensor:
        s = torch.as_tensor(sigma, dtype=x.dtype)
        s = s.reshape(s.shape + (1,) * (4 - s.ndim)) if s.ndim < 4 else s
        blur = F.avg_pool2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), 3, stride=1)
        mix = s / (s + 0.05)
        return x + (blur - x) * mix


def spikes_from_rates(rates: np.ndarray, ticks: int, seed: int = 0) -> np.ndarray:
    """Integrate-and-fire spikes ``(ticks, H, W)`` uint8 for per-photosite rates in [0, 1] (random phase)."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(0.0, 1.0, rates.shape)
    out = np.zeros((ticks,) + rates.shape, dtype=np.uint8)
    for t in range(ticks):
        v = v + rates
        fire = v >= 1.0
        out[t] = fire
        v = v - fire
    return out


def scene_rates(kind: str, h: int = 16, w: int = 16, cfa: str = "RGGB", seed: int = 0) -> np.ndarray:
    """Per-photosite firing rates of a named test scene.

    ``texture``: smooth random colours; ``dark``: no spikes; ``saturated``: a spike every tick;
    ``no_blue``: texture with the blue photosites dark; ``constant``: 0.4 everywhere;
    ``checker``: Nyquist checkerboard 0.1/0.9; ``ramp``: a smooth gradient 0.2…0.6.
    """
    rng = np.random.default_rng(seed)
    if kind == "dark":
        return np.zeros((h, w))
    if kind == "saturated":
        return np.ones((h, w))
    if kind == "constant":
        return np.full((h, w), 0.4)
    if kind == "ramp":  # smooth: no texture at the finest scale, so only noise shows there
        yy, xx = np.mgrid[0:h, 0:w]
        return 0.2 + 0.4 * (xx + 0.5 * yy) / (w + 0.5 * h)
    if kind == "checker":
        yy, xx = np.mgrid[0:h, 0:w]
        return np.where((yy + xx) % 2 == 0, 0.1, 0.9)
    base = rng.uniform(0.1, 0.7, (h // 4 + 2, w // 4 + 2, 3))
    from scipy.ndimage import zoom

    img = zoom(base, (h / base.shape[0] + 1e-9, w / base.shape[1] + 1e-9, 1), order=1)[:h, :w]
    cmap = channel_map(cfa, h, w)
    rates = np.take_along_axis(img, cmap[..., None].astype(np.intp), axis=2)[..., 0] * np.array([0.6, 1.0, 0.5])[cmap]
    if kind == "no_blue":
        rates[cmap == 2] = 0.0
    return rates


def make_source(kind: str = "texture", h: int = 16, w: int = 16, ticks: int = 30, cfa: str | None = "RGGB",
                seed: int = 0) -> ArraySource:
    """An :class:`ArraySource` of a named scene (see :func:`scene_rates`)."""
    rates = scene_rates(kind, h, w, cfa or "RGGB", seed)
    return ArraySource(spikes_from_rates(rates, ticks, seed), cfa=cfa)


class Recorder:
    """Wraps a guidance rule; records, per step, the iterates' finiteness and the data residual of x̂₀."""

    def __init__(self, rule):
        self.rule = rule
        self.needs_grad = rule.needs_grad
        self.residual: list[float] = []
        self.finite: list[bool] = []

    def step(self, prior, schedule, data, x_t, index, sigma, **kw):
        x, x0 = self.rule.step(prior, schedule, data, x_t, index, sigma, **kw)
        self.finite.append(bool(torch.isfinite(x).all() and torch.isfinite(x0).all()))
        with torch.no_grad():
            self.residual.append(float(data.norm(x0.clamp(0.0, 1.0))))
        return x, x0


class SigmaSpy(BlurDenoiser):
    """The stand-in denoiser, remembering every σ it was told."""

    def __init__(self, channels: int = 3):
        super().__init__(channels)
        self.told: list[np.ndarray] = []

    def denoise(self, x, sigma):
        self.told.append(np.asarray(torch.as_tensor(sigma, dtype=torch.float64).reshape(-1)))
        return super().denoise(x, sigma)
