"""Input checks shared by the differentiable operators (errors say expected vs. actual)."""

from __future__ import annotations

import functools

import numpy as np
import torch

from spikeview.cfa import channel_masks, parse_cfa
from spikeview.errors import ParameterError


def check_image(x: torch.Tensor, channels: int | None, name: str = "x", min_size: int = 1) -> None:
    """Raise unless ``x`` is a floating ``(N, channels, H, W)`` tensor with ``H, W >= min_size``.

    ``channels=None`` accepts any channel count.
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}; convert it with torch.as_tensor.")
    want = f"(N, {channels}, H, W)" if channels is not None else "(N, C, H, W)"
    if x.ndim != 4 or (channels is not None and x.shape[1] != channels):
        raise ParameterError(f"{name} must have shape {want}, got {tuple(x.shape)}; add the missing batch/channel axes.")
    if not x.is_floating_point():
        raise ParameterError(f"{name} must be a floating-point tensor, got {x.dtype}; call .float() first.")
    if min(x.shape[-2:]) < min_size:
        raise ParameterError(
            f"{name} of spatial size {tuple(x.shape[-2:])} is too small; this operator needs at least {min_size}x{min_size} pixels."
        )


def check_cfa(cfa: str | None, allow_mono: bool = False) -> str | None:
    """Normalise a CFA name; monochrome is rejected unless ``allow_mono``."""
    name = parse_cfa(cfa)
    if name is None and not allow_mono:
        raise ParameterError("cfa must be a Bayer pattern (RGGB, BGGR, GRBG or GBRG) for this operator, got monochrome ('none').")
    return name


@functools.lru_cache(maxsize=64)
def _masks_np(cfa: str, height: int, width: int) -> np.ndarray:
    return np.ascontiguousarray(channel_masks(cfa, height, width).transpose(2, 0, 1))


@functools.lru_cache(maxsize=32)
def _masks_tensor(cfa: str, height: int, width: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    # cached so that a sampler on a GPU does not copy the masks to the device at every step; a normal
    # tensor even when first asked for under inference_mode, so autograd can save it later
    with torch.inference_mode(False):
        return torch.from_numpy(_masks_np(cfa, height, width)).to(device=device, dtype=dtype).unsqueeze(0)


def cfa_masks(cfa: str, height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """``(1, 3, H, W)`` 0/1 masks of the CFA channels (0 R, 1 G, 2 B) in ``like``'s dtype and device (read-only)."""
    return _masks_tensor(cfa, int(height), int(width), like.device, like.dtype)


def check_positive_int(value: int, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ParameterError(f"{name} must be an integer >= {minimum}, got {value!r}; pass e.g. {name}={max(minimum, 10)}.")
    return int(value)
