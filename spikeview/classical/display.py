"""Float images to 8-bit display images with fixed levels.

Display mapping: ``v = (x - black) / (white - black)``, clipped to ``[0, 1]`` (NaN shows as black),
then a transfer curve — ``"srgb"`` (the piecewise sRGB encoding, IEC 61966-2-1), a power
``v ** gamma`` (``gamma=1/2.2`` is the classic display gamma, ``1.0`` is linear) — and rounding to
``0..255``. Levels are fixed by the caller and **never** adapted per frame, so brightness is
comparable from frame to frame (auto-levels would make noise flicker and hide exposure).

:func:`to_display` looks the curve up in a 65,536-entry table (a few ms at 1000×1000×3); its result
is within one code value of the exact mapping :func:`transfer` (exact at black, white, and
everywhere for the linear curve up to rounding ties).
"""

from __future__ import annotations

import functools

import numba
import numpy as np

from spikeview.errors import ParameterError
from spikeview.transfer import levels_ordered, srgb_encode

_LUT_SIZE = 65_536

Gamma = float | str


def _check_gamma(gamma: Gamma) -> Gamma:
    if isinstance(gamma, str):
        if gamma.strip().lower() != "srgb":
            raise ParameterError(f"gamma must be 'srgb' or a positive number (e.g. 1/2.2, 1.0 for linear), got {gamma!r}.")
        return "srgb"
    g = float(gamma)
    if not (np.isfinite(g) and g > 0):
        raise ParameterError(f"gamma must be 'srgb' or a positive number (e.g. 1/2.2, 1.0 for linear), got {gamma!r}.")
    return g


def _check_levels(black: float, white: float) -> tuple[float, float]:
    black, white = float(black), float(white)
    if not levels_ordered(black, white):
        raise ParameterError(f"Display levels need black < white, got black={black}, white={white}; e.g. black=0, white=1.")
    return black, white


def _curve(v: np.ndarray, gamma: Gamma) -> np.ndarray:
    """Transfer curve on ``v`` in [0, 1] (float64)."""
    if gamma == "srgb":
        return srgb_encode(v)
    return np.power(v, float(gamma))


def transfer(img: np.ndarray, black: float = 0.0, white: float = 1.0, gamma: Gamma = "srgb") -> np.ndarray:
    """The exact display mapping of the module docstring, as float64 in ``[0, 1]`` (no table)."""
    black, white = _check_levels(black, white)
    gamma = _check_gamma(gamma)
    v = (np.asarray(img, dtype=np.float64) - black) / (white - black)
    v = np.clip(np.nan_to_num(v, nan=0.0), 0.0, 1.0)
    return _curve(v, gamma)


def encode8(values: np.ndarray) -> np.ndarray:
    """``[0, 1]`` floats to uint8 codes, rounding half up (``floor(255·v + 0.5)``)."""
    return np.floor(np.asarray(values, dtype=np.float64) * 255.0 + 0.5).astype(np.uint8)


@functools.lru_cache(maxsize=16)
def _lut(gamma: Gamma) -> np.ndarray:
    lut = encode8(_curve(np.linspace(0.0, 1.0, _LUT_SIZE), gamma))
    lut.flags.writeable = False
    return lut


@numba.njit(cache=True, nogil=True)
def _apply_lut(flat: np.ndarray, black: float, scale: float, lut: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    top = lut.shape[0] - 1
    for i in range(flat.shape[0]):
        v = (flat[i] - black) * scale
        if v >= top:
            out[i] = lut[top]
        elif v > 0.0:  # also false for NaN
            out[i] = lut[int(v + 0.5)]
        else:
            out[i] = lut[0]


def to_display(img: np.ndarray, black: float = 0.0, white: float = 1.0, gamma: Gamma = "srgb") -> np.ndarray:
    """Map a float image to uint8 for display with fixed levels.

    Args:
        img: ``(H, W)`` or ``(H, W, 3)`` (any shape works) real-valued image, e.g. float32 in [0, 1].
        black: input value shown as 0.
        white: input value shown as 255 (``white > black``).
        gamma: ``"srgb"``, or a power applied after levels (``1/2.2`` display gamma, ``1.0``
            linear).

    Returns:
        uint8 array of the shape of ``img``.
    """
    black, white = _check_levels(black, white)
    gamma = _check_gamma(gamma)
    arr = np.asarray(img)
    if arr.dtype != np.float32 and arr.dtype != np.float64:
        arr = arr.astype(np.float32)
    flat = np.ascontiguousarray(arr).reshape(-1)
    out = np.empty(flat.shape, dtype=np.uint8)
    _apply_lut(flat, black, (_LUT_SIZE - 1) / (white - black), _lut(gamma), out)
    return out.reshape(arr.shape)
