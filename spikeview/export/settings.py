"""Export settings (:class:`ExportConfig`) and what every exported frame records (:class:`ExportMetadata`)."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.config import Config, check_value, param
from spikeview.errors import ParameterError
from spikeview.transfer import TRANSFERS, levels_ordered

#: EXR compressions offered (all lossless); OpenImageIO names
EXR_COMPRESSIONS = ("zip", "piz", "none")
#: libx264 presets, fastest first
X264_PRESETS = (
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
    "placebo",
)
#: how MP4 export makes an odd width/height even (yuv420p needs even sizes)
EVEN_SIZE_MODES = ("pad", "crop")


#: the range of a white point a preset or store may record (linear frame units; the flag's and control's is (0, 16])
WHITE_MIN, WHITE_MAX = 1e-6, 1e6


@dataclasses.dataclass
class ExportConfig(Config):
    """How frames are written. Saved into every output so it can be reproduced.

    Attributes:
        fps: MP4 playback rate in frames per second (> 0). Together with the tick rate and the
            step between output frames it sets the slow-motion factor (see
            :func:`spikeview.export.slow_motion_factor`).
        crf: libx264 constant rate factor, 0 (best) to 51 (worst); 18 is visually lossless.
        preset: libx264 speed/size preset, one of :data:`X264_PRESETS`.
        compression: EXR compression, one of :data:`EXR_COMPRESSIONS` (all lossless).
        png_bits: PNG bit depth, 8 or 16.
        black, white: fixed levels in linear units: ``white`` is the exposure's white point
            (``None``: the sequence's own, :func:`spikeview.classical.colour_cast.estimate_white`,
            chosen once per sequence by :func:`spikeview.pipeline.write_sequence`, which divides
            every frame by it: EXR keeps values above 1, npy is clipped to [0, 1]); for PNG and MP4
            ``black`` maps to 0 and ``white`` to full scale, values outside are clipped. An exporter
            used directly treats ``None`` as 1. Never chosen per frame (no
            auto-levels), so brightness is comparable across a sequence. EXR and npy ignore
            them and keep the linear values as they are.
        transfer: display encoding for PNG and MP4 after the levels: ``"auto"`` (the capture's convention,
            :func:`spikeview.transfer.resolve_transfer`, resolved by the pipeline where the capture is known; an
            exporter given ``auto`` alone uses sRGB, :meth:`curve`), ``"srgb"`` (IEC 61966-2-1 curve),
            ``"gamma"`` (pure power ``1/gamma``) or ``"linear"`` (none).
        gamma: exponent for ``transfer="gamma"`` (> 0).
        first_frame: number of the first file of an EXR/PNG sequence; file ``i`` of the export
            is numbered ``first_frame + i``.
        even_size: MP4 only, for an odd width or height: ``"pad"`` repeats the last row/column
            once (no image content lost, the video is one pixel larger) or ``"crop"`` drops it.
    """

    # the ranges declared with param() are those of the CLI's flags and the app's controls
    # (spikeview.recipe.PARAMS); __post_init__ checks what the writers need (a white point may be
    # recorded as the sequence found it, beyond the controls' range)
    TABLE = "export"

    fps: float = param(30.0, key="export_fps", label="Output fps", unit="fps", lo=0.01, hi=1000.0, step=1.0,
                       help="MP4 playback rate in frames per second.")
    crf: int = param(18, key="", label="MP4 quality", lo=0, hi=51,
                     help="libx264 constant rate factor, 0 (best) to 51; 18 is visually lossless.")
    preset: str = param("medium", flag="--x264-preset", key="", label="x264 preset", choices=X264_PRESETS,
                        help="libx264 speed/size preset.")
    compression: str = param("zip", key="", label="EXR compression", choices=EXR_COMPRESSIONS,
                             help="EXR compression (all lossless).")
    png_bits: int = 8
    black: float = param(0.0, label="Black level", lo=0.0, hi=1.0, step=0.01,
                         help="Linear value shown as black in PNG/MP4 and the app (fixed, never per frame).")
    white: float | None = param(None, label="White point", lo=WHITE_MIN, hi=16.0, step=0.01,
                                help="Exposure: the linear value (Y·α/η with a colour cast, Y in spikes per tick for monochrome) that becomes 1.0 in EXR and full scale in "
                                     "npy/PNG/MP4 and the app; unset, the sequence's 99.9th percentile, chosen once and "
                                     "printed (a file without a sidecar within 25 % of 0.6 spikes per tick takes 0.6, the "
                                     "conversion rate of the ecosystem's synthetic data sets).")
    transfer: str = param("auto", label="Display curve", choices=("auto",) + TRANSFERS,
                          help="Display encoding of PNG/MP4 and the app: auto (the capture's: its sidecar's, sRGB for "
                               "spikeview's own captures and cameras, linear for a file without a sidecar, as the "
                               "ecosystem's tools show it), srgb, gamma (power 1/gamma) or linear.")
    gamma: float = param(2.2, label="Gamma", lo=0.2, hi=5.0, step=0.05, help="Exponent of the gamma display curve.")
    first_frame: int = 0
    even_size: str = "pad"

    def __post_init__(self) -> None:
        def bad(name: str, value: Any, fix: str) -> ParameterError:
            return ParameterError(f"export setting '{name}' = {value!r} is not valid; {fix}.")

        if not (math.isfinite(self.fps) and 0.01 <= self.fps <= 1000):  # the recipe's range of --fps
            raise bad("fps", self.fps, "use a frame rate from 0.01 to 1000 such as 30")
        if not 0 <= self.crf <= 51:
            raise bad("crf", self.crf, "use 0 (best) to 51 (worst); 18 is visually lossless")
        if self.preset not in X264_PRESETS:
            raise bad("preset", self.preset, f"use one of {', '.join(X264_PRESETS)}")
        if self.compression not in EXR_COMPRESSIONS:
            raise bad("compression", self.compression, f"use one of {', '.join(EXR_COMPRESSIONS)}")
        if self.png_bits not in (8, 16):
            raise bad("png_bits", self.png_bits, "use 8 or 16")
        # black and white by the rules of their flags and controls (a preset is checked as --black/--white are); a
        # white point may be recorded beyond the controls' 16 as the sequence found it (dark captures' gains are
        # large), up to WHITE_MAX, where 1/white stays a normal float32
        check_value("export.black", float, self.black, 0.0, 1.0)
        if self.white is not None:
            w = check_value("export.white", float, self.white)
            if not WHITE_MIN <= w <= WHITE_MAX:
                raise bad("white", self.white, f"use a white point from {WHITE_MIN:g} to {WHITE_MAX:g} (linear frame units; "
                                               "unset, the sequence's own is used)")
        if not levels_ordered(self.black, self.white):
            raise bad("black/white", (self.black, self.white), "black must be less than white, e.g. 0 and 1")
        if self.transfer not in ("auto",) + TRANSFERS:
            raise bad("transfer", self.transfer, f"use one of auto, {', '.join(TRANSFERS)}")
        if not (math.isfinite(self.gamma) and self.gamma > 0):
            raise bad("gamma", self.gamma, "use a positive exponent such as 2.2")
        if self.first_frame < 0:
            raise bad("first_frame", self.first_frame, "use 0 or a positive number")
        if self.even_size not in EVEN_SIZE_MODES:
            raise bad("even_size", self.even_size, f"use one of {', '.join(EVEN_SIZE_MODES)}")

    def curve(self) -> str:
        """The curve the writers apply: :attr:`transfer`, with ``auto`` (no capture to ask) as sRGB."""
        return "srgb" if self.transfer == "auto" else self.transfer

    def white_or(self, estimate: float | None = None) -> float:
        """The white point outputs and the app use — the one "unset" rule: :attr:`white` when set, else
        the sequence's ``estimate`` (:func:`spikeview.pipeline.prepare_sequence`), else 1."""
        if self.white is not None:
            return float(self.white)
        return float(estimate) if estimate else 1.0


