"""Q, the soft quantisation of SFR values to the TFP grid ``{0, 1/Δτ, …, 1}``.

For ``x`` in the cell ``[l, u)`` between neighbouring levels (``u = l + 1/Δτ``)::

    φ(x) = (tanh(k · (x − (l + u)/2)) + 1) / 2,     q(x) = l · (1 − φ) + u · φ

(SpikeDiff; the paper found ``k = 50`` best at Δτ = 10). Properties of this implementation:

* ``k → ∞`` gives hard rounding to the nearest level; ``k = 0`` gives ``φ = ½``, the **cell
  midpoint** ``(l + u)/2``, a staircase with zero gradient (so ``k = 0`` does not mean identity).
* Within a cell ``q`` is smooth with ``dq/dx = (u − l) · k · (1 − tanh²) / 2``; ``tanh`` saturates,
  so every ``k ≥ 0`` (1e6 included) gives finite values and finite gradients.
* At a cell boundary ``q`` jumps up (it stays non-decreasing) by ``(u − l)(1 − tanh(k (u − l)/2))`` (0.013/Δτ at k = 50, Δτ = 10;
  ``u − l`` at k = 0). An input exactly on a level belongs to the cell above it (the top level 1 to
  the last cell); for large k it maps to itself either way.
* Outside [0, 1] the first and last cells extend to ±∞: ``q`` stays in [0, 1] and tends to 0 below
  and 1 above (the sensor saturates at one spike per tick), smoothly for finite k.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from spikeview.errors import ParameterError
from spikeview.ops._checks import check_positive_int


def _check_k(k: float) -> float:
    k = float(k)
    if not (k >= 0 and math.isfinite(k)):
        raise ParameterError(f"k (quantisation sharpness) must be a finite number >= 0, got {k}; the paper's value is 50.")
    return k


def soft_quantise(x: torch.Tensor, window: int, k: float) -> torch.Tensor:
    """Q: soft rounding to multiples of ``1/window`` in [0, 1] (see the module docstring).

    Args:
        x: float tensor of any shape (an SFR image, values nominally in [0, 1]; any real value works).
        window: Δτ, the TFP window in ticks; the levels are ``0, 1/Δτ, …, 1`` (Δτ = 10 gives 11 levels).
        k: sharpness ``k >= 0`` in units of 1/SFR (``k = 50`` in the paper; ``k = 0`` is the
            cell midpoint, large k approaches hard rounding).

    Returns:
        Tensor shaped like ``x``, values in [0, 1], differentiable in ``x``.
    """
    n = check_positive_int(window, "window")
    k = _check_k(k)
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        raise ParameterError(
            f"x must be a floating-point torch.Tensor, got {type(x).__name__}; convert it with torch.as_tensor(..., dtype=torch.float32)."
        )
    step = 1.0 / n
    with torch.no_grad():
        cell = torch.floor(x * n).clamp_(0, n - 1)
    lower = cell * step
    mid = lower + 0.5 * step
    phi = 0.5 * (torch.tanh(k * (x - mid)) + 1.0)
    return lower + step * phi


def hard_quantise(x: torch.Tensor, window: int = 10) -> torch.Tensor:
    """Round to the nearest multiple of ``1/window`` and clip to [0, 1] (the ``k → ∞`` limit, ties up).

    Args:
        x: float tensor of any shape.
        window: Δτ in ticks.

    Returns:
        Tensor shaped like ``x`` with values in ``{0, 1/Δτ, …, 1}`` (no gradient).
    """
    n = check_positive_int(window, "window")
    return (torch.floor(x * n + 0.5) / n).clamp(0.0, 1.0)


class SoftQuantise(nn.Module):
    """Module form of Q.

    Args:
        window: Δτ in ticks (levels ``0, 1/Δτ, …, 1``).
        k: sharpness ``k >= 0``.

    Shape:
        any → same.
    """

    def __init__(self, window: int, k: float):
        super().__init__()
        self.window = check_positive_int(window, "window")
        self.k = _check_k(k)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return soft_quantise(x, self.window, self.k)

    def extra_repr(self) -> str:
        return f"window={self.window}, k={self.k}"
