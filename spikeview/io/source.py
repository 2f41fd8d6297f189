"""The one interface over every spike stream: files, the simulator, cameras.

A :class:`SpikeSource` knows its geometry, tick rate and CFA, and answers "give me ticks
``[a, b)``" as a ``(b - a, H, W)`` uint8 array of 0/1 values, rows top-to-bottom **after** the
orientation flips of its :class:`StreamInfo` (so ``info.cfa`` names the top-left 2×2 of what
``read`` returns). Ticks are readout indices (50 µs each at 20 kHz), counted from the first complete
frame of the stream.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import ParameterError

DEFAULT_TICK_RATE = 20_000.0
#: tick rates accepted (readouts per second): spike cameras run at 20–40 kHz; slower or faster
#: rates are allowed for simulations and emulated sensors, but not absurd ones (durations overflow)
TICK_RATE_RANGE = (1.0, 1e9)


def check_tick_rate(tick_rate: object) -> float:
    """Validate a tick rate (readouts per second) and return it as a float."""
    try:
        value = float(tick_rate)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        value = float("nan")
    lo, hi = TICK_RATE_RANGE
    if not (np.isfinite(value) and lo <= value <= hi):
        raise ParameterError(f"tick_rate (--tick-rate) must be a number of readouts per second between {lo:g} and {hi:g}, got "
                             f"{tick_rate!r}; the cameras run at 20000.")
    return value

#: format names, as used by ``--format`` and in sidecars
FORMATS = ("plain", "raw400", "raw1m", "npz")


@dataclass
class StreamInfo:
    """What is known about a spike stream.

    Attributes:
        width, height: decoded frame size in pixels (after stripping raw tags).
        n_frames: number of complete frames (ticks) available.
        tick_rate: readouts per second (Hz); 20 kHz by default.
        cfa: top-left 2×2 after flips (``"RGGB"`` …) or ``None`` for monochrome.
        format: one of :data:`FORMATS`, or ``"memory"``/``"sim"``/``"camera"`` for non-file sources.
        flip_vertical, flip_horizontal: flips applied after decoding (the ecosystem stores rows
            upside down, so plain files default to ``flip_vertical=True``).
        path: the file, when there is one.
        warnings: things the reader noticed and the user should hear about (trailing partial
            frame, skipped corrupt blocks…), one sentence each.
        extra: free-form metadata carried from the sidecar (simulator parameters, drop counters).
        camera: the camera profile whose dark, flat and colour corrections apply to this stream
            (:class:`spikeview.classical.calibration.CameraProfile`, set by :func:`spikeview.classical.calibration.attach`), or ``None``.
        likely_size: ``(width, height)`` the firing rates point to when the given width shears the rows
            (set by :func:`spikeview.io.geometry.rate_warnings` with its warning), else ``None``.
    """

    width: int
    height: int
    n_frames: int
    tick_rate: float = DEFAULT_TICK_RATE
    cfa: str | None = None
    format: str = "memory"
    flip_vertical: bool = False
    flip_horizontal: bool = False
    path: Path | None = None
    warnings: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    camera: Any = None
    likely_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        self.cfa = parse_cfa(self.cfa)
        if self.path is not None:
            self.path = Path(self.path)

    @property
    def duration_s(self) -> float:
        """Stream length in seconds (``n_frames / tick_rate``)."""
        return self.n_frames / self.tick_rate

    def ticks_to_us(self, ticks: float) -> float:
        """Convert a tick count to microseconds at this stream's tick rate."""
        return ticks * 1e6 / self.tick_rate

    def replace(self, **changes: Any) -> "StreamInfo":
        return replace(self, **changes)