def tomlable(value: Any, name: str = "params") -> Any:
    """``value`` converted to what TOML can store (numpy scalars to Python, tuples to lists, ``None`` dropped).

    Raises:
        ParameterError: for a value TOML cannot hold (an array, an object…), naming its key.
    """
    if isinstance(value, Config):
        value = value.to_dict()
    if isinstance(value, dict):
        return {str(k): tomlable(v, f"{name}.{k}") for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [tomlable(v, f"{name}[{i}]") for i, v in enumerate(value) if v is not None]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            # TOML can store nan/inf, but a reproduction recipe with nan in it is a bug upstream
            raise ParameterError(f"metadata '{name}' is {value}; pass a finite number.")
        return value
    raise ParameterError(
        f"metadata '{name}' has type {type(value).__name__}, which a settings file cannot hold; "
        "pass numbers, strings, booleans, lists or tables of them."
    )


@dataclasses.dataclass
class ExportMetadata(Config):
    """What produced the frames; written into every output so a frame can be reproduced.

    Attributes:
        source: the spike file (or a description such as ``"simulator: bars"``).
        method: reconstruction method name (``"tfp"``, ``"tfi"``, ``"guided"``…).
        tick_rate: readouts per second of the source (Hz), 20 kHz by default.
        window: tick range ``[a, b)`` of the **first** output frame's window.
        centre_tick: centre tick of the first output frame.
        step_ticks: ticks between consecutive output frames. When given, frame ``i`` records
            window ``[a + i·step, b + i·step)`` and centre ``centre_tick + i·step``; when not,
            later frames record only what is passed to ``Exporter.write``.
        params: the full parameter set (plain dict). A :class:`~spikeview.config.Config` or TOML
            text passed here is converted to a dict.
        plan: what the guided plan decided for the first frame, one line per choice where it matters
            for reading the pixels (``tiles``: the per-tile map; ``precision``); empty for other methods.
    """

    source: str = ""
    method: str = ""
    tick_rate: float = 20_000.0
    window: tuple[int, int] | None = None
    centre_tick: int | None = None
    step_ticks: int | None = None
    params: dict[str, Any] = dataclasses.field(default_factory=dict)
    plan: dict[str, str] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.source, Path):
            self.source = str(self.source)
        params: Any = self.params
        if isinstance(params, Config):
            params = params.to_dict()
        elif isinstance(params, str):
            try:
                params = tomllib.loads(params)
            except tomllib.TOMLDecodeError as e:
                raise ParameterError(
                    f"metadata 'params' is not valid TOML text ({e}); pass a dict or a Config."
                ) from None
        elif params is None:
            params = {}
        if not isinstance(params, dict):
            raise ParameterError(
                f"metadata 'params' has type {type(params).__name__}; pass a dict, a Config or TOML text."
            )
        self.params = tomlable(params)
        if not (math.isfinite(self.tick_rate) and self.tick_rate > 0):
            raise ParameterError(f"metadata 'tick_rate' = {self.tick_rate!r}; pass the positive readout rate in Hz.")
        if self.window is not None:
            a, b = (int(v) for v in self.window)
            if not a < b:
                raise ParameterError(f"metadata 'window' = {self.window!r} is empty; pass ticks [a, b) with a < b.")
            self.window = (a, b)
            if self.centre_tick is not None and not a <= self.centre_tick < b:
                raise ParameterError(
                    f"metadata 'centre_tick' = {self.centre_tick} lies outside the window [{a}, {b}); "
                    "pass the centre of the first frame's window."
                )
        if self.step_ticks is not None and self.step_ticks <= 0:
            raise ParameterError(f"metadata 'step_ticks' = {self.step_ticks}; pass a positive tick step.")

    def frame_ticks(self, index: int) -> tuple[tuple[int, int] | None, int | None]:
        """Window ``[a, b)`` and centre tick of output frame ``index``, where known (else ``None``)."""
        if index == 0:
            return self.window, self.centre_tick
        if self.step_ticks is None:
            return None, None
        shift = index * self.step_ticks
        window = None if self.window is None else (self.window[0] + shift, self.window[1] + shift)
        centre = None if self.centre_tick is None else self.centre_tick + shift
        return window, centre
