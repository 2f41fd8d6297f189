"""One parametrised suite for the differentiable operators of :mod:`spikeview.ops`.

Every operator goes through the same checks (deepinv/kornia style): float64 ``gradcheck``,
adjointness for the linear ones, shape errors naming expected vs. actual, output shape, all four
CFA phases and odd sizes. Operator-specific properties follow below the generic checks.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable

import numpy as np
import pytest
import torch

from spikeview import ops
from spikeview.cfa import BAYER_PATTERNS, channel_masks
from spikeview.errors import ParameterError

SIZES = [(8, 8), (7, 9)]  # even and odd
F64 = torch.float64


def _gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _rand(shape, seed=0, low=0.0, high=1.0):
    return low + (high - low) * torch.rand(*shape, generator=_gen(seed), dtype=F64)


@dataclasses.dataclass
class Case:
    """One operator under test.

    ``fn`` maps an ``(N, c_in, H, W)`` float64 tensor to a tensor or a list of tensors. For linear
    operators ``adjoint(y, x_shape)`` maps an output-shaped ``y`` back to the input's shape.
    ``channels="any"`` marks operators that take any channel count, ``"elementwise"`` any shape.
    """

    name: str
    fn: Callable
    c_in: int
    adjoint: Callable | None = None
    channels: str = "fixed"
    input_range: tuple[float, float] = (0.0, 1.0)


def _cases() -> list[Case]:
    alpha = torch.tensor([2.0, 1.25, 4.0], dtype=F64)
    cases: list[Case] = []
    for cfa in BAYER_PATTERNS:
        cases += [
            Case(f"mosaic-{cfa}", lambda x, c=cfa: ops.mosaic(x, c), 3, lambda y, s, c=cfa: ops.mosaic_adjoint(y, c)),
            Case(f"mosaic_adjoint-{cfa}", lambda y, c=cfa: ops.mosaic_adjoint(y, c), 1, lambda x, s, c=cfa: ops.mosaic(x, c)),
            Case(f"Mosaic-{cfa}", ops.Mosaic(cfa), 3, lambda y, s, c=cfa: ops.Mosaic(c).adjoint(y)),
            Case(f"demosaic_bilinear-{cfa}", lambda y, c=cfa: ops.demosaic_bilinear(y, c), 1),
            Case(f"demosaic_variance-{cfa}", lambda v, c=cfa: ops.demosaic_variance(v, c), 1),
            Case(f"ForwardModel-{cfa}", ops.ForwardModel(cfa, 10, alpha=alpha, eta=0.5, k=50.0, dense_grad=False), 3),
            Case(
                f"ForwardModel.loss-{cfa}",
                lambda x, c=cfa: ops.ForwardModel(c, 10, alpha=alpha, k=50.0, dense_grad=False, bands=2).loss(
                    x, torch.full((x.shape[0], 1) + x.shape[-2:], 0.3, dtype=x.dtype)
                ),
                3,
            ),
        ]
    cast = ops.ColourCast(alpha, 1.5)
    cases += [
        Case("colour_cast", lambda x: ops.colour_cast(x, alpha, 0.7), 3, lambda y, s: ops.colour_cast(y, alpha, 0.7)),
        Case(
            "colour_cast_inverse", lambda x: ops.colour_cast_inverse(x, alpha, 0.7), 3, lambda y, s: ops.colour_cast_inverse(y, alpha, 0.7)
        ),
        Case("ColourCast", cast, 3, lambda y, s: cast.adjoint(y)),
        Case("laplacian_pyramid-L3", lambda x: ops.laplacian_pyramid(x, 3), 3, lambda b, s: ops.laplacian_pyramid_adjoint(b), "any"),
        Case("LaplacianPyramid-L1", ops.LaplacianPyramid(1), 2, lambda b, s: ops.LaplacianPyramid(1).adjoint(b), "any"),
        Case("pyr_down", ops.pyr_down, 3, lambda c, s: ops.pyr_down_adjoint(c, tuple(s[-2:])), "any"),
        # expand a coarse (h, w) level to a (2h - 1, 2w) frame: odd and even fine sizes at once
        Case("pyr_up", lambda c: ops.pyr_up(c, (2 * c.shape[-2] - 1, 2 * c.shape[-1])), 3, lambda y, s: ops.pyr_up_adjoint(y), "any"),
        Case("soft_quantise-k50", lambda x: ops.soft_quantise(x, 10, 50.0), 3, channels="elementwise", input_range=(-0.2, 1.2)),
        Case("SoftQuantise-k3", ops.SoftQuantise(4, 3.0), 1, channels="elementwise", input_range=(-0.2, 1.2)),
        Case("tfp_variance", lambda y: ops.tfp_variance(y, 10), 1, channels="elementwise", input_range=(0.02, 0.98)),
        Case("binomial_vst", lambda y: ops.binomial_vst(y, 10), 1, channels="elementwise"),
        Case("ForwardModel-mono", ops.ForwardModel(None, 10, k=50.0), 1),
        Case("multiscale_loss-l2", lambda x: ops.multiscale_loss(x, torch.full_like(x, 0.5), 3, (1.0, 0.5, 2.0), "l2"), 3, channels="any"),
        Case("multiscale_loss-l2sq", lambda x: ops.multiscale_loss(x, torch.full_like(x, 0.5), 2, None, "l2sq", "none"), 3, channels="any"),
    ]
    return cases


CASES = _cases()


def _flat(out) -> list[torch.Tensor]:
    return list(out) if isinstance(out, (list, tuple)) else [out]


def _inner(a, b) -> torch.Tensor:
    return sum((p * q).sum() for p, q in zip(_flat(a), _flat(b), strict=True))


def _input(case: Case, size, seed=0, n=2):
    return _rand((n, case.c_in) + size, seed, *case.input_range)


# ---------------------------------------------------------------------------------- generic checks


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_output_finite_and_shaped(case, size):
    x = _input(case, size)
    for t in _flat(case.fn(x)):
        assert t.dtype == F64
        assert torch.isfinite(t).all()
        assert t.ndim == 0 or t.shape[0] == x.shape[0]


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_gradcheck_float64(case, size):
    x = _input(case, size, n=1).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda t: tuple(_flat(case.fn(t))), (x,), eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("case", [c for c in CASES if c.adjoint is not None], ids=lambda c: c.name)
def test_adjointness(case, size):
    x = _rand((2, case.c_in) + size, 1, -1.0, 1.0)
    ax = case.fn(x)
    y = [torch.randn(t.shape, generator=_gen(2 + i), dtype=F64) for i, t in enumerate(_flat(ax))]
    y = y if isinstance(ax, (list, tuple)) else y[0]
    lhs = _inner(ax, y)
    rhs = _inner(x, case.adjoint(y, x.shape))
    assert abs(float(lhs - rhs)) <= 1e-10 * max(1.0, abs(float(lhs)))
    # and the operator is linear: A(2x + 3x') = 2 Ax + 3 Ax'
    x2 = _rand(x.shape, 5, -1.0, 1.0)
    for got, a, b in zip(_flat(case.fn(2 * x + 3 * x2)), _flat(ax), _flat(case.fn(x2)), strict=True):
        torch.testing.assert_close(got, 2 * a + 3 * b)


@pytest.mark.parametrize("case", [c for c in CASES if c.channels != "elementwise"], ids=lambda c: c.name)
def test_shape_error_says_expected_and_actual(case):
    # fixed-channel operators: a wrong channel count; the others: a missing batch axis
    bad = _rand((2, case.c_in + 1, 8, 8)) if case.channels == "fixed" else _rand((case.c_in, 8, 8))
    with pytest.raises(ParameterError) as err:
        case.fn(bad)
    msg = str(err.value)
    assert str(tuple(bad.shape)) in msg  # actual
    assert "H, W)" in msg  # expected


def test_elementwise_ops_accept_any_shape():
    x = _rand((5, 2, 3))
    for f in (lambda t: ops.soft_quantise(t, 10, 50), lambda t: ops.tfp_variance(t, 10), lambda t: ops.binomial_vst(t, 10)):
        assert f(x).shape == x.shape


def test_too_small_for_demosaicking_says_minimum():
    with pytest.raises(ParameterError, match="at least 2x2"):
        ops.demosaic_bilinear(torch.zeros(1, 1, 1, 5), "RGGB")
    with pytest.raises(ParameterError, match="at least 2x2"):
        ops.mosaic_dense_grad(torch.zeros(1, 3, 5, 1), "RGGB")


def test_bad_settings_raise_parameter_error():
    x = torch.zeros(1, 3, 4, 4)
    with pytest.raises(ParameterError, match="Unknown CFA"):
        ops.mosaic(x, "RGBG")
    with pytest.raises(ParameterError, match="monochrome"):
        ops.mosaic(x, None)
    with pytest.raises(ParameterError, match="alpha"):
        ops.colour_cast(x, torch.tensor([1.0, 0.0, 1.0]))
    with pytest.raises(ParameterError, match=r"\(3,\)"):
        ops.colour_cast(x, torch.ones(2))
    with pytest.raises(ParameterError, match="eta"):
        ops.colour_cast(x, torch.ones(3), eta=0.0)
    with pytest.raises(ParameterError, match="k "):
        ops.soft_quantise(x, 10, -1.0)
    with pytest.raises(ParameterError, match="window"):
        ops.soft_quantise(x, 0, 1.0)
    with pytest.raises(ParameterError, match="weights"):
        ops.multiscale_loss(x, x, 2, (1.0,))
    with pytest.raises(ParameterError, match="norm"):
        ops.multiscale_loss(x, x, 1, norm="l1")
    with pytest.raises(ParameterError, match="shape of a"):
        ops.multiscale_loss(x, x[:, :1])
    with pytest.raises(ParameterError, match="y_obs must have shape"):
        ops.ForwardModel("RGGB").loss(x, torch.zeros(1, 1, 4, 5))
    with pytest.raises(TypeError, match="torch.Tensor"):
        ops.mosaic(np.zeros((1, 3, 4, 4)), "RGGB")


# ------------------------------------------------------------------------------------------- M


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_mosaic_keeps_the_cfa_channel(cfa, size):
    x = _rand((2, 3) + size)
    y = ops.mosaic(x, cfa)
    m = torch.from_numpy(channel_masks(cfa, *size)).permute(2, 0, 1)
    want = (x * m).sum(1, keepdim=True)
    torch.testing.assert_close(y, want)
    # top-left 2x2 follows the name: e.g. GRBG has G at (0,0), R at (0,1)
    idx = {"R": 0, "G": 1, "B": 2}
    for k, (i, j) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
        assert y[0, 0, i, j] == x[0, idx[cfa[k]], i, j]


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_dense_grad_fills_missing_channels_and_matches_adjoint_at_photosites(cfa, size):
    x = _rand((2, 3) + size).requires_grad_(True)
    g = torch.randn((2, 1) + size, generator=_gen(3), dtype=F64)
    y = ops.mosaic_dense_grad(x, cfa)
    torch.testing.assert_close(y, ops.mosaic(x.detach(), cfa))  # forward identical to M
    (dense,) = torch.autograd.grad(y, x, g)
    exact = ops.mosaic_adjoint(g, cfa)
    m = torch.from_numpy(channel_masks(cfa, *size)).permute(2, 0, 1).expand_as(dense)
    # at each photosite its own channel gets exactly the adjoint's gradient ...
    torch.testing.assert_close(dense[m], exact[m])
    # ... and every missing channel gets a gradient too (the exact adjoint gives zero there)
    assert (exact[~m] == 0).all()
    assert (dense[~m] != 0).all()
    # the backward is bilinear demosaicking of the incoming gradient
    torch.testing.assert_close(dense, ops.demosaic_bilinear(g, cfa))
    # interior: G at an R/B site is the mean of its 4 edge neighbours
    cmap = torch.from_numpy(channel_masks(cfa, *size).argmax(-1))
    i, j = 3, 3 if cmap[3, 3] != 1 else 4
    assert cmap[i, j] != 1
    want = (g[0, 0, i - 1, j] + g[0, 0, i + 1, j] + g[0, 0, i, j - 1] + g[0, 0, i, j + 1]) / 4
    torch.testing.assert_close(dense[0, 1, i, j], want)


def test_dense_grad_is_not_the_true_derivative():
    """gradcheck must fail for the dense variant: its backward deliberately differs from M's Jacobian."""
    x = _rand((1, 3, 4, 4)).requires_grad_(True)
    assert not torch.autograd.gradcheck(lambda t: ops.mosaic_dense_grad(t, "RGGB"), (x,), raise_exception=False)
    mod = ops.Mosaic("BGGR", dense_grad=True)
    torch.testing.assert_close(mod(x), ops.mosaic(x, "BGGR"))


