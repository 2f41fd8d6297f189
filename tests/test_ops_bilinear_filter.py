"""The slice-based bilinear filter (demosaicking and its variance propagation) equals the grouped
convolution it replaced, for every CFA, odd and even sizes, batches, float64, and gradients."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from spikeview.ops.mosaic import _kernels, bilinear_filter, demosaic_bilinear
from spikeview.ops.noise import demosaic_variance


def reference(z: torch.Tensor, squared: bool) -> torch.Tensor:
    return F.conv2d(F.pad(z, (1, 1, 1, 1), mode="reflect"), _kernels(z, squared), groups=3)


@pytest.mark.parametrize("squared", [False, True])
@pytest.mark.parametrize("shape", [(1, 3, 2, 2), (2, 3, 7, 10), (1, 3, 64, 33)])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_filter_is_the_grouped_convolution(shape, squared, dtype):
    z = torch.rand(shape, dtype=dtype, generator=torch.Generator().manual_seed(sum(shape)))
    tol = 1e-6 if dtype == torch.float32 else 1e-12
    assert torch.allclose(bilinear_filter(z, squared), reference(z, squared), atol=tol, rtol=0)


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_demosaic_and_its_variance_and_gradient(cfa):
    from spikeview.ops.mosaic import mosaic_adjoint
    from spikeview.ops._checks import cfa_masks

    y = torch.rand(1, 1, 12, 18, dtype=torch.float64, requires_grad=True)
    out = demosaic_bilinear(y, cfa)
    assert torch.allclose(out, reference(mosaic_adjoint(y, cfa), False), atol=1e-12)
    g = torch.rand_like(out)
    (grad,) = torch.autograd.grad((out * g).sum(), y)
    yy = y.detach().clone().requires_grad_(True)
    (ref,) = torch.autograd.grad((reference(mosaic_adjoint(yy, cfa), False) * g).sum(), yy)
    assert torch.allclose(grad, ref, atol=1e-12)
    v = torch.rand(1, 1, 12, 18, dtype=torch.float64)
    z = v * cfa_masks(cfa, 12, 18, v)
    assert torch.allclose(demosaic_variance(v, cfa), reference(z, True), atol=1e-12)