class SpikeSource(ABC):
    """Random access to a binary spike stream; see the module docstring for conventions.

    Subclasses implement :meth:`_read` (and may override :meth:`count` with something faster).
    Sources are context managers; :meth:`close` releases files or devices.
    """

    info: StreamInfo

    # --- geometry -------------------------------------------------------------------------
    @property
    def width(self) -> int:
        return self.info.width

    @property
    def height(self) -> int:
        return self.info.height

    @property
    def n_frames(self) -> int:
        return self.info.n_frames

    @property
    def tick_rate(self) -> float:
        return self.info.tick_rate

    @property
    def cfa(self) -> str | None:
        return self.info.cfa

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n_frames, height, width)``."""
        return (self.info.n_frames, self.info.height, self.info.width)

    def __len__(self) -> int:
        return self.info.n_frames

    # --- access ---------------------------------------------------------------------------
    def check_range(self, a: int, b: int) -> tuple[int, int]:
        """Validate a tick range ``[a, b)``; raises :class:`ParameterError` with the valid range."""
        a, b = int(a), int(b)
        n = self.info.n_frames
        if a < 0 or b > n or a > b:
            name = self.info.path.name if self.info.path else "the stream"
            raise ParameterError(
                f"Tick range [{a}, {b}) is outside {name}, which holds ticks [0, {n}): choose a range inside it."
            )
        return a, b

    def read(self, a: int, b: int) -> np.ndarray:
        """Spikes of ticks ``[a, b)`` as a ``(b - a, H, W)`` uint8 array of 0/1, flips applied."""
        a, b = self.check_range(a, b)
        if a == b:
            return np.zeros((0, self.height, self.width), dtype=np.uint8)
        return self._read(a, b)

    @abstractmethod
    def _read(self, a: int, b: int) -> np.ndarray:
        """Implementation of :meth:`read` for a validated, non-empty range."""

    def count(self, a: int, b: int) -> np.ndarray:
        """Spike count per pixel over ticks ``[a, b)``: ``(H, W)`` uint16, flips applied."""
        a, b = self.check_range(a, b)
        if a == b:
            return np.zeros((self.height, self.width), dtype=np.uint16)
        return self._read(a, b).sum(axis=0, dtype=np.uint16)

    def count_windows(self, a: int, b: int, window: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """Spike counts of consecutive non-overlapping windows ``[a + i·window, a + (i+1)·window)``.

        Only windows that lie entirely inside ``[a, b)`` are counted (``(b - a) // window`` of
        them); trailing ticks that do not fill a window are left out.

        Args:
            a, b: tick range.
            window: ticks per window (≥ 1).
            out: optional C-contiguous ``(n_windows, H, W)`` uint16 array to fill (file readers
                reuse it to avoid allocating fresh memory on every call).

        Returns:
            ``(n_windows, H, W)`` uint16 counts, flips applied.
        """
        a, b = self.check_range(a, b)
        window = int(window)
        if window < 1:
            raise ParameterError(f"window must be at least 1 tick, got {window}; pass a positive window length.")
        n = (b - a) // window
        if out is None:
            out = np.empty((n, self.height, self.width), dtype=np.uint16)
        elif out.shape != (n, self.height, self.width):
            raise ParameterError(f"out has shape {out.shape}, expected {(n, self.height, self.width)}; allocate it to match.")
        for i in range(n):
            out[i] = self.count(a + i * window, a + (i + 1) * window)
        return out

    def close(self) -> None:
        """Release files/devices. Safe to call twice."""

    def __enter__(self) -> "SpikeSource":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ArraySource(SpikeSource):
    """A spike stream held in memory as a ``(T, H, W)`` array (already in display orientation)."""

    def __init__(self, spikes: np.ndarray, *, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
                 info: StreamInfo | None = None):
        spikes = np.asarray(spikes)
        if spikes.ndim != 3:
            raise ParameterError(f"Spike array must have shape (T, H, W), got shape {spikes.shape}: reshape it first.")
        if spikes.dtype != np.uint8:
            spikes = (spikes != 0).astype(np.uint8)
        self._spikes = spikes
        t, h, w = spikes.shape
        self.info = info if info is not None else StreamInfo(width=w, height=h, n_frames=t, tick_rate=tick_rate, cfa=cfa)

    def _read(self, a: int, b: int) -> np.ndarray:
        return np.array(self._spikes[a:b], dtype=np.uint8, copy=True)
