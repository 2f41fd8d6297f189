"""The data term of the guided sampler: the forward model A = Q∘C∘M, the noise weights and the pyramid.

For a scene estimate ``x`` (``(1, C, H, W)`` in [0, 1]) and the observed mosaicked TFP ``y``
(``(1, 1, H, W)``), the whitened residual is

    r(x) = √w̃ ⊙ (A(x) − y),     w̃_p = σ_n² / Var[y_p],     σ_n² = 1 / mean_p(1 / Var[y_p]),

so ``w̃`` has mean 1 (the residual stays in SFR units, the convention of the DPS reference code)
and dark/saturated/low-variance photosites are trusted more than mid-grey ones, as the binomial TFP
noise says (variance from :meth:`Observation.variance`, the ops noise model scaled to the data).
Two losses are built on the Laplacian pyramid ``P`` with ``levels + 1`` bands
(:func:`spikeview.ops.pyramid.multiscale_loss`; ``levels = 0`` is the plain residual):

* :meth:`DataTerm.norm`: ``Σ_l ‖P_l(r(x))‖`` (non-squared, DPS),
* :meth:`DataTerm.squared`: ``½ Σ_l ‖P_l(r(x))‖²`` (HQS), whose minimiser with a proximity term
  ``ρ/2 ‖x − z‖²`` is approached by :meth:`DataTerm.prox`.
"""

from __future__ import annotations

from typing import Any

import torch

from spikeview.ops.forward import ForwardModel
from spikeview.ops.mosaic import demosaic_bilinear, mosaic_adjoint
from spikeview.ops.pyramid import multiscale_loss


class DataTerm:
    """Weighted multiscale data term for one observation (see the module docstring).

    Args:
        forward: the forward model A (ops), configured with the plan's stages.
        y: ``(1, 1, H, W)`` observed TFP.
        variance: ``(1, 1, H, W)`` positive per-photosite variance of ``y``.
        levels: pyramid levels (band-pass levels; ``levels + 1`` bands, 0 = plain residual).
    """

    def __init__(self, forward: ForwardModel, y: torch.Tensor, variance: torch.Tensor, levels: int):
        self.forward = forward
        self.y = y
        inv = 1.0 / variance.clamp_min(1e-8)
        self.sigma_n2 = float(1.0 / inv.mean())
        self.w = (inv * self.sigma_n2).to(y.dtype)
        self.sqrt_w = self.w.sqrt()
        self.bands = int(levels) + 1

    def _loss(self, x: torch.Tensor, norm: str) -> torch.Tensor:
        pred = self.forward(x)
        return multiscale_loss(self.sqrt_w * pred, self.sqrt_w * self.y, self.bands, None, norm, "sum")

    def stages(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """What the sampler's data term computes for ``x``, stage by stage (the app's degradation preview).

        :meth:`ForwardModel.stages` (``x``, ``mx``, ``cmx``, ``a``) plus ``y`` (the observation),
        ``residual`` = ``√w̃ (A(x) − y)`` (the noise-weighted residual the loss sees) and ``bands``
        (its Laplacian pyramid with this term's bands, finest first; one band = no pyramid).
        """
        from spikeview.ops.pyramid import laplacian_pyramid

        out: dict[str, Any] = dict(self.forward.stages(x))
        res = self.sqrt_w * (out["a"] - self.y)
        out.update(y=self.y, residual=res, bands=laplacian_pyramid(res, self.bands))
        return out

    def norm(self, x: torch.Tensor) -> torch.Tensor:
        """``Σ_l ‖P_l(√w̃ (A(x) − y))‖`` (scalar, differentiable in ``x``)."""
        return self._loss(x, "l2")

    def squared(self, x: torch.Tensor) -> torch.Tensor:
        """``½ Σ_l ‖P_l(√w̃ (A(x) − y))‖²`` (scalar, differentiable in ``x``)."""
        return 0.5 * self._loss(x, "l2sq")

    def _curvature(self, x: torch.Tensor) -> torch.Tensor:
        """Diagonal preconditioner of :meth:`squared`, spread like M's backward pass.

        ``w̃_p g_c²`` with ``g_c`` the cast gain of the photosite's channel, put back on the image
        grid with the mosaic's adjoint (exact M) or its bilinear spread (dense gradient). Q is
        taken with its mean slope 1 (its local slope swings between ~0 on a level and ``k/(2Δτ)``
        between levels, which would make Gauss–Newton steps jump), and the pyramid as energy
        preserving (``‖P r‖ ≈ ‖r‖``).
        """
        fm = self.forward
        if fm.cfa is None:
            return self.w
        # the same for every step of a window (it depends on the weights and the cast, not on x's values)
        key = (tuple(x.shape), x.dtype, x.device, id(self.w), self.w._version, id(fm))
        cached = getattr(self, "_curv_cache", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        curv = self._curvature_of(x)
        self._curv_cache = (key, curv)
        return curv

    def _curvature_of(self, x: torch.Tensor) -> torch.Tensor:
        fm = self.forward
        gain = torch.ones(1, 3, 1, 1, dtype=x.dtype, device=x.device) if fm.cast is None else (fm.cast.eta / fm.cast.alpha.to(x.dtype)).view(1, 3, 1, 1)
        from spikeview.ops.mosaic import mosaic

        slope = mosaic(gain.expand_as(x), fm.cfa)
        curv = self.w * slope * slope
        if fm.mosaic is not None and fm.mosaic.dense_grad:
            return demosaic_bilinear(curv, fm.cfa)
        return mosaic_adjoint(curv, fm.cfa)

    def prox(self, z: torch.Tensor, rho: float | torch.Tensor, steps: int = 1) -> torch.Tensor:
        """Approximate ``argmin_x ½ Σ_l ‖P_l r(x)‖² + ρ/2 ‖x − z‖²`` by preconditioned gradient steps from ``z``.

        Each step is ``x ← x − ∇f(x) / (curvature + ρ)`` (Jacobi/Gauss–Newton); for the exact
        mosaic, no pyramid and a linear A the first step is the closed-form proximal point.

        Args:
            z: ``(1, C, H, W)`` prior estimate (x̂₀), detached.
            rho: proximity weight ρ > 0 (a number or ``(1, C, 1, 1)``).
            steps: number of steps (0 returns ``z``).

        Returns:
            ``(1, C, H, W)`` detached estimate clamped to [0, 1].
        """
        x = z.detach().clamp(0.0, 1.0)
        for _ in range(int(steps)):
            with torch.enable_grad():
                xs = x.clone().requires_grad_(True)
                f = self.squared(xs)
                (grad,) = torch.autograd.grad(f, xs)
            curv = self._curvature(x)
            x = (x - (grad + rho * (x - z)) / (curv + rho)).clamp(0.0, 1.0).detach()
        return x
