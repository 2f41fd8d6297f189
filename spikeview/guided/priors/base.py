"""The interface the guided sampler expects from a pixel-space denoising prior."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import torch

from spikeview.errors import SpikeviewError


class PriorUnavailableError(SpikeviewError):
    """A prior's package or weights file is missing; the message says what to install or where to put it."""


@runtime_checkable
class DenoiserPrior(Protocol):
    """A Gaussian denoiser used as the prior of a VE-style sampler (``x_t = x_0 + σ_t · n``).

    Attributes:
        channels: image channels it works on (3 RGB, 1 gray).
        sigma_max: largest noise level (in [0, 1] image units) it was trained for; start the
            sampler at or below it.
    """

    channels: int
    sigma_max: float

    def denoise(self, x: torch.Tensor, sigma: float | torch.Tensor) -> torch.Tensor:
        """Tweedie estimate ``E[x_0 | x]`` of ``x`` ``(N, channels, H, W)`` with noise level ``sigma``.

        ``sigma`` is a float, an ``(N,)`` or ``(N, channels)`` tensor, in [0, 1] image units. The
        result has ``x``'s shape and is differentiable in ``x`` (DPS backpropagates through it).
        """
        ...
