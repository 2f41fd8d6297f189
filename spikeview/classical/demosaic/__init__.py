"""Bayer demosaicking: one algorithm per module, named after its paper.

* ``bilinear`` (:mod:`.bilinear`; Losson et al. 2010 survey): numba, about 1 ms at 1000×1000,
  the live preview's method;
* ``malvar2004`` (:mod:`.malvar2004`; Malvar, He & Cutler): numba, a few ms, sharper;
* ``menon2007`` (:mod:`.menon2007`; Menon, Andriani & Calvagno, DDFAPD): numpy/scipy, a few
  hundred ms, best edges, for export.

All take a mosaicked ``(H, W)`` image whose top-left 2×2 is named by ``cfa`` and return an
``(H, W, 3)`` float32 RGB image (channels R, G, B); bilinear and Malvar mirror the image about
its edge pixels, Menon follows its reference implementation's edge handling.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from spikeview.classical.demosaic.bilinear import demosaic_bilinear
from spikeview.classical.demosaic.malvar2004 import demosaic_malvar2004
from spikeview.classical.demosaic.menon2007 import demosaic_menon2007
from spikeview.errors import ParameterError

_METHODS: dict[str, Callable[[np.ndarray, str], np.ndarray]] = {
    "bilinear": demosaic_bilinear,
    "malvar2004": demosaic_malvar2004,
    "menon2007": demosaic_menon2007,
}
#: valid values of the ``method`` argument (and of ``ClassicalConfig.demosaic``)
DEMOSAIC_METHODS: tuple[str, ...] = tuple(_METHODS)


def check_method(method: str) -> str:
    """Normalise a demosaicking method name; :class:`ParameterError` naming the choices otherwise."""
    m = str(method).strip().lower()
    if m not in _METHODS:
        raise ParameterError(f"Unknown demosaic method {method!r}: use one of {', '.join(DEMOSAIC_METHODS)}.")
    return m


def demosaic(cfa_image: np.ndarray, cfa: str, method: str = "bilinear") -> np.ndarray:
    """Demosaic a mosaicked image.

    Args:
        cfa_image: ``(H, W)`` mosaicked values, e.g. a TFP frame (float32 SFR in [0, 1]).
        cfa: top-left 2×2 of ``cfa_image`` after flips (``"RGGB"``, ``"BGGR"``, ``"GRBG"``,
            ``"GBRG"``).
        method: one of :data:`DEMOSAIC_METHODS`.

    Returns:
        ``(H, W, 3)`` float32 RGB. Bilinear stays inside the input range; Malvar and Menon can
        overshoot slightly at edges (not clipped here).

    Raises:
        ParameterError: unknown method, monochrome/unknown CFA, or an image that is not 2-D or is
            too small for the method.
    """
    return _METHODS[check_method(method)](cfa_image, cfa)


__all__ = ["DEMOSAIC_METHODS", "check_method", "demosaic", "demosaic_bilinear", "demosaic_malvar2004", "demosaic_menon2007"]
