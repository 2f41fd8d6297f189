"""Colour filter array (Bayer) naming and masks.

A CFA is named by its explicit top-left 2×2 block in reading order, **after** the orientation
flips have been applied to the decoded frame: ``"RGGB"`` means R at (0, 0), G at (0, 1), G at
(1, 0) and B at (1, 1). Monochrome streams use ``None`` (spelled ``"none"`` in files and flags).

Channel indices are 0 = R, 1 = G, 2 = B. The two greens of a Bayer quad are told apart as
"Gr" (the green on the red row) and "Gb" (the green on the blue row) where statistics need it.
"""

from __future__ import annotations

import numpy as np

from spikeview.errors import ParameterError

BAYER_PATTERNS: tuple[str, ...] = ("RGGB", "BGGR", "GRBG", "GBRG")
CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}
CHANNEL_NAMES = ("R", "G", "B")
#: names of the four photosite classes of a Bayer quad, in the order used by :func:`site_masks`
SITE_NAMES = ("R", "Gr", "Gb", "B")
#: the nominal response of a colour spike camera's R, G and B photosites to a neutral surface in daylight (relative
#: to G): green-heavy, like silicon behind a Bayer filter (real colour captures look green). The simulator's default
#: sensor and the prior of ``--white-balance auto`` (:mod:`spikeview.classical.white_balance`); a camera profile
#: measures the real one.
TYPICAL_RESPONSE = (0.6, 1.0, 0.5)


def parse_cfa(value: str | None) -> str | None:
    """Normalise a CFA setting: one of :data:`BAYER_PATTERNS` (case-insensitive) or ``None``.

    ``None``, ``""``, ``"none"`` and ``"mono"`` mean monochrome. Anything else raises
    :class:`ParameterError` naming the valid choices.
    """
    if value is None:
        return None
    v = str(value).strip().upper()
    if v in ("", "NONE", "MONO", "MONOCHROME"):
        return None
    if v not in BAYER_PATTERNS:
        raise ParameterError(
            f"Unknown CFA {value!r}: use one of {', '.join(BAYER_PATTERNS)} (top-left 2x2 after flips) or 'none' for monochrome."
        )
    return v


def cfa_to_str(cfa: str | None) -> str:
    """The spelling used in files and on the command line (``"none"`` for monochrome)."""
    return "none" if cfa is None else cfa


def flip_cfa(cfa: str | None, height: int, width: int, vertical: bool = False, horizontal: bool = False) -> str | None:
    """The CFA name seen after flipping a frame of the given size.

    Flipping an even-height frame vertically swaps the row parity (RGGB <-> GBRG); an odd height
    keeps it. Likewise horizontally with the width.
    """
    cfa = parse_cfa(cfa)
    if cfa is None:
        return None
    quad = [[cfa[0], cfa[1]], [cfa[2], cfa[3]]]
    if vertical and height % 2 == 0:
        quad = [quad[1], quad[0]]
    if horizontal and width % 2 == 0:
        quad = [[r[1], r[0]] for r in quad]
    return "".join(quad[0] + quad[1])


def channel_map(cfa: str, height: int, width: int) -> np.ndarray:
    """(H, W) int8 array of the channel index (0 R, 1 G, 2 B) of every photosite."""
    cfa = parse_cfa(cfa)
    if cfa is None:
        raise ParameterError("channel_map needs a Bayer CFA, got monochrome ('none').")
    quad = np.array([[CHANNEL_INDEX[cfa[0]], CHANNEL_INDEX[cfa[1]]], [CHANNEL_INDEX[cfa[2]], CHANNEL_INDEX[cfa[3]]]], dtype=np.int8)
    reps = ((height + 1) // 2, (width + 1) // 2)
    return np.tile(quad, reps)[:height, :width]


def channel_masks(cfa: str, height: int, width: int) -> np.ndarray:
    """(H, W, 3) bool array: ``masks[..., c]`` is True where the photosite sees channel c."""
    cmap = channel_map(cfa, height, width)
    return np.stack([cmap == c for c in range(3)], axis=-1)


def site_masks(cfa: str, height: int, width: int) -> dict[str, np.ndarray]:
    """(H, W) bool masks of the four Bayer sites ``R``, ``Gr``, ``Gb``, ``B``.

    ``Gr`` is the green sharing rows with red, ``Gb`` the green sharing rows with blue.
    """
    cfa = parse_cfa(cfa)
    if cfa is None:
        raise ParameterError("site_masks needs a Bayer CFA, got monochrome ('none').")
    yy, xx = np.mgrid[0:height, 0:width]
    return {name: (yy % 2 == py) & (xx % 2 == px) for name, (py, px) in site_offsets(cfa).items()}


def site_offsets(cfa: str) -> dict[str, tuple[int, int]]:
    """Row/column parity ``(py, px)`` in the 2×2 quad of each Bayer site ``R``, ``Gr``, ``Gb``, ``B``
    (``Gr`` shares rows with red): the one rule every per-site statistic uses."""
    red_row = 0 if "R" in (cfa[0], cfa[1]) else 1
    out = {}
    for (py, px), ch in zip(((0, 0), (0, 1), (1, 0), (1, 1)), cfa):
        out[ch if ch != "G" else ("Gr" if py == red_row else "Gb")] = (py, px)
    return {k: out[k] for k in SITE_NAMES}


def crop_roi(img: np.ndarray, roi: tuple[int, int, int, int] | None) -> tuple[np.ndarray, tuple[int, int]]:
    """``img[y:y+h, x:x+w]`` for ``roi = (x, y, w, h)`` with ``x, y`` rounded down to even pixels (the
    CFA phase stays that of the full frame); returns the crop and its ``(y, x)`` origin."""
    if roi is None:
        return img, (0, 0)
    x, y, w, h = (int(v) for v in roi)
    x0, y0 = max(0, x) & ~1, max(0, y) & ~1
    x1, y1 = min(img.shape[1], x + w), min(img.shape[0], y + h)
    if x1 - x0 < 2 or y1 - y0 < 2:
        raise ParameterError("The region of interest is empty: draw a rectangle inside the frame.")
    return img[y0:y1, x0:x1], (y0, x0)
