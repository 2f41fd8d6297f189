"""Classical reconstructions (numpy/numba): TFP, TFI, demosaicking, colour cast, display.

Data flow for one frame (see :mod:`spikeview.classical.reconstruct`)::

    source ─► window_range ─► tfp / tfi ─► apply_colour_cast_mosaic ─► demosaic ─► to_display
              (ticks [a, b))  (H, W) SFR    (Y_c·α_c/η, α per sequence)  (H, W, 3)    uint8

Everything here imports only numpy, scipy, numba and ``spikeview.io/cfa/errors/config``; the package
exports are lazy, so ``spikeview.classical.config`` (the settings) loads without numba.
"""

from spikeview._lazy import lazy_exports

_EXPORTS = {
    "CLASSICAL_METHODS": "spikeview.classical.config",
    "ClassicalConfig": "spikeview.classical.config",
    "ColourCastWarning": "spikeview.classical.colour_cast",
    "DEFAULT_ETA": "spikeview.classical.colour_cast",
    "DEFAULT_HALF_WINDOW": "spikeview.classical.tfi",
    "DEMOSAIC_METHODS": "spikeview.classical.demosaic",
    "alpha_from_means": "spikeview.classical.colour_cast",
    "alpha_from_sfr": "spikeview.classical.colour_cast",
    "alpha_with_note": "spikeview.classical.colour_cast",
    "apply_colour_cast": "spikeview.classical.colour_cast",
    "apply_colour_cast_mosaic": "spikeview.classical.colour_cast",
    "channel_means": "spikeview.classical.colour_cast",
    "counts_to_sfr": "spikeview.classical.tfp",
    "demosaic": "spikeview.classical.demosaic",
    "estimate_alpha": "spikeview.classical.colour_cast",
    "preview_rgb": "spikeview.classical.reconstruct",
    "reconstruct_frame": "spikeview.classical.reconstruct",
    "reconstruct_frames": "spikeview.classical.reconstruct",
    "resolve_alpha": "spikeview.classical.reconstruct",
    "sequence_channel_means": "spikeview.classical.colour_cast",
    "site_rates": "spikeview.classical.colour_cast",
    "tfi": "spikeview.classical.tfi",
    "tfi_array": "spikeview.classical.tfi",
    "tfp": "spikeview.classical.tfp",
    "tfp_array": "spikeview.classical.tfp",
    "to_display": "spikeview.classical.display",
    "transfer": "spikeview.classical.display",
    "window_counts": "spikeview.classical.tfp",
    "window_range": "spikeview.classical.windows",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
