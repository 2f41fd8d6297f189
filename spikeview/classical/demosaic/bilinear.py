"""Bilinear demosaicking (as surveyed by Losson, Macaire & Yang 2010, "Comparison of color
demosaicing methods").

Every missing colour is the mean of the nearest photosites of that colour: G at an R/B site from
its 4 edge neighbours; R/B at a G site from the 2 neighbours in the row or column that carries
that colour; B at R (R at B) from the 4 diagonal neighbours. Each output channel is interpolated
only from sites of the same channel, so the operation is linear per channel and commutes with a
per-channel gain (white balance / colour cast).

Edges: the image is mirrored about its edge pixels (scipy.ndimage ``mode="mirror"``), which keeps
the Bayer phase, so border pixels are averaged over the same kind of neighbours as the interior.
(The ``colour-demosaicing`` package uses scipy's default ``"reflect"`` mode, which brings the wrong
colour in at the border, so its outermost row and column differ; inside them both agree.)
"""

from __future__ import annotations

import numba
import numpy as np

from spikeview.classical.demosaic._common import check_cfa_image, quad_codes


@numba.njit(cache=True, nogil=True, inline="always")
def _g_site(o, x, ci, vi, row, rowm, rowp, xm, xp):  # type: ignore[no-untyped-def]  # pragma: no cover
    # green photosite: colour ci from the row neighbours, vi from the column neighbours
    half = np.float32(0.5)
    o[x, 1] = row[x]
    o[x, ci] = (row[xm] + row[xp]) * half
    o[x, vi] = (rowm[x] + rowp[x]) * half


@numba.njit(cache=True, nogil=True, inline="always")
def _c_site(o, x, ci, vi, row, rowm, rowp, xm, xp):  # type: ignore[no-untyped-def]  # pragma: no cover
    # red/blue photosite ci: green from the 4 edge neighbours, vi from the 4 diagonals
    quarter = np.float32(0.25)
    o[x, ci] = row[x]
    o[x, 1] = (rowm[x] + rowp[x] + row[xm] + row[xp]) * quarter
    o[x, vi] = (rowm[xm] + rowm[xp] + rowp[xm] + rowp[xp]) * quarter


@numba.njit(cache=True, nogil=True, inline="always")
def _row(o, row, rowm, rowp, w, g_even, ci, vi):  # type: ignore[no-untyped-def]  # pragma: no cover
    # one output row; ci (the row's red/blue) and vi (the other one) are literals after inlining
    for x in (0, w - 1):
        xm = x - 1 if x > 0 else 1  # mirror about the edge pixel
        xp = x + 1 if x < w - 1 else w - 2
        if ((x & 1) == 0) == g_even:
            _g_site(o, x, ci, vi, row, rowm, rowp, xm, xp)
        else:
            _c_site(o, x, ci, vi, row, rowm, rowp, xm, xp)
    # interior, two photosites per step so that the site type is fixed in the loop: a green first
    # photosite is done on its own, and the rest of the row starts at a colour site
    x = 1
    if not g_even and x < w - 1:
        _g_site(o, x, ci, vi, row, rowm, rowp, x - 1, x + 1)
        x = 2
    while x + 1 < w - 1:
        _c_site(o, x, ci, vi, row, rowm, rowp, x - 1, x + 1)
        _g_site(o, x + 1, ci, vi, row, rowm, rowp, x, x + 2)
        x += 2
    if x < w - 1:
        _c_site(o, x, ci, vi, row, rowm, rowp, x - 1, x + 1)


@numba.njit(cache=True, nogil=True)
def _bilinear_kernel(img: np.ndarray, quad: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    h, w = img.shape
    for y in range(h):
        ym = y - 1 if y > 0 else 1  # mirror about the edge pixel
        yp = y + 1 if y < h - 1 else h - 2
        g_even = quad[y & 1, 0] == 1  # green at even columns of this row
        ci = quad[y & 1, 1] if g_even else quad[y & 1, 0]  # the row's other colour
        # literal channel indices let the compiler fold the output offsets
        if ci == 0:
            _row(out[y], img[y], img[ym], img[yp], w, g_even, 0, 2)
        else:
            _row(out[y], img[y], img[ym], img[yp], w, g_even, 2, 0)


def demosaic_bilinear(cfa_image: np.ndarray, cfa: str) -> np.ndarray:
    """Bilinear demosaicking of a mosaicked image.

    Args:
        cfa_image: ``(H, W)`` mosaicked values (any real dtype; computed in float32), ``H, W >= 2``.
        cfa: top-left 2×2 of ``cfa_image`` (``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"``).

    Returns:
        ``(H, W, 3)`` float32 RGB in the value range of the input (a convex combination of input
        values, so ``[0, 1]`` in gives ``[0, 1]`` out). Each photosite keeps its own value in its
        own channel.
    """
    img = check_cfa_image(cfa_image, 2, "bilinear")
    quad = quad_codes(cfa)
    out = np.empty(img.shape + (3,), dtype=np.float32)
    _bilinear_kernel(img, quad, out)
    return out
