"""Laplacian pyramid P (linear, with adjoint and exact synthesis) and the multiscale loss.

Construction (Burt & Adelson 1983, with normalised convolution at the borders):

* ``B``: separable 5-tap binomial blur ``[1, 4, 6, 4, 1] / 16`` per channel, zero padding.
* ``D`` (reduce): ``D(x) = S(B(x) / B(1))``, ``S`` keeps even rows and columns, so an ``H × W``
  level becomes ``ceil(H/2) × ceil(W/2)`` (odd sizes keep their last row/column's sample). Dividing
  by ``B(1)`` renormalises the kernel where it leaves the frame, so constants are preserved.
* ``U`` (expand to a given size): ``U(c) = B(Z c) / B(Z 1)``, ``Z`` puts the coarse samples back on
  the even positions (zeros elsewhere); normalised the same way, so ``U(D(const)) = const``.
* Levels: ``X_0 = x``, ``X_{l+1} = D(X_l)``; bands ``P_l = X_l − U(X_{l+1})`` for ``l < L − 1`` and the
  coarsest residual ``P_{L−1} = X_{L−1}``. ``laplacian_synthesis`` inverts it exactly.

All of ``B``, ``D``, ``U`` and the pyramid are linear; :func:`laplacian_pyramid_adjoint` is the exact
adjoint of :func:`laplacian_pyramid` (``⟨P x, b⟩ = ⟨x, Pᵀ b⟩``).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from spikeview.errors import ParameterError
from spikeview.ops._checks import check_image

_BINOMIAL5 = (1.0, 4.0, 6.0, 4.0, 1.0)


def max_pyramid_bands(height: int, width: int) -> int:
    """Largest valid number of pyramid bands for an ``H × W`` frame: ``1 + ceil(log2(min(H, W)))``.

    Each level halves the size (rounding up) until the shorter side is one pixel.
    """
    s, n = min(int(height), int(width)), 1
    while s > 1:
        s = (s + 1) // 2
        n += 1
    return n


def max_levels(height: int, width: int) -> int:
    """Largest number of band-pass pyramid levels an ``H × W`` frame allows (the bands minus 1)."""
    return max_pyramid_bands(height, width) - 1


def _check_bands_count(bands: int, height: int, width: int) -> int:
    if isinstance(bands, bool) or not isinstance(bands, int) or bands < 1:
        raise ParameterError(f"bands must be an integer >= 1, got {bands!r}; use 1 for a single-scale loss.")
    top = max_pyramid_bands(height, width)
    if bands > top:
        raise ParameterError(
            f"bands={bands} is too many for a {height}x{width} frame: use at most {top} (each level halves the size down to 1 pixel)."
        )
    return bands


def _blur(x: torch.Tensor) -> torch.Tensor:
    c = x.shape[1]
    k = torch.tensor(_BINOMIAL5, dtype=x.dtype, device=x.device) / 16.0
    kh = k.view(1, 1, 1, 5).expand(c, 1, 1, 5)
    kv = k.view(1, 1, 5, 1).expand(c, 1, 5, 1)
    return F.conv2d(F.conv2d(x, kh, padding=(0, 2), groups=c), kv, padding=(2, 0), groups=c)


@functools.lru_cache(maxsize=64)
def _norm_maps(h: int, w: int, device: torch.device, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """``(B(1), B(Z 1))`` at size ``(h, w)``: the normalisers of D and U (cached: they depend on the size only)."""
    # normal tensors even when first asked for under inference_mode, so autograd can save them later
    with torch.inference_mode(False), torch.no_grad():
        ones = torch.ones(1, 1, h, w, dtype=dtype, device=device)
        coarse = _coarse_size((h, w))
        return _blur(ones), _blur(_zero_insert(ones[..., : coarse[0], : coarse[1]], (h, w)))


def _norm_down(h: int, w: int, like: torch.Tensor) -> torch.Tensor:
    return _norm_maps(int(h), int(w), like.device, like.dtype)[0]


def _norm_up(h: int, w: int, like: torch.Tensor) -> torch.Tensor:
    return _norm_maps(int(h), int(w), like.device, like.dtype)[1]


def _zero_insert(c: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    z = c.new_zeros(c.shape[0], c.shape[1], size[0], size[1])
    z[..., ::2, ::2] = c
    return z


def _coarse_size(size: tuple[int, int]) -> tuple[int, int]:
    return ((size[0] + 1) // 2, (size[1] + 1) // 2)


def _check_coarse(c: torch.Tensor, size: tuple[int, int]) -> None:
    check_image(c, None, "c")
    want = _coarse_size((int(size[0]), int(size[1])))
    if tuple(c.shape[-2:]) != want:
        raise ParameterError(f"c must have spatial size {want} (ceil-half of {tuple(size)}), got {tuple(c.shape[-2:])}.")


def pyr_down(x: torch.Tensor) -> torch.Tensor:
    """D: blur (normalised at the borders) and keep even rows/columns.

    Args:
        x: ``(N, C, H, W)`` float.

    Returns:
        ``(N, C, ceil(H/2), ceil(W/2))``.
    """
    check_image(x, None)
    h, w = x.shape[-2:]
    return (_blur(x) / _norm_down(h, w, x))[..., ::2, ::2]


def pyr_down_adjoint(c: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Dᵀ: the adjoint of :func:`pyr_down` from ``(N, C, ceil(H/2), ceil(W/2))`` back to ``size = (H, W)``."""
    _check_coarse(c, size)
    return _blur(_zero_insert(c, size) / _norm_down(size[0], size[1], c))


