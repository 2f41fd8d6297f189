"""The latent-diffusion (Stable Diffusion) parts of the guided sampler: a schedule and a guidance rule.

There is one guided driver, :class:`spikeview.guided.sampler.GuidedSampler`; with ``prior = "sd"`` it
runs the same plan, start estimate Y₀, forward model and data term (noise weights, multiscale loss),
callback and cancel check as with FFDNet, and swaps in these parts:

* the **schedule** :class:`DDIMLadder` (DDIM over ``[0, t_s]`` of the model's training schedule), with
  ``t_s`` the first timestep whose noise-to-signal ratio ``√((1 − ᾱ_t)/ᾱ_t)`` reaches ``2·t_start``
  (:func:`start_timestep`; ``t_start`` is the same pixel noise level, fraction of full scale, as
  for FFDNet: the VAE works in [−1, 1], hence the 2);
* the **guidance rule** :class:`LatentDPSGuidance`: ``ε̂, ẑ₀ = Tweedie(UNet(Z_t, t))``,
  ``X̂₀ = clamp(D(ẑ₀), 0, 1)`` cropped, ``L = ‖P(√w̃ (A(X̂₀) − Y))‖`` (non-squared, the DPS
  reference), ``Z_{t−1} = DDIM(Z_t; ẑ₀, ε̂) − s·∇_{Z_t} L`` through decoder and UNet;
* the **space** :class:`LatentSpace`: ``Z_ts = √ᾱ_ts · E(pad(Y₀)) + √(1 − ᾱ_ts) · z`` at the start
  (edge-replicated to multiples of the VAE factor), ``clamp(D(Z_0), 0, 1)`` cropped at the end.

Noise comes from the sampler's CPU ``torch.Generator`` (seeded by ``seed``), so a seed gives the same
noise on every device; on CPU the result is bitwise reproducible.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from spikeview.errors import ParameterError
from spikeview.guided.schedule import StepOutput


def start_timestep(alphas_cumprod: torch.Tensor, sigma: float) -> int:
    """``t_s`` for pixel noise level ``sigma`` (fraction of 1): the first ``t`` with ``√((1−ᾱ_t)/ᾱ_t) >= 2σ``."""
    abar = torch.as_tensor(alphas_cumprod, dtype=torch.float64)
    target = 1.0 / (1.0 + (2.0 * float(sigma)) ** 2)
    below = torch.nonzero(abar <= target)
    return int(below[0]) if below.numel() else int(abar.numel()) - 1


class DDIMLadder:
    """DDIM (Song et al. 2021) over ``steps`` timesteps evenly spaced from ``t_start`` down to ~0.

    diffusers' shape: :meth:`set_timesteps` fixes the ladder, :meth:`step` goes from ``z_t`` to
    ``z_{t−1}`` given ``ẑ₀`` and ``ε̂`` and returns both the new sample and ``ẑ₀``. The last step
    lands on the clean latent (``ᾱ = 1``).

    Args:
        alphas_cumprod: ``(T,)`` ``ᾱ_t`` of the model's training schedule.
    """

    def __init__(self, alphas_cumprod: torch.Tensor):
        self.alphas_cumprod = torch.as_tensor(alphas_cumprod, dtype=torch.float64).cpu()
        self.timesteps = np.zeros(0, dtype=np.int64)
        self._abar = np.zeros(0)
        self._abar_prev = np.zeros(0)

    def set_timesteps(self, steps: int, t_start: int) -> np.ndarray:
        """Fix the ladder: ``steps`` distinct integer timesteps, the first ``t_start``.

        Returns:
            ``(steps,)`` int64 descending timesteps (also ``self.timesteps``).
        """
        n = int(self.alphas_cumprod.numel())
        if not 0 <= t_start < n:
            raise ParameterError(f"start timestep {t_start} is outside the model's schedule [0, {n}).")
        ts = np.rint(np.linspace(t_start, 0, steps + 1)[:-1]).astype(np.int64)
        if steps > 1 and np.any(np.diff(ts) >= 0):
            raise ParameterError(
                f"steps = {steps} is more than the start timestep t_s = {t_start} allows: use at most {max(t_start, 1)} steps or a larger t_start."
            )
        abar = self.alphas_cumprod.numpy()
        self.timesteps = ts
        self._abar = abar[ts]
        self._abar_prev = np.concatenate([abar[ts[1:]], [1.0]])
        return ts

    def sigma(self, index: int, like: torch.Tensor) -> torch.Tensor:
        """Noise-to-signal ratio ``√((1 − ᾱ_t)/ᾱ_t)`` of step ``index`` as a ``(1, 1, 1, 1)`` tensor (for reports)."""
        a = float(self._abar[index])
        return torch.full((1, 1, 1, 1), math.sqrt((1 - a) / a), dtype=like.dtype, device=like.device)

    def alpha_bar(self, index: int) -> tuple[float, float]:
        """``(ᾱ_t, ᾱ_{t−1})`` of step ``index`` (``ᾱ_{t−1} = 1`` after the last step)."""
        return float(self._abar[index]), float(self._abar_prev[index])

    def step(self, z0: torch.Tensor, eps: torch.Tensor, index: int, eta: float = 0.0,
             noise: torch.Tensor | None = None) -> StepOutput:
        """``z_{t−1} = √ᾱ_{t−1}·ẑ₀ + √(1 − ᾱ_{t−1} − σ²)·ε̂ + σ·z`` with DDIM's
        ``σ = η·√((1 − ᾱ_{t−1})/(1 − ᾱ_t))·√(1 − ᾱ_t/ᾱ_{t−1})``.

        Args:
            z0: predicted clean latent ẑ₀.
            eps: predicted unit noise ε̂.
            index: step index in ``[0, steps)``.
            eta: DDIM η in [0, 1]; ``noise`` (N(0, I), ``z0``'s shape) is needed when > 0.
            noise: fresh noise.
        """
        if not 0 <= index < len(self.timesteps):
            raise ParameterError(f"step index {index} is outside [0, {len(self.timesteps)}); call set_timesteps first.")
        a, a_prev = self.alpha_bar(index)
        sigma = 0.0
        if eta > 0 and a_prev < 1.0:
            sigma = eta * math.sqrt((1 - a_prev) / (1 - a)) * math.sqrt(max(1 - a / a_prev, 0.0))
        out = math.sqrt(a_prev) * z0 + math.sqrt(max(1 - a_prev - sigma * sigma, 0.0)) * eps
        if sigma > 0:
            if noise is None:
                raise ParameterError("DDIM with eta > 0 needs fresh noise; pass noise=.")
            out = out + sigma * noise
        return StepOutput(out, z0)


class LatentDPSGuidance:
    """DPS in the latent space of a :class:`~spikeview.guided.priors.sd.LatentDiffusionPrior` (module docstring).

    Args:
        s: step size on ``∇_{Z_t} L`` (0 = unguided DDIM, plain SDEdit).
        size: ``(H, W)`` of the observation (the decoded image is cropped to it).
    """

    needs_grad = True

    def __init__(self, s: float, size: tuple[int, int]):
        self.s = float(s)
        self.size = size
        #: data loss ``L`` of each step of the last run
        self.losses: list[float] = []

    def step(self, prior: Any, schedule: DDIMLadder, data: Any, z_t: torch.Tensor, index: int, sigma: torch.Tensor, *,
             zeta: float = 0.0, generator: torch.Generator | None = None, transform: int | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        h, w = self.size
        t = int(schedule.timesteps[index])
        guide = self.s > 0
        with torch.enable_grad() if guide else torch.no_grad():
            z_in = z_t.detach().requires_grad_(guide)
            eps, z0 = prior.predict(z_in, t)
            x0 = prior.decode(z0)[..., :h, :w].clamp(0.0, 1.0)
            grad = None
            if guide:
                xin = x0.mean(dim=1, keepdim=True) if data.forward.channels == 1 else x0
                loss = data.norm(xin)
                (grad,) = torch.autograd.grad(loss, z_in)
                self.losses.append(float(loss.detach()))
        fresh = None
        if zeta > 0:
            fresh = torch.randn(z_t.shape, generator=generator, dtype=torch.float32).to(z_t.device)
        z = schedule.step(z0.detach(), eps.detach(), index, zeta, fresh).prev_sample
        if grad is not None:
            z = z - self.s * grad
        x0 = x0.detach()
        if data.forward.channels == 1:
            x0 = x0.mean(dim=1, keepdim=True)
        return z.detach(), x0

    def __repr__(self) -> str:
        return f"LatentDPSGuidance(s={self.s:g})"


class LatentSpace:
    """Where a latent prior's samples live: encode the start, decode the end (module docstring)."""

    def __init__(self, prior: Any, size: tuple[int, int], channels: int):
        self.prior = prior
        self.size = size
        self.channels = channels

    def start(self, x_start: torch.Tensor, schedule: DDIMLadder, generator: torch.Generator) -> torch.Tensor:
        """``Z_ts`` from Y₀ ``(1, C, H, W)`` in [0, 1] (gray repeated to RGB; padded to the VAE factor)."""
        prior = self.prior
        x = torch.nan_to_num(x_start, nan=0.0).clamp(0.0, 1.0)
        if x.shape[1] == 1:
            x = x.expand(-1, 3, -1, -1)
        f = prior.vae_factor
        h, w = self.size
        pad_h, pad_w = (-h) % f, (-w) % f
        if pad_h or pad_w:
            x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
        with torch.no_grad():
            z_enc = prior.encode(x.contiguous().to(prior.device))
        a_s = prior.alpha_bar(int(schedule.timesteps[0]))
        noise = torch.randn(z_enc.shape, generator=generator, dtype=torch.float32).to(z_enc.device)
        return math.sqrt(a_s) * z_enc + math.sqrt(1.0 - a_s) * noise

    def finish(self, z: torch.Tensor) -> torch.Tensor:
        """``clamp(D(Z_0), 0, 1)`` cropped, on the CPU (gray: the channel mean)."""
        h, w = self.size
        with torch.no_grad():
            x = self.prior.decode(z)[..., :h, :w].clamp(0.0, 1.0).float().cpu()
        return x.mean(dim=1, keepdim=True) if self.channels == 1 else x


def make_ladder(prior: Any, steps: int, t_start: float) -> DDIMLadder:
    """The DDIM ladder of ``prior`` for ``steps`` steps from the pixel noise level ``t_start``."""
    if not t_start > 0:
        raise ParameterError("the sd prior starts from a noised latent: set the start noise t_s above 0.")
    ladder = DDIMLadder(prior.alphas_cumprod)
    ladder.set_timesteps(steps, start_timestep(prior.alphas_cumprod, t_start))
    return ladder


