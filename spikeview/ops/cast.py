"""C, the per-channel colour cast of the sensor, and its gray-world estimate.

Convention (METHOD.md): the camera sees channel ``c`` of the scene scaled by ``η / α_c`` with
``α_c = 1 / mean(Y_c)`` (gray-world over the whole sequence), so

* ``colour_cast(x)_c = x_c · η / α_c = x_c · η · mean(Y_c)`` (scene → sensor, used in A = Q∘C∘M), and
* ``colour_cast_inverse(y)_c = y_c · α_c / η`` (sensor → scene, the colour correction of the TFP
  estimate). A gray-world-corrected estimate has channel means ``1 / η``: ``η`` is the range
  parameter, ``η = 2`` puts the average grey at 0.5.

One α per sequence keeps the colour stable across frames; a per-frame ``(N, 3)`` α is accepted too.
"""

from __future__ import annotations

import torch
from torch import nn

from spikeview.errors import ParameterError
from spikeview.ops._checks import cfa_masks, check_cfa, check_image


def _alpha_gain(alpha: torch.Tensor | tuple[float, float, float], like: torch.Tensor, values: bool = True) -> torch.Tensor:
    """Validate α and return it as ``(1 or N, 3, 1, 1)`` in ``like``'s dtype/device (``values=False``: its shape
    only, for α a :class:`ColourCast` checked when it was made: no device-to-host read per call on a GPU)."""
    a = torch.as_tensor(alpha, dtype=like.dtype, device=like.device)
    if a.shape == (3,):
        a = a.unsqueeze(0)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] not in (1, like.shape[0]):
        raise ParameterError(
            f"alpha must have shape (3,) (one per sequence) or ({like.shape[0]}, 3) (one per frame), got {tuple(a.shape)}."
        )
    if values and (not bool(torch.isfinite(a).all()) or bool((a <= 0).any())):
        raise ParameterError(f"alpha must be finite and positive, got {a.detach().cpu().tolist()}; estimate it with estimate_alpha.")
    return a[:, :, None, None]


def _check_eta(eta: float) -> float:
    eta = float(eta)
    if not (eta > 0 and eta < float("inf")):
        raise ParameterError(f"eta must be a positive finite number, got {eta}; the default is 1.0.")
    return eta


def colour_cast(x: torch.Tensor, alpha: torch.Tensor | tuple[float, float, float], eta: float = 1.0) -> torch.Tensor:
    """C: scale channel ``c`` by ``η / α_c`` (linear, self-adjoint).

    Args:
        x: ``(N, 3, H, W)`` float RGB scene in [0, 1].
        alpha: ``(3,)`` gray-world factors ``α_c = 1 / mean(Y_c)`` of the sequence (or ``(N, 3)`` per
            frame), positive; see :func:`estimate_alpha`.
        eta: range parameter ``η > 0``.

    Returns:
        ``(N, 3, H, W)`` sensor-side image ``x_c · η / α_c`` (may exceed 1; Q saturates it).
    """
    check_image(x, 3)
    return x * (_check_eta(eta) / _alpha_gain(alpha, x))


def colour_cast_inverse(y: torch.Tensor, alpha: torch.Tensor | tuple[float, float, float], eta: float = 1.0) -> torch.Tensor:
    """C⁻¹, the colour correction: scale channel ``c`` by ``α_c / η``.

    Args:
        y: ``(N, 3, H, W)`` demosaicked sensor-side RGB (e.g. bilinear TFP).
        alpha: as in :func:`colour_cast`.
        eta: as in :func:`colour_cast`.

    Returns:
        ``(N, 3, H, W)`` corrected image (channel means ``1/η`` when α was estimated from ``y``);
        not clipped.
    """
    check_image(y, 3, "y")
    return y * (_alpha_gain(alpha, y) / _check_eta(eta))


def estimate_alpha(y_mosaic: torch.Tensor, cfa: str, min_mean: float = 1e-6) -> torch.Tensor:
    """Gray-world ``α_c = 1 / mean(Y_c)`` over all frames of a mosaicked sequence.

    Channel means are taken over every photosite of that colour in every frame (one α for the
    whole sequence). A channel whose mean is ``<= min_mean`` (dark scene, a colour absent from the
    scene, or from a frame too small to hold it) carries no gray-world information; it gets the mean
    of the informative channels' means (assume a neutral response, so the guidance trusts the data
    that this colour is dark). If no channel is informative, ``α = (1, 1, 1)``. Never divides by zero.

    Args:
        y_mosaic: ``(N, 1, H, W)`` mosaicked SFR (TFP) in [0, 1], frames of one sequence.
        cfa: Bayer pattern of the mosaic's top-left 2×2.
        min_mean: smallest channel mean treated as signal (SFR units).

    Returns:
        ``(3,)`` α in ``y_mosaic``'s dtype/device, finite and positive, detached.
    """
    name = check_cfa(cfa)
    check_image(y_mosaic, 1, "y_mosaic")
    with torch.no_grad():
        m = cfa_masks(name, y_mosaic.shape[-2], y_mosaic.shape[-1], y_mosaic)
        sums = (y_mosaic * m).sum(dim=(0, 2, 3))
        counts = m.sum(dim=(0, 2, 3)) * y_mosaic.shape[0]
        means = torch.where(counts > 0, sums / counts.clamp_min(1), torch.zeros_like(sums))
        valid = means > min_mean
        if bool(valid.any()):
            means = torch.where(valid, means, means[valid].mean())
        else:
            means = torch.ones_like(means)
        return 1.0 / means


class ColourCast(nn.Module):
    """Module form of C: stores α (a buffer) and η.

    Args:
        alpha: ``(3,)`` or ``(N, 3)`` positive gray-world factors (see :func:`estimate_alpha`).
        eta: range parameter ``η > 0``.

    Shape:
        ``(N, 3, H, W)`` → ``(N, 3, H, W)``.
    """

    alpha: torch.Tensor

    def __init__(self, alpha: torch.Tensor | tuple[float, float, float], eta: float = 1.0):
        super().__init__()
        a = torch.as_tensor(alpha).detach().clone()
        if not a.is_floating_point():
            a = a.to(torch.get_default_dtype())
        _alpha_gain(a, torch.zeros(a.shape[0] if a.ndim == 2 else 1, 3, 1, 1, dtype=a.dtype))
        self.register_buffer("alpha", a)
        self.eta = _check_eta(eta)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        check_image(x, 3)  # α and η were checked when the module was made
        return x * (self.eta / _alpha_gain(self.alpha, x, values=False))

    def adjoint(self, y: torch.Tensor) -> torch.Tensor:
        """Cᵀ = C (a diagonal scaling)."""
        return self.forward(y)

    def inverse(self, y: torch.Tensor) -> torch.Tensor:
        """C⁻¹ (colour correction)."""
        return colour_cast_inverse(y, self.alpha, self.eta)

    def extra_repr(self) -> str:
        return f"alpha={self.alpha.tolist()}, eta={self.eta}"
