"""Numba kernels of the app's display path (imported on first use; compiled code is cached)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def block_mean_u8(img: np.ndarray, f: int) -> np.ndarray:  # pragma: no cover - compiled
    """Rounded mean over ``f × f`` blocks of an ``(H, W, C)`` uint8 image (edges cropped)."""
    h, w, c = img.shape[0] // f, img.shape[1] // f, img.shape[2]
    out = np.empty((h, w, c), dtype=np.uint8)
    n = f * f
    for i in range(h):
        for j in range(w):
            for k in range(c):
                acc = 0
                for di in range(f):
                    for dj in range(f):
                        acc += img[i * f + di, j * f + dj, k]
                out[i, j, k] = (acc + n // 2) // n
    return out
