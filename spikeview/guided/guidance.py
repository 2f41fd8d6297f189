"""Guidance rules: how the data term steers one sampler step.

A rule takes the current sample ``x_t`` and returns ``(x_{t-1}, x̂₀)`` given the prior, the schedule
and the data term. Two rules (METHOD.md):

* :class:`DPSGuidance` (Chung et al., diffusion posterior sampling): ``x̂₀ = D(x_t, σ_t)`` with
  autograd on, ``L = Σ_l ‖P_l(√w̃ (A(clamp(x̂₀)) − y))‖`` (the **non-squared** norm, as the DPS
  reference code), ``x_{t-1} = step(x_t, x̂₀) − s·∇_{x_t} L``. One forward and one backward pass of
  the prior per step. To keep every ``s`` finite, ``x_{t-1}`` is clamped to ``[-1, 2]`` (a sample
  outside that range is no longer near the image manifold the prior was trained on).
* :class:`HQSGuidance` (DiffPIR / DPIR, half-quadratic splitting): ``x̂₀ = D(x_t, σ_t)`` without
  autograd, then a data step on x̂₀ itself: ``argmin_x ½‖P r(x)‖² + ρ_t/2 ‖x − x̂₀‖²`` with
  ``ρ_t = λ σ_n² / σ_t²`` (:meth:`DataTerm.prox`), then re-noising to σ_{t-1} mixing the predicted
  noise and fresh noise with ζ (:meth:`VESchedule.step`). One prior call per step.

Both optionally rotate/flip the prior's input by a different one of the 8 dihedral transforms per
step (periodic geometric self-ensemble, as DPIR): the prior is not exactly equivariant, so its
artefacts then change place from step to step and average out, at no extra cost.
"""

from __future__ import annotations

from typing import Protocol

import torch

from spikeview.guided.likelihood import DataTerm
from spikeview.guided.priors.base import DenoiserPrior
from spikeview.guided.schedule import VESchedule


def _dihedral(x: torch.Tensor, k: int, inverse: bool = False) -> torch.Tensor:
    """The ``k``-th of the 8 rotations/flips of the last two axes (or its inverse)."""
    rot, flip = k % 4, k >= 4
    if not inverse:
        x = torch.rot90(x, rot, (2, 3))
        return x.flip(3) if flip else x
    x = x.flip(3) if flip else x
    return torch.rot90(x, -rot, (2, 3))


def denoise(prior: DenoiserPrior, x: torch.Tensor, sigma: torch.Tensor, transform: int | None = None) -> torch.Tensor:
    """``prior.denoise(x, σ)``, through dihedral transform ``transform`` (``None`` = identity).

    ``sigma`` is ``(1, C, 1, 1)`` (per channel) or ``(1, C, H, W)`` (per pixel).
    """
    s = sigma.reshape(sigma.shape[0], sigma.shape[1]) if sigma.shape[-2:] == (1, 1) else sigma
    if transform is None or transform == 0:
        return prior.denoise(x, s)
    xt = _dihedral(x, transform)
    st = _dihedral(s, transform) if s.ndim == 4 else s
    return _dihedral(prior.denoise(xt, st), transform, inverse=True)


class GuidanceRule(Protocol):
    """One guided step: ``(x_{t-1}, x̂₀) = rule.step(...)``."""

    needs_grad: bool

    def step(self, prior: DenoiserPrior, schedule: VESchedule, data: DataTerm, x_t: torch.Tensor, index: int,
             sigma: torch.Tensor, *, zeta: float, generator: torch.Generator | None,
             transform: int | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Return the next sample and the clean estimate x̂₀ (both detached, ``x_t``'s shape)."""
        ...


class DPSGuidance:
    """Diffusion posterior sampling with the non-squared residual norm (see the module docstring).

    Args:
        s: step size ``s >= 0`` on ``∇_{x_t} ‖P(Y) − P(A(x̂₀))‖`` (0 = unguided sampling).
    """

    needs_grad = True

    def __init__(self, s: float):
        self.s = float(s)

    def step(self, prior, schedule, data, x_t, index, sigma, *, zeta=0.0, generator=None, transform=None):
        with torch.enable_grad():
            xs = x_t.detach().clone().requires_grad_(True)
            x0 = denoise(prior, xs, sigma, transform)
            loss = data.norm(x0.clamp(0.0, 1.0))
            (grad,) = torch.autograd.grad(loss, xs)
        x0 = x0.detach()
        grad = torch.nan_to_num(grad, nan=0.0, posinf=0.0, neginf=0.0)
        prev = schedule.step(x0, index, x_t.detach(), zeta=zeta, generator=generator).prev_sample
        prev = (prev - self.s * grad).clamp(-1.0, 2.0)
        return prev.detach(), x0

    def __repr__(self) -> str:
        return f"DPSGuidance(s={self.s:g})"


class HQSGuidance:
    """DiffPIR/HQS: data steps on x̂₀, no backpropagation through the prior (see the module docstring).

    Args:
        lam: λ > 0 in ``ρ_t = λ σ_n² / σ_t²`` (larger = trust the prior more).
        data_steps: preconditioned gradient steps of the data sub-problem per sampler step (0 = none:
            unguided).
        renoise: re-noise x̂₀ to σ_{t-1} between steps (DiffPIR) or hand x̂₀ on (DPIR).
        s: weight of the data step against the prior: ``x̂₀ ← x̂₀ + s·(prox(x̂₀) − x̂₀)`` (1 = the
            full proximal step, 0 = the prior's estimate alone, > 1 over-relaxed).
    """

    needs_grad = False

    def __init__(self, lam: float, data_steps: int, renoise: bool, s: float):
        self.lam = float(lam)
        self.s = float(s)
        self.data_steps = int(data_steps)
        self.renoise = bool(renoise)

    def step(self, prior, schedule, data, x_t, index, sigma, *, zeta=0.0, generator=None, transform=None):
        with torch.no_grad():
            x0 = denoise(prior, x_t, sigma, transform)
        # MAP weights: data ½Σ(Ax−y)²/σ_p², prior ½‖x−x̂₀‖²/σ_t²; times σ_n² gives w̃ and ρ_t = σ_n²/σ_t²
        # (the residual is in sensor units, x̂₀ in image units: the cast gain sits inside A).
        sig = sigma.mean(dim=(2, 3), keepdim=True) if sigma.shape[-2:] != (1, 1) else sigma
        rho = self.lam * data.sigma_n2 / sig.clamp_min(1e-6) ** 2
        x_data = data.prox(x0, rho, self.data_steps)
        # s weighs the data step against the prior: 1 takes it fully, 0 keeps the prior's estimate
        x0 = x_data if self.s == 1.0 else (x0.clamp(0.0, 1.0) + self.s * (x_data - x0.clamp(0.0, 1.0))).clamp(0.0, 1.0)
        if not self.renoise:  # DPIR: hand x̂₀ itself to the next, lower noise level
            return x0, x0
        prev = schedule.step(x0, index, x_t.detach(), zeta=zeta, generator=generator).prev_sample
        return prev.detach(), x0

    def __repr__(self) -> str:
        return f"HQSGuidance(lam={self.lam:g}, data_steps={self.data_steps}, s={self.s:g})"

