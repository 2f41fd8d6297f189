"""The strong one-pass baseline every guided result must beat (METHOD.md).

TFP → bilinear (or Malvar) demosaicking → colour correction ``Y·α/η`` → one pass of the prior at
the **data-derived** noise level σ_c of that estimate (:func:`spikeview.guided.plan.estimate_sigma`,
per channel, times ``sigma_scale``). The benchmark sweeps ``sigma_scale`` and reports the best.
"""

from __future__ import annotations

import numpy as np
import torch

from spikeview.guided.observation import Observation
from spikeview.guided.priors.base import DenoiserPrior


def start_estimate(obs: Observation, use_mosaic: bool = True, use_cast: bool = True, demosaic: str = "bilinear",
                   *, denoised: bool = True) -> np.ndarray:
    """Y₀: the demosaicked, colour-corrected TFP estimate, clipped to [0, 1].

    ``demosaic="auto"`` asks the plan's rule (:func:`spikeview.guided.plan.choose_demosaic`) with
    the window's data-derived noise; ``denoised`` says whether the prior cleans the estimate
    afterwards (the sampler's start, the one-pass input) or it is an output itself.

    Returns:
        ``(H, W, 3)`` float32 for a Bayer stream with ``use_mosaic``, else ``(H, W)``.
    """
    y = obs.y
    if obs.cfa is None or not use_mosaic:
        return np.clip(y, 0.0, 1.0).astype(np.float32)
    from spikeview.classical.demosaic import demosaic as _demosaic

    if demosaic == "auto":
        from spikeview.classical.noise import choose_demosaic
        from spikeview.guided.observation import estimate_sigma

        demosaic = choose_demosaic(float(estimate_sigma(obs, True, use_cast).max()), "auto", denoised=denoised,
                                   mean_count=obs.mean_count(), shape=obs.shape)[0]

    rgb = _demosaic(y, obs.cfa, demosaic)
    if use_cast and obs.alpha is not None:
        rgb = rgb * (obs.alpha / obs.eta).astype(np.float32)
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


def to_tensor(img: np.ndarray) -> torch.Tensor:
    """``(H, W, C)`` or ``(H, W)`` numpy → ``(1, C, H, W)`` float32 tensor."""
    t = torch.from_numpy(np.ascontiguousarray(img, dtype=np.float32))
    return t[None, None] if t.ndim == 2 else t.permute(2, 0, 1)[None]


def to_image(x: torch.Tensor) -> np.ndarray:
    """``(1, C, H, W)`` tensor → ``(H, W, 3)`` / ``(H, W)`` float32 numpy in [0, 1]."""
    a = x.detach().clamp(0.0, 1.0)[0].cpu().numpy().astype(np.float32)
    return a[0] if a.shape[0] == 1 else np.ascontiguousarray(a.transpose(1, 2, 0))


def one_pass(prior: DenoiserPrior, y0: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """One prior pass over ``y0`` with per-channel σ (fractions of 1), or a ``(1, C, H, W)`` per-pixel σ map."""
    from spikeview.guided.device import module_device

    dev = module_device(prior)  # the prior's device (guided.device)
    x = to_tensor(y0).to(dev, non_blocking=True)
    sig = np.asarray(sigma, dtype=np.float32)
    if sig.ndim == 4:  # a per-pixel map (1, C, H, W)
        with torch.no_grad():
            return to_image(prior.denoise(x, torch.as_tensor(sig, device=dev)))
    s = torch.as_tensor(sig.reshape(1, -1), device=dev)
    if s.shape[1] != x.shape[1]:
        s = s.mean(dim=1, keepdim=True).expand(1, x.shape[1])
    with torch.no_grad():
        return to_image(prior.denoise(x, s))


def baseline(obs: Observation, prior: DenoiserPrior, *, sigma_scale: float = 1.0, use_mosaic: bool = True,
             use_cast: bool = True, demosaic: str = "bilinear", sigma_map: bool = False) -> np.ndarray:
    """TFP → demosaic → colour cast → one prior pass at ``sigma_scale`` × the data-derived σ.

    Args:
        obs: the window.
        prior: a denoiser with as many channels as the estimate (3 for Bayer, 1 for monochrome).
        sigma_scale: factor on the data-derived noise level.
        use_mosaic, use_cast: as the plan's ``mosaic`` and ``cast``.
        demosaic: ``"bilinear"`` or ``"malvar2004"``.
        sigma_map: the prior's σ per pixel (:func:`~spikeview.guided.observation.start_variance`: the
            observation's own noise where it is, so a photosite that pooled fewer windows is denoised harder), not
            the frame's RMS. The plan's fallback uses it (a real dark capture otherwise kept 16×16 blocks of raw
            noise where its pooling could not borrow).

    Returns:
        ``(H, W, 3)`` (or ``(H, W)``) float32 in [0, 1].
    """
    from spikeview.guided.observation import estimate_sigma, start_variance

    y0 = start_estimate(obs, use_mosaic, use_cast, demosaic)
    if sigma_map:
        var, gain = start_variance(obs, use_mosaic, use_cast)
        sigma = np.sqrt(np.maximum(var, 0.0)) * np.asarray(gain, dtype=np.float64).reshape(-1, 1, 1) * float(sigma_scale)
        sigma = np.minimum(sigma, getattr(prior, "sigma_max", np.inf)).astype(np.float32)[None]
    else:
        sigma = estimate_sigma(obs, use_mosaic, use_cast) * float(sigma_scale)
        sigma = np.minimum(sigma, getattr(prior, "sigma_max", np.inf))
    return one_pass(prior, y0, sigma)
