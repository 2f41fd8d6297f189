"""Settings of the classical reconstructions (TFP/TFI), the ``[classical]`` table of a recipe.

Light on purpose (no numba, no torch; :mod:`spikeview.classical` imports its numba modules lazily):
the CLI builds its flags from these settings at start-up. The observation fields here (window Δτ,
demosaic, colour cast, η, α) are shared with the guided sampler; their one home is this table
(:mod:`spikeview.recipe`). Each settable field is declared once with :func:`~spikeview.config.param`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from spikeview.config import Config, param
from spikeview.errors import ParameterError

#: η: after the gray-world correction each channel's sequence mean is ``1/η``
DEFAULT_ETA = 2.0
#: windows sampled from a long stream for the gray-world estimate
DEFAULT_ALPHA_WINDOWS = 64
#: TFI search half-window in ticks
DEFAULT_HALF_WINDOW = 32
#: demosaicking methods (one file each in :mod:`spikeview.classical.demosaic`)
DEMOSAICS = ("auto", "bilinear", "malvar2004", "menon2007")

#: valid values of :attr:`ClassicalConfig.method`
CLASSICAL_METHODS = ("tfp", "tfi")


@dataclasses.dataclass
class ClassicalConfig(Config):
    """Settings of a classical reconstruction (saved to / loaded from TOML).

    Attributes:
        method: ``"tfp"`` (spike count over a window) or ``"tfi"`` (inter-spike interval).
        window: TFP window Δτ in ticks (10 ticks = 0.5 ms at 20 kHz, the SpikeDiff observation).
        tfi_half_window: TFI search half-window in ticks (missing spikes cap the interval at twice it).
        demosaic: ``"auto"`` (the plan's rule from the measured noise: bilinear where noise dominates,
            Malvar-2004 where the window is clean or the prior denoises afterwards;
            :func:`spikeview.guided.plan.choose_demosaic`), or one of ``"bilinear"``,
            ``"malvar2004"``, ``"menon2007"`` (Bayer streams only).
        colour_cast: undo the sensor's colour cast with gains chosen by ``white_balance`` (Bayer streams only;
            monochrome frames are returned uncorrected).
        eta: range parameter η: after correction each channel's sequence mean is ``1/η``.
        alpha: fixed gray-world gains ``[α_R, α_G, α_B]``; ``None`` estimates them once per
            sequence with :func:`estimate_alpha`.
        white_balance: how the gains are estimated when ``alpha`` is unset: ``auto`` (the camera profile's colour
            response when one is attached; else gray-world where the scene averages to gray, else an estimator that
            does not assume it, with the reason printed), ``gray-world``,
            ``gray-edge``, ``gray-edge-2``, ``shades-of-gray``, ``white-patch``, ``combined``, ``profile`` (the
            camera profile's colour response) or fixed gains ``"R,G,B"``
            (:mod:`spikeview.classical.white_balance`).
        alpha_window, alpha_max_windows: how :func:`estimate_alpha` samples the sequence.
        clip: clip frames to ``[0, 1]``; off (default), frames keep scene-linear values above 1
            (highlights brighter than 1/η's scale, Malvar/Menon overshoot): the exports map them by the
            sequence's white point (:func:`spikeview.pipeline.write_sequence`).
    """

    TABLE = "classical"

    method: str = "tfp"
    window: int = param(10, label="Window Δτ", unit="ticks", lo=1, hi=4096, step=1,
                        help="TFP window Δτ in ticks (10 ticks = 0.5 ms at 20 kHz); also the guided sampler's observation.")
    tfi_half_window: int = param(DEFAULT_HALF_WINDOW, label="TFI half-window", unit="ticks", lo=1, hi=512, step=1,
                                 help="TFI searches at least this many ticks before and after the centre tick (a dark "
                                      "capture's search reaches until an empty search reads its darkest floor, up to 512: "
                                      "the CLI and the TFI pane's title say how far).")
    demosaic: str = param("auto", label="Demosaicking", choices=DEMOSAICS,
                          help="Demosaicking of TFP/TFI outputs and of the guided start estimate: auto (the plan picks from "
                               "the measured noise: bilinear where noise dominates, malvar2004 where clean or denoised "
                               "afterwards), bilinear, malvar2004 or menon2007.")
    colour_cast: bool = param(True, label="Correct colour cast",
                              help="Undo the sensor's per-channel response with gains estimated once per sequence "
                                   "(white_balance says how; Bayer streams).")
    eta: float = param(DEFAULT_ETA, label="Colour range η", lo=0.0, lo_open=True, hi=8.0, step=0.05,
                       help="Range parameter η of the colour cast: after correction each channel's sequence mean is 1/η "
                            "(2 → 0.5).")
    white_balance: str = param("auto", key="white_balance", label="White balance",
                               help="How the colour-cast gains are estimated once per sequence: auto (the camera profile's "
                                    "colour response when it has one; else gray-world where the scene averages to gray "
                                    "(a dark one once its dark rate is taken off), else combined pulled toward the "
                                    "typical spike-camera response, or toward neutral when it lands near R = G = B; the "
                                    "reason is printed), gray-world, gray-edge, gray-edge-2, shades-of-gray, "
                                    "white-patch, combined, typical (the typical response R 0.6 / G 1 / B 0.5), "
                                    "profile (the --camera profile's colour response) or fixed gains R,G,B.")
    alpha: list[float] | None = None
    alpha_window: int = 10
    alpha_max_windows: int = DEFAULT_ALPHA_WINDOWS
    clip: bool = False

    def __post_init__(self) -> None:
        self.method = str(self.method).strip().lower()
        if self.method not in CLASSICAL_METHODS:
            raise ParameterError(f"Unknown classical method {self.method!r}: use one of {', '.join(CLASSICAL_METHODS)}.")
        self.check_params()
        for name in ("window", "tfi_half_window", "alpha_window", "alpha_max_windows"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ParameterError(f"{name} must be a whole number >= 1, got {value!r}; fix the setting.")
        self.alpha = check_gains("classical.alpha", self.alpha)
        from spikeview.classical.white_balance import parse_white_balance

        wb = parse_white_balance(self.white_balance, "classical.white_balance")
        self.white_balance = wb if isinstance(wb, str) else ",".join(f"{v:g}" for v in wb)


def check_gains(name: str, alpha: list[float] | None) -> list[float] | None:
    """Colour-cast gains as three finite positive floats ``[α_R, α_G, α_B]`` (``None`` stays unset)."""
    if alpha is None:
        return None
    a = [float(v) for v in alpha]
    if len(a) != 3 or not all(np.isfinite(v) and v > 0 for v in a):
        raise ParameterError(f"{name} = {alpha!r} must be three finite positive gains [R, G, B], or unset to estimate them.")
    return a
