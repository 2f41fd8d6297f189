"""Classical reconstructions (numpy/numba): TFP, TFI, demosaicking, colour cast, display.

Data flow for one frame (see :mod:`spikeview.classical.reconstruct`)::

    source ─► window_range ─► tfp / tfi ─► apply_colour_cast_mosaic ─► demosaic ─► to_display
              (ticks [a, b))  (H, W) SFR    (Y_c·α_c/η, α per sequence)  (H, W, 3)    uint8

Everything here imports only numpy, scipy, numba and ``spikeview.io/cfa/errors/config``. The names
below are imported on first use (``import spikeview.classical.config``, which the CLI needs at
start-up, loads no numba). The functions named like their modules are imported from those:
``from spikeview.classical.demosaic import demosaic``, ``…tfi import tfi``, ``…tfp import tfp``.
"""

from spikeview._lazy import lazy_exports

#: module of each public name (imported on first use)
_EXPORTS = {
    **dict.fromkeys(["DEFAULT_ETA", "ColourCastWarning", "alpha_from_means", "alpha_from_sfr", "alpha_with_note",
                     "apply_colour_cast", "apply_colour_cast_mosaic", "channel_means", "estimate_alpha",
                     "sequence_channel_means", "site_rates"], "spikeview.classical.colour_cast"),
    **dict.fromkeys(["CLASSICAL_METHODS", "ClassicalConfig"], "spikeview.classical.config"),
    **dict.fromkeys(["DEMOSAIC_METHODS"], "spikeview.classical.demosaic"),
    **dict.fromkeys(["to_display", "transfer"], "spikeview.classical.display"),
    **dict.fromkeys(["preview_rgb", "reconstruct_frame", "reconstruct_frames", "resolve_alpha"], "spikeview.classical.reconstruct"),
    **dict.fromkeys(["DEFAULT_HALF_WINDOW", "tfi_array"], "spikeview.classical.tfi"),
    **dict.fromkeys(["counts_to_sfr", "tfp_array", "window_counts"], "spikeview.classical.tfp"),
    **dict.fromkeys(["window_range"], "spikeview.classical.windows"),
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
