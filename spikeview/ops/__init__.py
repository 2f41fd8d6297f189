"""Differentiable camera operators (torch): the SpikeDiff forward model ``A = Q ∘ C ∘ M``.

Images are ``(N, 3, H, W)`` (monochrome ``(N, 1, H, W)``) float tensors in [0, 1]; mosaics and TFP
observations are ``(N, 1, H, W)``. CFAs are named by their top-left 2×2 after flips
(:mod:`spikeview.cfa`), channels 0 = R, 1 = G, 2 = B. Every operator is a pure function plus a thin
``nn.Module`` storing its settings; linear ones have an exact adjoint.

* M: :func:`mosaic`, :func:`mosaic_adjoint`, :func:`mosaic_dense_grad`, :class:`Mosaic`
  (and the torch :func:`demosaic_bilinear`)
* C: :func:`colour_cast`, :func:`colour_cast_inverse`, :func:`estimate_alpha`, :class:`ColourCast`
* Q: :func:`soft_quantise`, :func:`hard_quantise`, :class:`SoftQuantise`
* P: :func:`laplacian_pyramid` (+ adjoint, synthesis), :func:`multiscale_loss`
* noise: :func:`tfp_variance`, :func:`binomial_vst`, :func:`effective_sigma`
* :class:`ForwardModel`: ``A`` with its multiscale loss
"""

from spikeview.ops.cast import ColourCast, colour_cast, colour_cast_inverse, estimate_alpha
from spikeview.ops.forward import ForwardModel
from spikeview.ops.mosaic import Mosaic, demosaic_bilinear, mosaic, mosaic_adjoint, mosaic_dense_grad
from spikeview.ops.noise import (
    binomial_vst,
    binomial_vst_inverse,
    demosaic_variance,
    effective_sigma,
    tfp_variance,
)
from spikeview.ops.pyramid import (
    LaplacianPyramid,
    laplacian_pyramid,
    laplacian_pyramid_adjoint,
    laplacian_synthesis,
    max_pyramid_bands,
    multiscale_loss,
    pyr_down,
    pyr_down_adjoint,
    pyr_up,
    pyr_up_adjoint,
)
from spikeview.ops.quantise import SoftQuantise, hard_quantise, soft_quantise

__all__ = [
    "ColourCast",
    "ForwardModel",
    "LaplacianPyramid",
    "Mosaic",
    "SoftQuantise",
    "binomial_vst",
    "binomial_vst_inverse",
    "colour_cast",
    "colour_cast_inverse",
    "demosaic_bilinear",
    "demosaic_variance",
    "effective_sigma",
    "estimate_alpha",
    "hard_quantise",
    "laplacian_pyramid",
    "laplacian_pyramid_adjoint",
    "laplacian_synthesis",
    "max_pyramid_bands",
    "mosaic",
    "mosaic_adjoint",
    "mosaic_dense_grad",
    "multiscale_loss",
    "pyr_down",
    "pyr_down_adjoint",
    "pyr_up",
    "pyr_up_adjoint",
    "soft_quantise",
    "tfp_variance",
]
