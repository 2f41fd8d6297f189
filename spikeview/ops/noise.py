"""Noise model of TFP observations and the effective noise level handed to the prior.

Model: a photosite with firing probability ``p`` per tick (``p = rate · intensity``, cast included)
fires ``n`` times in a window of Δτ ticks; treating the ticks as independent Bernoulli trials,
``n ~ Binomial(Δτ, p)`` and the TFP value ``Y = n / Δτ`` has

    E[Y] = p,     Var[Y] = p (1 − p) / Δτ.

This is an upper bound for a noise-free integrate-and-fire pixel with a random initial voltage
(whose count is ``floor(pΔτ + U)``, variance ≤ 1/(4Δτ²)); sensor noise (shot noise, threshold
jitter, SCSim's constants) moves real data towards it. Photosites are independent.

* :func:`tfp_variance` evaluates ``Var[Y]`` at a smoothed rate estimate ``p̃ = (nΔτ + a)/(Δτ + 2a)``
  (``a = ½``: Jeffreys/Krichevsky–Trofimov), which floors the variance where ``Y ∈ {0, 1}`` (no
  spike or a spike every tick says little about how close ``p`` is to 0 or 1).
* :func:`binomial_vst` is Anscombe's (1948) arcsine transform for binomial counts; its output
  has variance ≈ 1 where ``Δτ·p(1 − p)`` is not small, so Gaussian guidance on it is justified.
* :func:`effective_sigma` propagates the photosite variances through bilinear demosaicking and the
  colour correction, giving the noise level of the initial estimate ``Y₀`` per channel.
"""

from __future__ import annotations

import math

import torch

from spikeview.errors import ParameterError
from spikeview.ops._checks import cfa_masks, check_cfa, check_image, check_positive_int
from spikeview.ops.cast import _alpha_gain, _check_eta, estimate_alpha
from spikeview.ops.mosaic import bilinear_filter


def _check_prior(prior: float) -> float:
    prior = float(prior)
    if not (prior >= 0 and math.isfinite(prior)):
        raise ParameterError(f"prior (pseudo-count) must be a finite number >= 0, got {prior}; the default 0.5 is the Jeffreys prior.")
    return prior


def tfp_variance(y: torch.Tensor, window: int, prior: float = 0.5) -> torch.Tensor:
    """Per-photosite variance of TFP values under the binomial model.

    ``Var[Y] = p̃ (1 − p̃) / Δτ`` with ``p̃ = (Y·Δτ + a) / (Δτ + 2a)`` (``Y`` clipped to [0, 1]).
    With ``a > 0`` the variance is floored where ``Y ∈ {0, 1}`` at
    ``a (Δτ + a) / ((Δτ + 2a)² Δτ)`` (0.0043 for Δτ = 10, a = ½, i.e. σ ≈ 0.066).

    Args:
        y: float tensor of TFP values (any shape, e.g. ``(N, 1, H, W)``), nominally in ``{0, 1/Δτ, …, 1}``.
        window: Δτ, the TFP window in ticks.
        prior: pseudo-count ``a >= 0`` (``0`` gives the plug-in ``Y(1 − Y)/Δτ``, zero at 0 and 1).

    Returns:
        Tensor shaped like ``y`` of variances in SFR² units, ``> 0`` when ``prior > 0``.
    """
    n = check_positive_int(window, "window")
    a = _check_prior(prior)
    p = (y.clamp(0.0, 1.0) * n + a) / (n + 2 * a)
    return p * (1.0 - p) / n


def binomial_vst(y: torch.Tensor, window: int) -> torch.Tensor:
    """Anscombe's variance-stabilising transform for binomial counts, on SFR values.

    ``z = 2 √(Δτ + ½) · asin √((Y·Δτ + ⅜) / (Δτ + ¾))``; ``Var[z] ≈ 1`` for ``Y = n/Δτ``,
    ``n ~ Binomial(Δτ, p)`` with ``Δτ p (1 − p)`` not small (less near ``p ∈ {0, 1}``).

    Args:
        y: float tensor (any shape), clipped to [0, 1] (zero gradient outside).
        window: Δτ in ticks.

    Returns:
        Tensor shaped like ``y``, values in ``[z(0), z(1)]`` (about [1.22, 8.96] for Δτ = 10); finite,
        with finite gradients everywhere.
    """
    n = check_positive_int(window, "window")
    t = (y.clamp(0.0, 1.0) * n + 0.375) / (n + 0.75)
    return 2.0 * math.sqrt(n + 0.5) * torch.asin(torch.sqrt(t))


