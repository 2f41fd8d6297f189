"""The sRGB transfer curve (IEC 61966-2-1), both ways: its one home; and the rule for display levels.

The exporters (:mod:`spikeview.export.display`), the app's display (:mod:`spikeview.classical.display`),
the simulator's image loading (:mod:`spikeview.sim.images`) and the benchmark's ground truth all call
these two functions. They keep the dtype they are given (float32 in, float32 out; float64 in,
float64 out), so each caller keeps its own precision; they do not clip.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: the display curves of PNG/MP4 and the app (``export.transfer``; ``"auto"`` = the capture's own, :func:`source_transfer`)
TRANSFERS = ("srgb", "gamma", "linear")
#: how the white point (full scale on display) is found, as every run's white-point line says it
#: (:func:`spikeview.classical.colour_cast.estimate_white`)
WHITE_HOW = "the 99.9th percentile of the sequence's rates"
#: where a file source records its display convention (``StreamInfo.extra``; the sidecar's ``[stream] transfer``)
DISPLAY_KEY = "display_transfer"


def source_transfer(info: Any) -> tuple[str, str]:
    """The display curve a capture's rates want, and why: the sidecar's ``transfer``; ``srgb`` for spikeview's own
    captures (a sidecar without it, the simulator, live cameras: rates in proportion to linear light); ``linear``
    for a file without a sidecar, the convention of the ecosystem's tools (SpikeCV, Spike-Zoo show spike rates
    linearly, and their data sets are made from display-referred frames)."""
    extra = getattr(info, "extra", None) or {}
    value = extra.get(DISPLAY_KEY)
    if value in TRANSFERS:
        if "sidecar" in extra:
            return value, f"the capture's sidecar says transfer = {value}"
        if value == "linear":
            return value, ("a capture without a sidecar: spike rates shown linearly, as the ecosystem's tools (SpikeCV, "
                           "Spike-Zoo) do; --transfer srgb for a camera's linear light")
        return value, f"the capture says transfer = {value}"
    return "srgb", "rates in proportion to linear light (a spikeview capture, the simulator or a camera): the sRGB curve"


def resolve_transfer(requested: str, info: Any) -> tuple[str, str]:
    """``export.transfer`` for a capture: ``auto`` → :func:`source_transfer`; a curve the user chose, as is."""
    if requested == "auto":
        return source_transfer(info)
    return requested, f"set by --transfer {requested}"


def levels_ordered(black: float, white: float | None) -> bool:
    """The one rule for display levels (the app's display and the exporters): both finite, white above black.

    ``white=None`` (the sequence's own white point, not known yet) passes.
    """
    return math.isfinite(black) and (white is None or (math.isfinite(white) and white > black))


#: the sRGB curve's knee, in linear light and in encoded values
SRGB_KNEE_LINEAR = 0.0031308
SRGB_KNEE_ENCODED = 0.04045


def _is_tensor(x: Any) -> bool:
    """A torch tensor (checked without importing torch)."""
    return type(x).__module__.split(".")[0] == "torch"


def srgb_encode(linear: Any) -> Any:
    """Linear light to sRGB-encoded values (both nominally ``[0, 1]``), same dtype and shape; a torch tensor stays one
    (on its device: :mod:`spikeview.guided.chroma`)."""
    if _is_tensor(linear):
        import torch

        return torch.where(linear <= SRGB_KNEE_LINEAR, 12.92 * linear,
                           1.055 * torch.pow(torch.clamp(linear, min=SRGB_KNEE_LINEAR), 1 / 2.4) - 0.055)
    x = np.asarray(linear)
    return np.where(x <= SRGB_KNEE_LINEAR, 12.92 * x, 1.055 * np.power(np.maximum(x, SRGB_KNEE_LINEAR), 1 / 2.4) - 0.055)


def srgb_decode(encoded: Any) -> Any:
    """sRGB-encoded values to linear light (the inverse of :func:`srgb_encode`), same dtype and shape; a torch tensor
    stays one."""
    if _is_tensor(encoded):
        import torch

        return torch.where(encoded <= SRGB_KNEE_ENCODED, encoded / 12.92,
                           torch.pow((torch.clamp(encoded, min=SRGB_KNEE_ENCODED) + 0.055) / 1.055, 2.4))
    x = np.asarray(encoded)
    return np.where(x <= SRGB_KNEE_ENCODED, x / 12.92, ((np.maximum(x, SRGB_KNEE_ENCODED) + 0.055) / 1.055) ** 2.4)
