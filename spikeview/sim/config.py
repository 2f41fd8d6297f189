"""Settings of the spike simulator (:class:`SimConfig`), light to import (numpy only).

The sensor model and its units
==============================

Everything is expressed per photosite and per tick (one readout, ``1 / tick_rate`` seconds).

* **Voltage.** The integrator voltage ``E`` is counted in volts of photodiode swing; the nominal
  firing threshold is ``threshold_v`` (1 V by default, the order of the Vdd − Vref swing of a
  3.3 V pixel). Internally the simulator divides every voltage by ``threshold_v``.
* **Photo-current.** The photo-current is scaled so that, with every noise switched off, a
  photosite whose channel sees linear intensity ``I`` gains ``rate · gain_c · I · threshold_v``
  volts per tick and so fires ``rate · gain_c · I`` spikes per tick on average (``gain_c`` is the
  spectral gain of its CFA channel; a monochrome photosite sees the Rec. 709 luminance with gain
  1). Reset is by subtraction of the threshold; the initial voltage is uniform in
  ``[0, threshold)``. A pixel can fire at most once per tick and holds at most one threshold of
  charge above the reset level, so a pixel driven harder than 1 spike/tick saturates at exactly
  1 spike/tick.
* **Charge.** The nominal photodiode capacitance ``capacitance_mean_ff`` (fF) and
  ``threshold_v`` give the number of electrons per threshold crossing,
  ``N_e = C · V_th / q`` (27,139 e⁻ with the defaults). A tick at intensity ``I`` collects
  ``λ = rate · gain_c · I · N_e`` photo-electrons.

The noise terms (each has its own switch and its own random stream, so turning one off leaves the
others' draws unchanged). Constants are those published with the SCSim simulator; SCSim does not
state all units, so spikeview reads them as follows:

* ``dark_current`` — fixed pattern, per pixel ``I_d ~ N(0.4442, 0.1731)`` **pA**, clipped at 0,
  added to the photo-current as charge: ``I_d / (q · tick_rate)`` electrons per tick
  (138.6 e⁻/tick at 20 kHz, i.e. 0.0051 threshold/tick ≈ 102 dark spikes per second, or an
  intensity of 0.0085 at rate 0.6).
* ``prnu`` — fixed pattern photo-response non-uniformity: per-pixel gain ``g ~ N(1, 0.058)``
  (clipped at 0) on the photo-current (not on the dark current).
* ``threshold_fpn`` — fixed pattern of the threshold: per-pixel capacitance
  ``C ~ N(4.348, 0.0128)`` fF (the voltage step is ``charge / C``) and comparator offset
  ``δ ~ N(−0.0076, 0.0497)`` V (the pixel fires and resets at ``threshold_v + δ``). The offset's
  mean lowers the average threshold by 0.76 %, so the average rate rises by about 0.77 %.
* ``shot_noise`` — the electron count of each tick (photo + dark) is Poisson(λ): exact (Knuth)
  below λ = 20, normal approximation N(λ, λ) above, where the two are indistinguishable.
* ``threshold_jitter`` — each comparison uses ``threshold + j``, ``j ~ N(0, 0.0064)`` V, drawn
  per pixel and per tick; the reset still subtracts the pixel's fixed threshold.
* ``reset_slowdown`` — the tick right after a spike integrates ``× 0.998`` of its charge.

Ground truth is the scene's clean linear RGB at the tick (no spectral gains, no noise); see
:class:`spikeview.sim.simulator.SimulatedCapture`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from spikeview.cfa import cfa_to_str, parse_cfa
from spikeview.config import Config
from spikeview.cfa import TYPICAL_RESPONSE
from spikeview.errors import ParameterError

#: elementary charge (C)
ELEMENTARY_CHARGE = 1.602176634e-19
#: Rec. 709 luminance weights, the response of a monochrome photosite to linear RGB
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
#: names of the noise switches, in the order the sidecar lists them
NOISE_SWITCHES = ("dark_current", "prnu", "threshold_fpn", "shot_noise", "threshold_jitter", "reset_slowdown")


@dataclasses.dataclass
class SimConfig(Config):
    """Everything the simulator needs besides the scene; saves to TOML and loads back unchanged.

    Geometry and time:
        width, height: output size in pixels; ``None`` keeps the scene's (cropped) size. The
            scene is resized (bilinear, anti-aliased when shrinking) when they differ.
        crop: ``[top, left, height, width]`` in scene pixels, applied before resizing; ``None``
            uses the whole scene.
        n_ticks: number of ticks to simulate (≥ 1).
        tick_rate: readouts per second (Hz); 20 kHz for the PKU cameras.
        start_s: scene time (seconds) of tick 0; tick ``t`` sees the scene at
            ``start_s + t / tick_rate``.

    Response:
        rate: spikes per tick at linear intensity 1 in a channel of gain 1 (0.6 in the public
            synthetic sets).
        cfa: ``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"`` (top-left 2×2 of the frames as read,
            i.e. after the reader's flips) or ``"none"`` for a monochrome sensor.
        spectral_gains: relative response of the R, G and B photosites (each ≥ 0). The default
            ``(0.6, 1.0, 0.5)`` (:data:`spikeview.cfa.TYPICAL_RESPONSE`) is green-heavy like silicon behind a Bayer
            filter in daylight:
            a grey scene gives a green-cast mosaic, which gray-world colour-cast correction
            (α_c = 1 / mean(Y_c)) has to undo. Ignored for ``cfa="none"``.

    Noise (see the module docstring for the model and units): the switches ``dark_current``,
    ``prnu``, ``threshold_fpn``, ``shot_noise``, ``threshold_jitter`` and ``reset_slowdown``, and
    their constants ``threshold_v`` (V), ``capacitance_mean_ff``/``capacitance_std_ff`` (fF),
    ``threshold_offset_mean_v``/``threshold_offset_std_v`` (V), ``dark_current_mean_pa``/
    ``dark_current_std_pa`` (pA), ``prnu_std`` (relative), ``jitter_std_v`` (V) and
    ``reset_factor``. ``hot_pixels``: the fraction of photosites whose dark current is ``hot_pixel_factor`` times
    their drawn value (hot pixels; needs ``dark_current``; 0 by default, drawn from a stream of their own so that
    every other draw is unchanged).

    Output:
        seed: seed of every random draw (fixed patterns, initial voltages, temporal noise); the
            same seed and settings give identical spikes, whatever the chunking.
        gt_every: ticks between ground-truth frames; frames are kept at ticks
            ``0, gt_every, 2·gt_every, …`` (a window ``[t − Δτ/2, t + Δτ/2)`` then has its
            ground truth at its centre tick ``t``). The default, 50, keeps a ``.gt.npz`` (6 bytes
            per pixel per frame before compression) below the capture (1/8 byte per pixel per
            tick); use a multiple of the reconstruction step to have a frame at every centre.
        flip_vertical: store rows upside down when writing a ``.dat`` (the ecosystem's
            convention; readers flip them back by default).
    """

    width: int | None = None
    height: int | None = None
    crop: list[int] | None = None
    n_ticks: int = 2000
    tick_rate: float = 20_000.0
    start_s: float = 0.0

    rate: float = 0.6
    cfa: str = "RGGB"
    spectral_gains: tuple[float, float, float] = TYPICAL_RESPONSE

    dark_current: bool = True
    prnu: bool = True
    threshold_fpn: bool = True
    shot_noise: bool = True
    threshold_jitter: bool = True
    reset_slowdown: bool = True

    threshold_v: float = 1.0
    capacitance_mean_ff: float = 4.348
    capacitance_std_ff: float = 0.0128
    threshold_offset_mean_v: float = -0.0076
    threshold_offset_std_v: float = 0.0497
    dark_current_mean_pa: float = 0.4442
    dark_current_std_pa: float = 0.1731
    prnu_std: float = 0.058
    jitter_std_v: float = 0.0064
    reset_factor: float = 0.998
    hot_pixels: float = 0.0
    hot_pixel_factor: float = 100.0

    seed: int = 0
    gt_every: int = 50
    flip_vertical: bool = True

    def __post_init__(self) -> None:
        self.cfa = cfa_to_str(parse_cfa(self.cfa))
        self.spectral_gains = tuple(float(g) for g in self.spectral_gains)  # type: ignore[assignment]
        _check(len(self.spectral_gains) == 3 and all(math.isfinite(g) and g >= 0 for g in self.spectral_gains),
               "spectral_gains", self.spectral_gains, "three finite numbers ≥ 0 (R, G, B)")
        for name in ("width", "height"):
            v = getattr(self, name)
            _check(v is None or v >= 1, name, v, "a positive number of pixels or left unset")
        if self.crop is not None:
            self.crop = [int(v) for v in self.crop]
            _check(len(self.crop) == 4 and self.crop[0] >= 0 and self.crop[1] >= 0 and self.crop[2] >= 1
                   and self.crop[3] >= 1, "crop", self.crop, "[top, left, height, width] with top, left ≥ 0 and a positive size")
        _check(self.n_ticks >= 1, "n_ticks", self.n_ticks, "at least 1")
        _check(_pos(self.tick_rate), "tick_rate", self.tick_rate, "a positive frequency in Hz (20000 for the PKU cameras)")
        _check(math.isfinite(self.start_s) and self.start_s >= 0, "start_s", self.start_s, "a time ≥ 0 in seconds")
        _check(_pos(self.rate), "rate", self.rate, "a positive number of spikes per tick at intensity 1 (0.6 in the synthetic sets)")
        _check(_pos(self.threshold_v), "threshold_v", self.threshold_v, "a positive voltage")
        _check(_pos(self.capacitance_mean_ff), "capacitance_mean_ff", self.capacitance_mean_ff, "a positive capacitance in fF")
        for name in ("capacitance_std_ff", "threshold_offset_std_v", "dark_current_std_pa", "prnu_std", "jitter_std_v"):
            v = getattr(self, name)
            _check(math.isfinite(v) and v >= 0, name, v, "a standard deviation ≥ 0")
        for name in ("threshold_offset_mean_v", "dark_current_mean_pa"):
            _check(math.isfinite(getattr(self, name)), name, getattr(self, name), "a finite number")
        _check(math.isfinite(self.reset_factor) and 0 < self.reset_factor <= 1, "reset_factor", self.reset_factor,
               "a factor in (0, 1]")
        _check(math.isfinite(self.hot_pixels) and 0 <= self.hot_pixels <= 1, "hot_pixels", self.hot_pixels,
               "a fraction of the photosites in [0, 1]")
        _check(_pos(self.hot_pixel_factor), "hot_pixel_factor", self.hot_pixel_factor, "a positive factor")
        _check(self.seed >= 0, "seed", self.seed, "an integer ≥ 0")
        _check(self.gt_every >= 1, "gt_every", self.gt_every, "at least 1 tick")

    # --- derived quantities ------------------------------------------------------------------
    @property
    def cfa_or_none(self) -> str | None:
        """The CFA as :mod:`spikeview.cfa` spells it (``None`` for monochrome)."""
        return parse_cfa(self.cfa)

    @property
    def electrons_per_threshold(self) -> float:
        """Photo-electrons per nominal threshold crossing, ``C · V_th / q`` (27,139 by default)."""
        return self.capacitance_mean_ff * 1e-15 * self.threshold_v / ELEMENTARY_CHARGE

    @property
    def dark_threshold_per_tick(self) -> float:
        """Mean dark charge per tick in threshold units (0.0051 with the defaults)."""
        electrons = self.dark_current_mean_pa * 1e-12 / ELEMENTARY_CHARGE / self.tick_rate
        return electrons / self.electrons_per_threshold

    @property
    def noise_on(self) -> dict[str, bool]:
        """The noise switches by name."""
        return {name: bool(getattr(self, name)) for name in NOISE_SWITCHES}

    @classmethod
    def noiseless(cls, **changes: Any) -> "SimConfig":
        """A config with every noise term off (the ideal integrate-and-fire sensor)."""
        return cls(**{**{name: False for name in NOISE_SWITCHES}, **changes})

    def with_noise(self, on: bool = True, **switches: bool) -> "SimConfig":
        """A copy with every noise switch set to ``on``, then the named ``switches`` applied."""
        unknown = sorted(set(switches) - set(NOISE_SWITCHES))
        if unknown:
            raise ParameterError(f"Unknown noise switch(es) {', '.join(unknown)}: use {', '.join(NOISE_SWITCHES)}.")
        return self.replace(**{name: on for name in NOISE_SWITCHES}, **switches)


def _pos(v: float) -> bool:
    return math.isfinite(v) and v > 0


def _check(ok: bool, name: str, value: object, wanted: str) -> None:
    if not ok:
        raise ParameterError(f"Simulation setting '{name}' = {value!r} is invalid: use {wanted}.")