def binomial_vst_inverse(z: torch.Tensor, window: int) -> torch.Tensor:
    """Algebraic inverse of :func:`binomial_vst` (not an unbiased inverse), clipped to [0, 1]."""
    n = check_positive_int(window, "window")
    s = torch.sin((z / (2.0 * math.sqrt(n + 0.5))).clamp(0.0, math.pi / 2))
    return ((s * s * (n + 0.75) - 0.375) / n).clamp(0.0, 1.0)


def demosaic_variance(v: torch.Tensor, cfa: str) -> torch.Tensor:
    """Variance of :func:`~spikeview.ops.mosaic.demosaic_bilinear` output for independent photosites.

    ``Var[D y]_i = Σ_j w_ij² v_j`` with the bilinear weights (an interpolated value averaging 2 or 4
    photosites has ½ or ¼ of their variance). At the one-pixel border, mirrored neighbours are
    the same photosite counted twice; they are treated as independent there (slight underestimate).

    Args:
        v: ``(N, 1, H, W)`` per-photosite variances, ``H, W >= 2``.
        cfa: Bayer pattern of the mosaic's top-left 2×2.

    Returns:
        ``(N, 3, H, W)`` per-pixel, per-channel variances.
    """
    name = check_cfa(cfa)
    check_image(v, 1, "v", min_size=2)
    return bilinear_filter(v * cfa_masks(name, v.shape[-2], v.shape[-1], v), squared=True)


def effective_sigma(
    y: torch.Tensor,
    cfa: str | None,
    window: int,
    alpha: torch.Tensor | tuple[float, float, float] | None = None,
    eta: float = 1.0,
    prior: float = 0.5,
    per_pixel: bool = False,
) -> torch.Tensor:
    """Noise level σ of the demosaicked, colour-corrected TFP estimate ``Y₀``, from the data.

    ``Y₀_c = (α_c / η) · demosaic_bilinear(Y)_c`` (mono: ``Y₀ = Y``). Its noise variance is
    ``(α_c / η)² · demosaic_variance(tfp_variance(Y))_c``; the returned σ is its root mean over the
    pixels of each frame (the RMS noise, what a denoiser's noise map expects), or the per-pixel root
    with ``per_pixel=True``. Demosaicking error (aliasing) is not included, and bilinear
    interpolation makes the noise spatially correlated.

    Args:
        y: ``(N, 1, H, W)`` mosaicked TFP values in [0, 1] (``H, W >= 2`` for a Bayer CFA).
        cfa: Bayer pattern of ``y``'s top-left 2×2, or ``None`` for monochrome.
        window: Δτ in ticks.
        alpha: ``(3,)`` (or ``(N, 3)``) gray-world factors of the sequence; ``None`` estimates them
            from ``y`` with :func:`~spikeview.ops.cast.estimate_alpha`. Ignored for monochrome.
        eta: range parameter ``η`` of the cast (ignored for monochrome).
        prior: pseudo-count of :func:`tfp_variance`.
        per_pixel: return a per-pixel σ map instead of one σ per frame and channel.

    Returns:
        ``(N, 3)`` (mono ``(N, 1)``) σ in the [0, 1] units of ``Y₀``, or ``(N, 3 or 1, H, W)`` with
        ``per_pixel``; detached.
    """
    name = check_cfa(cfa, allow_mono=True)
    check_image(y, 1, "y", min_size=2 if name is not None else 1)
    with torch.no_grad():
        v = tfp_variance(y, window, prior)
        if name is not None:
            if alpha is None:
                alpha = estimate_alpha(y, name)
            gain = _alpha_gain(alpha, y) / _check_eta(eta)
            v = demosaic_variance(v, name) * gain * gain
        if per_pixel:
            return v.sqrt()
        return v.mean(dim=(2, 3)).sqrt()