@pytest.mark.parametrize("size", [(8, 8), (7, 9), (2, 2), (3, 2)], ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_demosaic_bilinear_matches_the_numpy_implementation(cfa, size):
    bilinear = pytest.importorskip("spikeview.classical.demosaic.bilinear")
    y = np.random.default_rng(4).random(size).astype(np.float32)
    want = bilinear.demosaic_bilinear(y, cfa)
    got = ops.demosaic_bilinear(torch.from_numpy(y)[None, None], cfa)[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


# ------------------------------------------------------------------------------------------- C


def test_estimate_alpha_gray_world_and_cast_round_trip():
    gain = torch.tensor([0.5, 0.8, 0.25], dtype=F64)  # sensor response per channel
    x = _rand((3, 3, 8, 8), 6, 0.2, 0.8)
    y = ops.mosaic(x * gain[None, :, None, None], "GBRG")
    alpha = ops.estimate_alpha(y, "GBRG")
    m = torch.from_numpy(channel_masks("GBRG", 8, 8)).permute(2, 0, 1)[None]
    means = (y * m).sum((0, 2, 3)) / (m.sum((0, 2, 3)) * 3)
    torch.testing.assert_close(alpha, 1.0 / means)
    # the corrected estimate has channel means 1/eta (gray world), whatever the sensor gain
    eta = 2.0
    rgb = ops.colour_cast_inverse(ops.mosaic_adjoint(y, "GBRG"), alpha, eta)
    torch.testing.assert_close((rgb * m).sum((0, 2, 3)) / (m.sum((0, 2, 3)) * 3), torch.full((3,), 1 / eta, dtype=F64))
    torch.testing.assert_close(ops.colour_cast_inverse(ops.colour_cast(x, alpha, eta), alpha, eta), x)
    # per-frame alpha broadcasts over the batch
    per_frame = alpha[None].expand(3, 3)
    torch.testing.assert_close(ops.colour_cast(x, per_frame, eta), ops.colour_cast(x, alpha, eta))


def test_estimate_alpha_is_safe_for_dark_channels():
    y = torch.zeros(2, 1, 6, 6, dtype=F64)
    torch.testing.assert_close(ops.estimate_alpha(y, "RGGB"), torch.ones(3, dtype=F64))
    m = torch.from_numpy(channel_masks("RGGB", 6, 6)).permute(2, 0, 1)[None].to(F64)
    y = 0.2 * m[:, 1:2] + 0.4 * m[:, 2:3]  # G at 0.2, B at 0.4, no red at all
    alpha = ops.estimate_alpha(y, "RGGB")
    assert torch.isfinite(alpha).all()
    torch.testing.assert_close(alpha, 1.0 / torch.tensor([0.3, 0.2, 0.4], dtype=F64))
    # a 1x1 frame has no G or B photosite
    assert torch.isfinite(ops.estimate_alpha(torch.full((1, 1, 1, 1), 0.5), "RGGB")).all()


# ------------------------------------------------------------------------------------------- Q

K_VALUES = [0.0, 1.0, 50.0, 1e3, 1e6]
SPECIAL_X = [-1e3, -0.5, -1e-9, 0.0, 0.05, 0.1, 0.15, 0.3, 0.55, 0.6, 0.999, 1.0, 1.0 + 1e-9, 1.5, 1e3]


@pytest.mark.parametrize("dtype", [torch.float32, F64])
@pytest.mark.parametrize("k", K_VALUES)
def test_soft_quantise_finite_values_and_gradients(k, dtype):
    x = torch.cat([torch.tensor(SPECIAL_X, dtype=dtype), torch.rand(200, generator=_gen(7), dtype=dtype) * 1.4 - 0.2])
    x.requires_grad_(True)
    q = ops.soft_quantise(x, 10, k)
    (g,) = torch.autograd.grad(q.sum(), x)
    assert torch.isfinite(q).all() and torch.isfinite(g).all()
    assert (q >= 0).all() and (q <= 1).all()
    assert (g >= 0).all()  # monotone within a cell
    if k == 0:  # the midpoint of the cell, constant within it
        cell = torch.floor(x.detach() * 10).clamp(0, 9)
        torch.testing.assert_close(q.detach(), (cell + 0.5) / 10)
        assert (g == 0).all()


def test_soft_quantise_approaches_hard_rounding():
    x = torch.rand(2000, generator=_gen(8), dtype=F64) * 1.2 - 0.1
    frac = (x * 10) - torch.floor(x * 10)
    x = x[(frac - 0.5).abs() > 0.02]  # away from the midpoints, where rounding flips
    hard = ops.hard_quantise(x, 10)
    errors = [float((ops.soft_quantise(x, 10, k) - hard).abs().max()) for k in K_VALUES]
    assert all(a > b for a, b in itertools.pairwise(errors))  # strictly better as k grows
    assert errors[0] == pytest.approx(0.05, abs=1e-12)  # k = 0: half a step off everywhere
    assert errors[-1] < 1e-12
    # levels are fixed points for large k, whatever cell rounding puts them in
    lv = torch.arange(11, dtype=F64) / 10
    torch.testing.assert_close(ops.soft_quantise(lv, 10, 1e6), lv)


def test_soft_quantise_k50_jump_at_cell_boundary_is_documented_size():
    k, n = 50.0, 10
    b = torch.tensor([0.3 - 1e-12, 0.3 + 1e-12], dtype=F64)
    q = ops.soft_quantise(b, n, k)
    jump = float(q[1] - q[0])  # q is non-decreasing: the jump is upwards
    assert jump == pytest.approx((1 / n) * (1 - np.tanh(k / (2 * n))), rel=1e-6)


# ------------------------------------------------------------------------------------------- P


@pytest.mark.parametrize("size", [(8, 8), (7, 9), (13, 5), (1, 1), (2, 3)], ids=lambda s: f"{s[0]}x{s[1]}")
def test_pyramid_shapes_synthesis_and_constants(size):
    top = ops.max_pyramid_bands(*size)
    x = _rand((2, 3) + size, 9)
    bands = ops.laplacian_pyramid(x, top)
    h, w = size
    for b in bands:
        assert b.shape[-2:] == (h, w)
        h, w = (h + 1) // 2, (w + 1) // 2
    assert min(bands[-1].shape[-2:]) == 1  # the maximum depth ends at one pixel on the shorter side
    torch.testing.assert_close(ops.laplacian_synthesis(bands), x, rtol=0, atol=1e-12)
    const = ops.laplacian_pyramid(torch.full((1, 1) + size, 0.37, dtype=F64), top)
    for b in const[:-1]:
        assert b.abs().max() < 1e-12
    torch.testing.assert_close(const[-1], torch.full_like(const[-1], 0.37))


def test_pyramid_levels_validated_with_the_maximum():
    assert ops.max_pyramid_bands(8, 8) == 4  # 8 → 4 → 2 → 1
    assert ops.max_pyramid_bands(7, 100) == 4  # 7 → 4 → 2 → 1
    assert ops.max_pyramid_bands(1, 9) == 1
    with pytest.raises(ParameterError, match="at most 4"):
        ops.laplacian_pyramid(torch.zeros(1, 3, 8, 9), 5)
    with pytest.raises(ParameterError, match="integer >= 1"):
        ops.laplacian_pyramid(torch.zeros(1, 3, 8, 8), 0)
    with pytest.raises(ParameterError, match="at most 3"):
        ops.multiscale_loss(torch.zeros(1, 1, 4, 4), torch.zeros(1, 1, 4, 4), 4)


def test_multiscale_loss_values():
    a = _rand((2, 3, 8, 8), 10)
    b = _rand((2, 3, 8, 8), 11)
    # one level: the plain (squared) Euclidean norm per sample
    per = torch.linalg.vector_norm((a - b).flatten(1), dim=1)
    torch.testing.assert_close(ops.multiscale_loss(a, b, 1, reduction="none"), per)
    torch.testing.assert_close(ops.multiscale_loss(a, b, 1, norm="l2sq"), (per**2).sum())
    torch.testing.assert_close(ops.multiscale_loss(a, b, 1, reduction="mean"), per.mean())
    # more levels weigh each band; a constant offset lives only in the coarsest band
    off = ops.multiscale_loss(a + 0.1, a, 3, (0.0, 0.0, 2.0), reduction="none")
    torch.testing.assert_close(off, torch.full((2,), 2 * 0.1 * (3 * 2 * 2) ** 0.5, dtype=F64))
    assert float(ops.multiscale_loss(a + 0.1, a, 3, (1.0, 1.0, 0.0))) < 1e-12
    # zero residual: value 0 and a finite (zero) gradient for the non-squared norm
    x = a.clone().requires_grad_(True)
    (g,) = torch.autograd.grad(ops.multiscale_loss(x, a, 3), x)
    assert torch.isfinite(g).all() and (g == 0).all()


# --------------------------------------------------------------------------------------- noise


def test_tfp_variance_model_and_floor():
    y = torch.arange(11, dtype=F64) / 10
    torch.testing.assert_close(ops.tfp_variance(y, 10, prior=0.0), y * (1 - y) / 10)
    v = ops.tfp_variance(y, 10)
    assert (v > 0).all()
    floor = 0.5 * 10.5 / (11.0**2 * 10)  # a (Δτ + a) / ((Δτ + 2a)² Δτ), see the docstring
    assert float(v[0]) == pytest.approx(floor) and float(v[-1]) == pytest.approx(floor)


def _binomial_tfp(p: torch.Tensor, window: int, seed: int) -> torch.Tensor:
    ticks = torch.rand((window,) + p.shape, generator=_gen(seed), dtype=F64)
    return (ticks < p).sum(0).to(F64) / window


def test_binomial_vst_stabilises_variance_and_inverts():
    window = 10
    for p in (0.3, 0.5, 0.7):
        y = _binomial_tfp(torch.full((20000,), p, dtype=F64), window, seed=int(p * 10))
        var = float(ops.binomial_vst(y, window).var())
        # Anscombe's transform: ≈ 1; 20000 samples give a standard error of about 1 %
        assert var == pytest.approx(1.0, abs=0.08)
        assert float(y.var()) == pytest.approx(p * (1 - p) / window, rel=0.05)
    y = torch.arange(11, dtype=F64) / 10
    torch.testing.assert_close(ops.binomial_vst_inverse(ops.binomial_vst(y, window), window), y)


@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_effective_sigma_matches_simulated_noise(cfa):
    """σ from the data ≈ the measured RMS noise of the corrected estimate Y₀ (binomial counts)."""
    window, eta = 10, 2.0
    h, w = 24, 24
    yy, xx = torch.meshgrid(torch.linspace(0, 1, h, dtype=F64), torch.linspace(0, 1, w, dtype=F64), indexing="ij")
    scene = torch.stack([0.3 + 0.4 * xx, 0.5 + 0.2 * yy, 0.6 - 0.3 * xx * yy])[None]  # smooth, in [0.3, 0.7]
    gain = torch.tensor([0.7, 1.0, 0.5], dtype=F64)[None, :, None, None]
    p = ops.mosaic(scene * gain, cfa)  # (1, 1, H, W) firing probabilities, colour cast included
    frames = 64
    y = torch.cat([_binomial_tfp(p, window, seed=100 + t) for t in range(frames)])
    alpha = ops.estimate_alpha(y, cfa)
    y0 = ops.colour_cast_inverse(ops.demosaic_bilinear(y, cfa), alpha, eta)
    clean = ops.colour_cast_inverse(ops.demosaic_bilinear(p, cfa), alpha, eta)
    measured = ((y0 - clean) ** 2).mean(dim=(0, 2, 3)).sqrt()
    sigma = ops.effective_sigma(y, cfa, window, alpha, eta)
    assert sigma.shape == (frames, 3)
    predicted = (sigma**2).mean(0).sqrt()
    # the Jeffreys-smoothed plug-in is within a few per cent here; 7 % leaves room for the border
    torch.testing.assert_close(predicted, measured, rtol=0.07, atol=0.0)
    # the per-pixel map has the same mean variance
    pix = ops.effective_sigma(y, cfa, window, alpha, eta, per_pixel=True)
    torch.testing.assert_close((pix**2).mean(dim=(2, 3)).sqrt(), sigma)


def test_effective_sigma_mono_and_dark_frames():
    y = torch.zeros(2, 1, 8, 8)
    s = ops.effective_sigma(y, None, 10)
    assert s.shape == (2, 1)
    torch.testing.assert_close(s, ops.tfp_variance(torch.zeros(2, 1), 10).sqrt())
    s = ops.effective_sigma(torch.ones(1, 1, 8, 8), "RGGB", 10)  # saturated: finite, floored
    assert torch.isfinite(s).all() and (s > 0).all()


# ----------------------------------------------------------------------------------- ForwardModel


def test_forward_model_composes_q_c_m():
    x = _rand((2, 3, 8, 9), 12)
    alpha = torch.tensor([2.0, 1.0, 3.0], dtype=F64)
    fm = ops.ForwardModel("GRBG", 10, alpha=alpha, eta=1.5, k=50.0).double()
    want = ops.soft_quantise(ops.mosaic(ops.colour_cast(x, alpha, 1.5), "GRBG"), 10, 50.0)
    torch.testing.assert_close(fm(x), want)
    assert ops.ForwardModel("GRBG", cast=False, k=None)(x).equal(ops.mosaic(x, "GRBG"))
    mono = ops.ForwardModel(None, 4, k=1e6)
    torch.testing.assert_close(mono(x[:, :1]), ops.hard_quantise(x[:, :1], 4))
    assert mono.channels == 1 and fm.channels == 3


def test_forward_model_loss_is_zero_at_the_truth_and_guides_towards_it():
    x = _rand((1, 3, 16, 16), 13, 0.2, 0.8)
    fm = ops.ForwardModel("RGGB", 10, k=None, bands=3, dense_grad=True)
    y = fm(x).detach()
    assert float(fm.loss(x, y)) == 0.0
    # a gradient step from a perturbed scene reduces the loss (dense gradient included)
    for vst in (False, True):
        fm.vst = vst
        z = (x + 0.1 * torch.randn(x.shape, generator=_gen(14), dtype=F64)).clamp(0.05, 0.95).requires_grad_(True)
        loss = fm.loss(z, y)
        (g,) = torch.autograd.grad(loss, z)
        assert (g != 0).all()  # dense: every channel of every pixel is guided
        assert float(fm.loss(z.detach() - 0.01 * g, y)) < float(loss.detach())


def test_forward_model_from_observation_and_initial_estimate():
    y = _rand((3, 1, 8, 8), 15)
    fm = ops.ForwardModel.from_observation(y, "BGGR", 10, eta=2.0)
    torch.testing.assert_close(fm.alpha, ops.estimate_alpha(y, "BGGR"))
    y0 = fm.initial_estimate(y.float())
    assert y0.shape == (3, 3, 8, 8)
    torch.testing.assert_close(y0, ops.colour_cast_inverse(ops.demosaic_bilinear(y.float(), "BGGR"), fm.alpha, 2.0))
    torch.testing.assert_close(fm.effective_sigma(y.float()), ops.effective_sigma(y.float(), "BGGR", 10, fm.alpha, 2.0))
    assert ops.ForwardModel.from_observation(y, None).alpha is None


def test_cached_constants_survive_inference_mode():
    """Masks and pyramid normalisers first built under inference_mode must still work with autograd."""
    size = (11, 13)  # a size no other test uses, so the caches are cold
    with torch.inference_mode():
        ops.ForwardModel("GBRG", 10, bands=3).loss(torch.rand((1, 3) + size), torch.rand((1, 1) + size))
    x = torch.rand((1, 3) + size, requires_grad=True)
    loss = ops.ForwardModel("GBRG", 10, bands=3).loss(x, torch.rand((1, 1) + size))
    (g,) = torch.autograd.grad(loss, x)
    assert torch.isfinite(g).all()