def pyr_up(c: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """U: expand ``(N, C, ceil(H/2), ceil(W/2))`` to ``size = (H, W)`` (normalised interpolation).

    Coarse sample ``(i, j)`` sits at fine position ``(2i, 2j)``, matching :func:`pyr_down`.
    """
    _check_coarse(c, size)
    return _blur(_zero_insert(c, size)) / _norm_up(size[0], size[1], c)


def pyr_up_adjoint(r: torch.Tensor) -> torch.Tensor:
    """Uᵀ: the adjoint of :func:`pyr_up`, from ``(N, C, H, W)`` to ``(N, C, ceil(H/2), ceil(W/2))``."""
    check_image(r, None, "r")
    return _blur(r / _norm_up(r.shape[-2], r.shape[-1], r))[..., ::2, ::2]


def laplacian_pyramid(x: torch.Tensor, bands: int) -> list[torch.Tensor]:
    """P: the Laplacian pyramid with ``bands`` bands (see the module docstring).

    Args:
        x: ``(N, C, H, W)`` float, any ``H, W >= 1`` (odd sizes fine).
        bands: ``L >= 1``, at most :func:`max_pyramid_bands` ``(H, W)``; ``L = 1`` returns ``[x]``.

    Returns:
        ``L`` tensors: band ``l`` has shape ``(N, C, H_l, W_l)`` with ``H_0 = H`` and
        ``H_{l+1} = ceil(H_l / 2)``; the last is the coarsest low-pass residual.

    Raises:
        ParameterError: ``bands`` out of range (the message gives the maximum).
    """
    check_image(x, None)
    _check_bands_count(bands, x.shape[-2], x.shape[-1])
    out: list[torch.Tensor] = []
    cur = x
    for _ in range(bands - 1):
        low = pyr_down(cur)
        out.append(cur - pyr_up(low, (cur.shape[-2], cur.shape[-1])))
        cur = low
    out.append(cur)
    return out


def _band_sizes(size: tuple[int, int], bands: int) -> list[tuple[int, int]]:
    sizes = [size]
    for _ in range(bands - 1):
        sizes.append(_coarse_size(sizes[-1]))
    return sizes


def _check_bands(bands: Sequence[torch.Tensor]) -> list[tuple[int, int]]:
    if len(bands) < 1:
        raise ParameterError("bands must hold at least one tensor (the output of laplacian_pyramid).")
    for b in bands:
        check_image(b, None, "bands[i]")
    sizes = _band_sizes((bands[0].shape[-2], bands[0].shape[-1]), len(bands))
    got = [tuple(b.shape[-2:]) for b in bands]
    if got != sizes:
        raise ParameterError(f"bands have spatial sizes {got}, expected {sizes} (each level ceil-halves the previous one).")
    return sizes


def laplacian_pyramid_adjoint(bands: Sequence[torch.Tensor]) -> torch.Tensor:
    """Pᵀ: the adjoint of :func:`laplacian_pyramid` (not its inverse).

    Args:
        bands: ``L`` tensors shaped like ``laplacian_pyramid``'s output.

    Returns:
        ``(N, C, H, W)`` with ``⟨P x, bands⟩ = ⟨x, Pᵀ bands⟩``.
    """
    sizes = _check_bands(bands)
    g = bands[-1]
    for lvl in range(len(bands) - 2, -1, -1):
        g = bands[lvl] + pyr_down_adjoint(g - pyr_up_adjoint(bands[lvl]), sizes[lvl])
    return g


def laplacian_synthesis(bands: Sequence[torch.Tensor]) -> torch.Tensor:
    """P⁻¹: rebuild the image from its bands (``X_l = P_l + U(X_{l+1})``); exact up to rounding."""
    sizes = _check_bands(bands)
    x = bands[-1]
    for lvl in range(len(bands) - 2, -1, -1):
        x = bands[lvl] + pyr_up(x, sizes[lvl])
    return x


def multiscale_loss(
    a: torch.Tensor,
    b: torch.Tensor,
    bands: int = 3,
    weights: Sequence[float] | None = None,
    norm: str = "l2",
    reduction: str = "sum",
) -> torch.Tensor:
    """Distance between ``a`` and ``b`` summed over the bands of their Laplacian pyramids.

    ``loss_n = Σ_l w_l · ‖P_l(a_n) − P_l(b_n)‖`` per sample ``n`` (the pyramid is linear, so it is
    computed once on ``a − b``).

    Args:
        a: ``(N, C, H, W)`` float (e.g. ``A(X̂₀)``).
        b: same shape (e.g. the observation ``Y``).
        bands: number of bands ``L`` (1 = plain single-scale loss); at most ``max_pyramid_bands(H, W)``.
        weights: ``L`` non-negative weights ``w_l`` (finest first); default all 1.
        norm: ``"l2"``, the Euclidean norm (non-squared, as in the DPS reference code; its gradient
            is 0 at zero residual), or ``"l2sq"``, its square.
        reduction: ``"sum"`` over the batch (independent per-sample gradients), ``"mean"``, or
            ``"none"`` for the ``(N,)`` per-sample losses.

    Returns:
        Scalar tensor (or ``(N,)`` for ``reduction="none"``), differentiable in ``a`` and ``b``.
    """
    check_image(a, None, "a")
    if not isinstance(b, torch.Tensor) or b.shape != a.shape:
        got = tuple(b.shape) if isinstance(b, torch.Tensor) else type(b).__name__
        raise ParameterError(f"b must have the shape of a, {tuple(a.shape)}, got {got}.")
    _check_bands_count(bands, a.shape[-2], a.shape[-1])
    if weights is None:
        w = [1.0] * bands
    else:
        w = [float(v) for v in weights]
        if len(w) != bands or any(not (v >= 0) for v in w):
            raise ParameterError(f"weights must be {bands} non-negative numbers (one per pyramid level), got {list(weights)}.")
    if norm not in ("l2", "l2sq"):
        raise ParameterError(f"norm must be 'l2' or 'l2sq', got {norm!r}.")
    if reduction not in ("sum", "mean", "none"):
        raise ParameterError(f"reduction must be 'sum', 'mean' or 'none', got {reduction!r}.")
    total = a.new_zeros(a.shape[0])
    for wl, band in zip(w, laplacian_pyramid(a - b, bands), strict=True):
        flat = band.flatten(1)
        per = torch.linalg.vector_norm(flat, dim=1) if norm == "l2" else (flat * flat).sum(dim=1)
        total = total + wl * per
    if reduction == "sum":
        return total.sum()
    if reduction == "mean":
        return total.mean()
    return total


class LaplacianPyramid(nn.Module):
    """Module form of P with ``bands`` bands; ``adjoint`` and ``inverse`` included.

    Shape:
        ``(N, C, H, W)`` → list of ``bands`` tensors ``(N, C, H_l, W_l)``.
    """

    def __init__(self, bands: int = 3):
        super().__init__()
        if isinstance(bands, bool) or not isinstance(bands, int) or bands < 1:
            raise ParameterError(f"bands must be an integer >= 1, got {bands!r}.")
        self.bands = bands

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        return laplacian_pyramid(x, self.bands)

    def adjoint(self, bands: Sequence[torch.Tensor]) -> torch.Tensor:
        return laplacian_pyramid_adjoint(bands)

    def inverse(self, bands: Sequence[torch.Tensor]) -> torch.Tensor:
        return laplacian_synthesis(bands)

    def extra_repr(self) -> str:
        return f"bands={self.bands}"
