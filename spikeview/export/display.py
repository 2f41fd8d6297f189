"""Linear frames to display-encoded integers for PNG and MP4 (fixed levels, no auto-levels).

The mapping is the same for every frame of an export, so brightness can be compared across a
sequence: ``v = clip((x - black) / (white - black), 0, 1)``, then the transfer curve, then
rounding to the nearest integer code.
"""

from __future__ import annotations

import numpy as np

from spikeview.export.settings import ExportConfig
from spikeview.transfer import srgb_encode


def encode_display(frame: np.ndarray, config: ExportConfig) -> np.ndarray:
    """Apply the fixed levels and the transfer curve of ``config``.

    Args:
        frame: float32 ``(H, W)`` or ``(H, W, 3)``, linear light (nominally ``[0, 1]``).
        config: supplies ``black``, ``white``, ``transfer`` and ``gamma``.

    Returns:
        float32 array of the same shape in ``[0, 1]``, display-encoded.
    """
    white = config.white_or()
    x = (frame.astype(np.float32) - np.float32(config.black)) / np.float32(white - config.black)
    x = np.clip(x, 0.0, 1.0)
    if config.curve() == "srgb":
        return srgb_encode(x)
    if config.curve() == "gamma":
        return np.power(x, np.float32(1.0 / config.gamma)).astype(np.float32)
    return x


def quantize(encoded: np.ndarray, bits: int) -> np.ndarray:
    """Round display-encoded values in ``[0, 1]`` to ``uint8`` (``bits=8``) or ``uint16`` (``bits=16``)."""
    if bits == 8:
        return np.rint(encoded * 255.0).astype(np.uint8)
    if bits == 16:
        return np.rint(encoded * 65535.0).astype(np.uint16)
    raise ValueError(f"bits must be 8 or 16, got {bits}")


def to_display(frame: np.ndarray, config: ExportConfig, bits: int = 8) -> np.ndarray:
    """``quantize(encode_display(frame, config), bits)``: what PNG and MP4 store.

    Returns:
        ``uint8`` or ``uint16`` array with the shape of ``frame``.
    """
    return quantize(encode_display(frame, config), bits)
