"""The noise schedule of the guided sampler: variance-exploding (VE), x_t = x₀ + σ_t·n.

A pixel-space denoiser ``D(x, σ)`` trained on Gaussian noise is a VE diffusion model: Tweedie's
formula gives the clean estimate ``x̂₀ = D(x_t, σ_t)``. The schedule follows diffusers' scheduler
shape: :meth:`VESchedule.set_timesteps` fixes the σ ladder, :meth:`VESchedule.step` goes from
``x_t`` to ``x_{t-1}`` given x̂₀ and returns both.

Conventions: pixel values are fractions of 1 (σ = 25/255 is FFDNet's "σ = 25"); step indices count
from 0 (the start, largest σ) to ``n - 1`` (the last prior call); ``sigmas`` has ``n + 1`` rows
ending in 0. The start level may differ per channel (the TFP estimate of a blue channel with a
strong cast gain is noisier than the green one): ``sigma_start`` is then a sequence and ``sigmas``
has one column per channel, each a geometric ladder to ``sigma_end``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from spikeview.errors import ParameterError


class StepOutput(NamedTuple):
    """What :meth:`VESchedule.step` returns (diffusers' ``prev_sample`` / ``pred_original_sample``)."""

    prev_sample: torch.Tensor
    pred_original_sample: torch.Tensor


@dataclass
class VESchedule:
    """Geometric σ ladder from ``sigma_start`` down to ``sigma_end``, then 0.

    Attributes:
        sigma_start: noise level of the first prior call (fraction of 1), >= 0: one number, or one
            per channel.
        sigma_end: last non-zero level, ``0 < sigma_end`` (one number or one per channel); clipped
            to each channel's start.
    """

    sigma_start: float | tuple[float, ...]  # the sampler's: guided.t_start (topped up per channel); no default here
    sigma_end: float | tuple[float, ...]  # guided.sigma_end

    def __post_init__(self) -> None:
        start = np.atleast_1d(np.asarray(self.sigma_start, dtype=np.float64))
        if start.ndim != 1 or start.size < 1 or not np.all(np.isfinite(start)) or np.any(start < 0):
            raise ParameterError(f"sigma_start = {self.sigma_start!r} must be finite noise levels >= 0 (fractions of 1).")
        end = np.broadcast_to(np.atleast_1d(np.asarray(self.sigma_end, dtype=np.float64)), start.shape)
        if not np.all(np.isfinite(end)) or np.any(end <= 0):
            raise ParameterError(f"sigma_end = {self.sigma_end!r} must be finite noise levels > 0 (fractions of 1).")
        self._start = start
        self._end = end
        self.sigmas = np.zeros((1, start.size))
        self.timesteps = np.zeros(0, dtype=np.int64)

    def set_timesteps(self, n: int) -> np.ndarray:
        """Fix ``n`` steps: ``sigmas[i]`` for step ``i`` (geometric per channel), ``sigmas[n] = 0``.

        Returns:
            The ``(n + 1, C)`` float64 array of σ (``C`` = entries of ``sigma_start``), also stored as
            ``self.sigmas``.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ParameterError(f"steps = {n!r} must be a whole number >= 1.")
        cols = []
        for hi, end in zip(self._start, self._end):
            lo = min(float(end), hi)
            cols.append(np.full(n, hi) if (n == 1 or hi <= 0) else np.geomspace(hi, lo, n))
        self.sigmas = np.concatenate([np.stack(cols, axis=1), np.zeros((1, len(cols)))], axis=0)
        self.timesteps = np.arange(n, dtype=np.int64)
        return self.sigmas

    def sigma(self, index: int, like: torch.Tensor) -> torch.Tensor:
        """σ of step ``index`` as a ``(1, C, 1, 1)`` tensor in ``like``'s dtype/device (``C`` 1 or the channels)."""
        s = torch.as_tensor(self.sigmas[index], dtype=like.dtype, device=like.device)
        return s.view(1, -1, 1, 1)

    def add_noise(self, x0: torch.Tensor, sigma: float | torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """``x0 + sigma·n`` with ``n ~ N(0, 1)`` drawn from ``generator`` (``sigma`` a number or ``(1, C, 1, 1)``)."""
        if not bool(torch.any(torch.as_tensor(sigma) > 0)):
            return x0.clone()
        from spikeview.guided.device import randn

        noise = randn(x0.shape, generator, x0.dtype, x0.device)  # the CPU generator's numbers on any device
        return x0 + sigma * noise

    def step(self, x0_hat: torch.Tensor, index: int, sample: torch.Tensor, *, zeta: float = 0.0,
             eps_hat: torch.Tensor | None = None, generator: torch.Generator | None = None) -> StepOutput:
        """One step from ``x_t`` (``sample``, at ``sigmas[index]``) to ``x_{t-1}`` at ``sigmas[index + 1]``.

        ``x_{t-1} = x̂₀ + σ_{t-1}·(√(1-ζ)·ε̂ + √ζ·z)``: DDIM in VE form for ζ = 0, DiffPIR's
        re-noising for 0 < ζ <= 1. ``ε̂ = (x_t - x̂₀) / σ_t`` unless given (its σ-normalised
        direction is kept; a zero σ_t gives ε̂ = 0).

        Args:
            x0_hat: the (possibly data-corrected) clean estimate, same shape as ``sample``.
            index: step index ``i`` in ``[0, n)``.
            sample: the current noisy sample x_t.
            zeta: fresh-noise fraction in [0, 1].
            eps_hat: predicted unit noise; derived from ``sample`` and ``x0_hat`` when ``None``.
            generator: source of the fresh noise.
        """
        n = len(self.sigmas) - 1
        if not 0 <= index < n:
            raise ParameterError(f"step index {index} is outside [0, {n}); call set_timesteps first.")
        if not np.any(self.sigmas[index + 1] > 0):
            return StepOutput(x0_hat, x0_hat)
        s_t, s_prev = self.sigma(index, sample), self.sigma(index + 1, sample)
        if eps_hat is None:
            eps_hat = torch.where(s_t > 0, (sample - x0_hat) / s_t.clamp_min(1e-12), torch.zeros_like(sample))
        noise = eps_hat
        if zeta > 0:
            from spikeview.guided.device import randn

            fresh = randn(sample.shape, generator, sample.dtype, sample.device)
            noise = (1 - zeta) ** 0.5 * eps_hat + zeta ** 0.5 * fresh
        return StepOutput(x0_hat + s_prev * noise, x0_hat)


def ve_ladder(sigma_obs: np.ndarray, sigma_add: np.ndarray, sigma_max: float, sigma_end: float, steps: int) -> VESchedule:
    """The sampler's σ ladder: from ``sqrt(σ_obs² + σ_add²)`` per channel (capped at the prior's ``sigma_max``,
    at least 1e-4) down to ``sigma_end`` in ``steps`` steps (the untiled sampler and the tiles alike)."""
    first = np.maximum(np.minimum(np.sqrt(sigma_obs ** 2 + sigma_add ** 2), sigma_max), 1e-4)
    sched = VESchedule(tuple(first), sigma_end)
    sched.set_timesteps(steps)
    return sched
