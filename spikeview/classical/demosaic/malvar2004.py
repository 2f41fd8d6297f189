"""Malvar–He–Cutler demosaicking: H. S. Malvar, L.-W. He and R. Cutler, "High-quality linear
interpolation for demosaicing of Bayer-patterned color images", ICASSP 2004.

Bilinear interpolation corrected by the Laplacian of the photosite's own channel, with the paper's
fixed 5×5 kernels (gains α = 1/2, β = 5/8, γ = 3/4). Linear, but it mixes channels, so apply any
per-channel gain (colour cast) to the mosaic *before* demosaicking. Output can overshoot the input
range slightly near edges (the kernels have negative taps).

Edges: the image is mirrored about its edge pixels (scipy.ndimage ``mode="mirror"``), which keeps
the Bayer phase. (``colour-demosaicing`` uses scipy's default ``"reflect"``, which brings the wrong
colour in at the border; the two agree except in the outer 2 rows and columns.)
"""

from __future__ import annotations

import numba
import numpy as np

from spikeview.classical.demosaic._common import check_cfa_image, quad_codes


@numba.njit(cache=True, nogil=True, inline="always")
def _g_site(o, x, ci, vi, r0, r1, r2, r3, r4):  # type: ignore[no-untyped-def]  # pragma: no cover
    # green photosite; r0..r4 are padded rows y-2..y+2, padded column of x is x + 2
    px = x + 2
    v = r2[px]
    diag = r1[px - 1] + r1[px + 1] + r3[px - 1] + r3[px + 1]
    o[x, 1] = v
    # colour ci lies left/right (kernel with 4/8 taps along the row), vi above/below
    o[x, ci] = (np.float32(5) * v + np.float32(4) * (r2[px - 1] + r2[px + 1]) - (r2[px - 2] + r2[px + 2]) - diag
                + np.float32(0.5) * (r0[px] + r4[px])) * np.float32(0.125)
    o[x, vi] = (np.float32(5) * v + np.float32(4) * (r1[px] + r3[px]) - (r0[px] + r4[px]) - diag
                + np.float32(0.5) * (r2[px - 2] + r2[px + 2])) * np.float32(0.125)


@numba.njit(cache=True, nogil=True, inline="always")
def _c_site(o, x, ci, vi, r0, r1, r2, r3, r4):  # type: ignore[no-untyped-def]  # pragma: no cover
    # red/blue photosite ci; vi is the opposite colour (on the diagonals)
    px = x + 2
    v = r2[px]
    ring2 = r0[px] + r4[px] + r2[px - 2] + r2[px + 2]
    o[x, ci] = v
    o[x, 1] = (np.float32(4) * v + np.float32(2) * (r1[px] + r3[px] + r2[px - 1] + r2[px + 1]) - ring2) * np.float32(0.125)
    o[x, vi] = (np.float32(6) * v + np.float32(2) * (r1[px - 1] + r1[px + 1] + r3[px - 1] + r3[px + 1])
                - np.float32(1.5) * ring2) * np.float32(0.125)


@numba.njit(cache=True, nogil=True, inline="always")
def _row(o, w, g_even, ci, vi, r0, r1, r2, r3, r4):  # type: ignore[no-untyped-def]  # pragma: no cover
    # two photosites per step so that the site type is fixed in the loop: a green first photosite is
    # done on its own, and the rest of the row starts at a colour site
    x = 0
    if g_even and x < w:
        _g_site(o, x, ci, vi, r0, r1, r2, r3, r4)
        x = 1
    while x + 1 < w:
        _c_site(o, x, ci, vi, r0, r1, r2, r3, r4)
        _g_site(o, x + 1, ci, vi, r0, r1, r2, r3, r4)
        x += 2
    if x < w:
        _c_site(o, x, ci, vi, r0, r1, r2, r3, r4)


@numba.njit(cache=True, nogil=True)
def _malvar_padded(p: np.ndarray, quad: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    h, w = out.shape[0], out.shape[1]
    for y in range(h):
        g_even = quad[y & 1, 0] == 1  # green at even columns of this row
        ci = quad[y & 1, 1] if g_even else quad[y & 1, 0]  # the row's other colour
        # literal channel indices let the compiler fold the output offsets
        if ci == 0:
            _row(out[y], w, g_even, 0, 2, p[y], p[y + 1], p[y + 2], p[y + 3], p[y + 4])
        else:
            _row(out[y], w, g_even, 2, 0, p[y], p[y + 1], p[y + 2], p[y + 3], p[y + 4])


def demosaic_malvar2004(cfa_image: np.ndarray, cfa: str) -> np.ndarray:
    """Malvar–He–Cutler (2004) demosaicking of a mosaicked image.

    Args:
        cfa_image: ``(H, W)`` mosaicked values (any real dtype; computed in float32), ``H, W >= 3``.
        cfa: top-left 2×2 of ``cfa_image`` (``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"``).

    Returns:
        ``(H, W, 3)`` float32 RGB, not clipped (values may leave the input range near edges).
    """
    img = check_cfa_image(cfa_image, 3, "malvar2004")
    quad = quad_codes(cfa)
    out = np.empty(img.shape + (3,), dtype=np.float32)
    # numpy's "reflect" mirrors about the edge pixel (c b | a b c), which keeps the Bayer phase
    _malvar_padded(np.pad(img, 2, mode="reflect"), quad, out)
    return out
