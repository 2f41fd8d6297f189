"""Classical reconstructions (numpy/numba): TFP, TFI, demosaicking, colour cast, display.

Data flow for one frame (see :mod:`spikeview.classical.reconstruct`)::

    source ─► window_range ─► tfp / tfi ─► apply_colour_cast_mosaic ─► demosaic ─► to_display
              (ticks [a, b))  (H, W) SFR    (Y_c·α_c/η, α per sequence)  (H, W, 3)    uint8

Everything here imports only numpy, scipy, numba and ``spikeview.io/cfa/errors/config``.
"""

from spikeview.classical.colour_cast import (
    DEFAULT_ETA,
    ColourCastWarning,
    alpha_from_means,
    alpha_from_sfr,
    alpha_with_note,
    apply_colour_cast,
    apply_colour_cast_mosaic,
    channel_means,
    estimate_alpha,
    sequence_channel_means,
    site_rates,
)
from spikeview.classical.demosaic import DEMOSAIC_METHODS, demosaic
from spikeview.classical.display import to_display, transfer
from spikeview.classical.reconstruct import (
    CLASSICAL_METHODS,
    ClassicalConfig,
    preview_rgb,
    reconstruct_frame,
    reconstruct_frames,
    resolve_alpha,
)
from spikeview.classical.tfi import DEFAULT_HALF_WINDOW, tfi, tfi_array
from spikeview.classical.tfp import counts_to_sfr, tfp, tfp_array, window_counts
from spikeview.classical.windows import window_range

__all__ = [
    "CLASSICAL_METHODS",
    "DEFAULT_ETA",
    "DEFAULT_HALF_WINDOW",
    "DEMOSAIC_METHODS",
    "ClassicalConfig",
    "ColourCastWarning",
    "alpha_from_means",
    "alpha_from_sfr",
    "alpha_with_note",
    "apply_colour_cast",
    "apply_colour_cast_mosaic",
    "channel_means",
    "counts_to_sfr",
    "demosaic",
    "estimate_alpha",
    "preview_rgb",
    "reconstruct_frame",
    "reconstruct_frames",
    "resolve_alpha",
    "sequence_channel_means",
    "site_rates",
    "tfi",
    "tfi_array",
    "tfp",
    "tfp_array",
    "to_display",
    "transfer",
    "window_counts",
    "window_range",
]
