"""Shared pieces of the demosaicking kernels: input checks and CFA codes."""

from __future__ import annotations

import numpy as np

from spikeview.cfa import CHANNEL_INDEX, parse_cfa
from spikeview.errors import ParameterError


def quad_codes(cfa: str | None) -> np.ndarray:
    """``(2, 2)`` int64 channel index (0 R, 1 G, 2 B) of the CFA's top-left quad."""
    name = parse_cfa(cfa)
    if name is None:
        raise ParameterError("Demosaicking needs a Bayer CFA (RGGB, BGGR, GRBG or GBRG), got monochrome; skip demosaicking for mono streams.")
    return np.array([[CHANNEL_INDEX[name[0]], CHANNEL_INDEX[name[1]]], [CHANNEL_INDEX[name[2]], CHANNEL_INDEX[name[3]]]], dtype=np.int64)


def check_cfa_image(image: np.ndarray, min_size: int, method: str, dtype: type = np.float32) -> np.ndarray:
    """Validate a mosaicked ``(H, W)`` image and return it C-contiguous in ``dtype``."""
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise ParameterError(f"cfa_image must be a mosaicked (H, W) array, got shape {arr.shape}; pass one frame.")
    if min(arr.shape) < min_size:
        raise ParameterError(f"cfa_image of shape {arr.shape} is too small for {method!r} demosaicking; it needs at least {min_size}x{min_size} pixels.")
    return np.ascontiguousarray(arr, dtype=dtype)
