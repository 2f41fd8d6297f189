"""Integrate-and-fire simulation of a (chromatic) spike camera looking at a :class:`Scene`.

Pipeline per tick ``t`` (``1 / tick_rate`` seconds; the scene is sampled at
``start_s + t / tick_rate``):

1. the scene's linear RGB frame (a blend of two key frames, see :mod:`spikeview.sim.scenes`);
2. CFA sampling: each photosite keeps its channel (monochrome: Rec. 709 luminance);
3. integrate-and-fire with the sensor model of :mod:`spikeview.sim.config` (spectral gains,
   fixed-pattern and temporal noise), one spike at most per photosite and tick.

:class:`SpikeSimulator` streams ticks in chunks and keeps only the integrator state, so long
simulations do not hold the stream in memory (:func:`spikeview.sim.write.simulate_to_file` uses
it). :func:`simulate` keeps a short run in memory as a :class:`SimulatedCapture` (bit-packed,
1 bit per photosite and tick), a :class:`~spikeview.io.source.SpikeSource` with ground truth.

Determinism: every random number is a function of (seed, stream, tick, pixel) — fixed patterns
come from ``numpy.random.default_rng([seed, stream])`` and temporal noise from a counter-based
hash — so the same seed and settings give identical bytes whatever the chunk size or thread
count.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spikeview.cfa import channel_map
from spikeview.errors import Cancelled, ParameterError
from spikeview.io.source import SpikeSource, StreamInfo
from spikeview.sim.config import ELEMENTARY_CHARGE, LUMINANCE_WEIGHTS, SimConfig
from spikeview.sim.scenes import Key, ResizedScene, Scene, open_scene

ProgressCallback = Callable[[int, int], None]
CancelCheck = Callable[[], bool]

# streams of numpy.random.default_rng([seed, stream]) for the fixed patterns
_STREAM_DARK, _STREAM_PRNU, _STREAM_CAP, _STREAM_OFFSET, _STREAM_V0, _STREAM_HOT = 1, 2, 3, 4, 5, 6
# streams of the counter-based temporal noise
_STREAM_NOISE, _STREAM_KNUTH = 101, 102
_MASK64 = (1 << 64) - 1
#: frames of at least this many photosites are simulated by several threads (bands of rows; see
#: ``SPIKEVIEW_THREADS``); below it one thread is faster than the hand-over
PARALLEL_MIN_PIXELS = 1 << 18
#: memory budget (bytes) of the key planes of one chunk
CHUNK_PLANE_BYTES = 64 << 20


def _splitmix(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def stream_key(seed: int, stream: int) -> np.uint64:
    """uint64 key of one counter-based random stream of a seed."""
    golden = 0x9E3779B97F4A7C15
    return np.uint64(_splitmix((_splitmix((seed + golden) & _MASK64) + stream * golden) & _MASK64))


# ---------------------------------------------------------------------------------------------
# the sensor's fixed pattern
# ---------------------------------------------------------------------------------------------
@dataclass
class SensorPattern:
    """The per-photosite constants of one simulated sensor (all ``(H, W)``).

    Attributes:
        channel: int8 CFA channel per photosite (0 R, 1 G, 2 B), −1 for monochrome.
        drive: float32 voltage gained per tick at intensity 1, in units of the nominal threshold
            (``rate · spectral gain · PRNU gain``).
        dark: float32 dark charge per tick in threshold units (0 with ``dark_current`` off).
        cap_ratio: float32 nominal / actual capacitance (1 with ``threshold_fpn`` off).
        theta: float32 firing threshold in units of the nominal threshold (1 with
            ``threshold_fpn`` off).
        v0: float64 initial voltage, uniform in ``[0, theta)``.
    """

    channel: np.ndarray
    drive: np.ndarray
    dark: np.ndarray
    cap_ratio: np.ndarray
    theta: np.ndarray
    v0: np.ndarray
    _flat_index: np.ndarray | None = field(default=None, repr=False, compare=False)

    @classmethod
    def build(cls, config: SimConfig, height: int, width: int) -> "SensorPattern":
        """Draw the fixed pattern of ``config`` for an ``height × width`` sensor."""
        shape = (height, width)
        seed = config.seed

        def rng(stream: int) -> np.random.Generator:
            return np.random.default_rng([seed, stream])

        cfa = config.cfa_or_none
        if cfa is None:
            channel = np.full(shape, -1, dtype=np.int8)
            gain = np.ones(shape, dtype=np.float64)
        else:
            channel = channel_map(cfa, height, width)
            gain = np.asarray(config.spectral_gains, dtype=np.float64)[channel]
        if config.prnu:
            gain = gain * np.maximum(rng(_STREAM_PRNU).normal(1.0, config.prnu_std, shape), 0.0)
        drive = (config.rate * gain).astype(np.float32)

        if config.dark_current:
            amps = np.maximum(rng(_STREAM_DARK).normal(config.dark_current_mean_pa, config.dark_current_std_pa, shape), 0.0)
            if config.hot_pixels > 0:  # hot pixels: a stream of their own, every other draw unchanged
                amps = np.where(rng(_STREAM_HOT).random(shape) < config.hot_pixels, amps * config.hot_pixel_factor, amps)
            # pA → electrons per tick → threshold units
            per_pa = 1e-12 / ELEMENTARY_CHARGE / config.tick_rate / config.electrons_per_threshold
            dark = (amps * per_pa).astype(np.float32)
        else:
            dark = np.zeros(shape, dtype=np.float32)

        if config.threshold_fpn:
            cap = rng(_STREAM_CAP).normal(config.capacitance_mean_ff, config.capacitance_std_ff, shape)
            cap = np.maximum(cap, 1e-3 * config.capacitance_mean_ff)
            cap_ratio = (config.capacitance_mean_ff / cap).astype(np.float32)
            offset = rng(_STREAM_OFFSET).normal(config.threshold_offset_mean_v, config.threshold_offset_std_v, shape)
            theta = np.maximum((config.threshold_v + offset) / config.threshold_v, 1e-3).astype(np.float32)
        else:
            cap_ratio = np.ones(shape, dtype=np.float32)
            theta = np.ones(shape, dtype=np.float32)
        v0 = rng(_STREAM_V0).random(shape) * theta.astype(np.float64)
        return cls(channel=channel, drive=drive, dark=dark, cap_ratio=cap_ratio, theta=theta, v0=v0)

    @property
    def shape(self) -> tuple[int, int]:
        return self.channel.shape  # type: ignore[return-value]

    def mosaic(self, frame: np.ndarray) -> np.ndarray:
        """The intensity each photosite sees: ``(H, W)`` float32 from a linear ``(H, W, 3)`` frame."""
        frame = np.ascontiguousarray(frame, dtype=np.float32)
        if self.channel[0, 0] < 0:
            return (frame @ np.asarray(LUMINANCE_WEIGHTS, dtype=np.float32)).astype(np.float32)
        if self._flat_index is None:
            h, w = self.channel.shape
            self._flat_index = np.arange(h * w, dtype=np.intp) * 3 + self.channel.reshape(-1)
        return frame.reshape(-1)[self._flat_index].reshape(self.channel.shape)

    def expected_rate(self, frame: np.ndarray) -> np.ndarray:
        """Mean spikes per tick of each photosite under a constant ``frame``, (H, W) float64.

        ``(drive · I + dark) · cap_ratio / theta`` capped at 1: exact for the fixed pattern, and
        ignoring the reset slowdown (−0.2 % at most) and the saturation of shot noise/jitter.
        """
        charge = self.drive.astype(np.float64) * self.mosaic(frame) + self.dark
        return np.minimum(charge * self.cap_ratio / self.theta, 1.0)


def prepare_scene(scene: Scene | str | Path, config: SimConfig) -> Scene:
    """The scene as the sensor sees it: opened if a path, then cropped/resized per ``config``."""
    if isinstance(scene, (str, Path)):
        scene = open_scene(scene)
    if not isinstance(scene, Scene):
        raise ParameterError(f"Expected a Scene or a path to a scene, got {type(scene).__name__}.")
    size = None
    if config.width is not None or config.height is not None:
        base_h = config.crop[2] if config.crop else scene.height
        base_w = config.crop[3] if config.crop else scene.width
        size = (config.height or base_h, config.width or base_w)
    if config.crop is None and (size is None or size == scene.size):
        return scene
    return ResizedScene(scene, crop=config.crop, size=size)


# ---------------------------------------------------------------------------------------------
# streaming simulator
# ---------------------------------------------------------------------------------------------
class SpikeSimulator:
    """Stateful simulator: call :meth:`run` repeatedly to get consecutive ticks.

    Args:
        scene: the scene (or a path :func:`~spikeview.sim.scenes.open_scene` opens); cropped and
            resized per ``config``.
        config: the settings; ``config.n_ticks`` bounds :meth:`chunks`, not :meth:`run` (a live
            simulated camera may run on while the scene lasts).

    Raises:
        ParameterError: the scene is shorter than ``config.n_ticks`` ticks.
    """

    def __init__(self, scene: Scene | str | Path, config: SimConfig):
        self.config = config
        self.scene = prepare_scene(scene, config)
        self.height, self.width = self.scene.height, self.scene.width
        try:
            self.check_ticks(config.n_ticks)
        except ParameterError:
            if not isinstance(scene, Scene):
                self.scene.close()
            raise
        self.sensor = SensorPattern.build(config, self.height, self.width)
        self.tick = 0
        self._volt = self.sensor.v0.copy()
        self._fired = np.zeros((self.height, self.width), dtype=np.uint8)
        self._planes: OrderedDict[Key, np.ndarray] = OrderedDict()
        self._key_noise = stream_key(config.seed, _STREAM_NOISE)
        self._key_knuth = stream_key(config.seed, _STREAM_KNUTH)
        self._table: np.ndarray | None = None
        self._step: np.ndarray | None = None
        npix = self.height * self.width
        self.chunk_ticks = int(max(1, min(1024, CHUNK_PLANE_BYTES // (4 * npix))))

    # --- time -----------------------------------------------------------------------------
    def time_of(self, tick: int) -> float:
        """Scene time in seconds of a tick: ``start_s + tick / tick_rate``."""
        return self.config.start_s + int(tick) / self.config.tick_rate

    def check_ticks(self, n_ticks: int) -> None:
        """Raise :class:`ParameterError` unless the scene lasts for ticks ``[0, n_ticks)``."""
        d = self.scene.duration_s
        if d is None:
            return
        last = self.time_of(n_ticks - 1)
        if last > d * (1 + 1e-12):
            most = int(math.floor((d - self.config.start_s) * self.config.tick_rate)) + 1
            start = f" from {self.config.start_s:g} s" if self.config.start_s else ""
            raise ParameterError(
                f"The scene lasts {d:g} s but {n_ticks} ticks at {self.config.tick_rate:g} Hz{start} need {last:g} s: "
                f"simulate at most {max(most, 0)} ticks (--ticks {max(most, 0)}, n_ticks in a config), or give a "
                "longer input (for an image folder, more frames or a lower --fps)."
            )

    def gt_at(self, tick: int) -> np.ndarray:
        """The clean linear RGB frame the sensor sees at ``tick``: (H, W, 3) float32 in [0, 1]."""
        return self.scene.frame_at(self.time_of(int(tick)))

    # --- simulation -----------------------------------------------------------------------
    def _plane(self, key: Key) -> np.ndarray:
        plane = self._planes.get(key)
        if plane is None:
            plane = self.sensor.mosaic(self.scene.key_frame(key))
            self._planes[key] = plane
            while len(self._planes) > 4:
                self._planes.popitem(last=False)
        else:
            self._planes.move_to_end(key)
        return plane

    def run(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """Simulate the next ``n`` ticks: ``(n, H, W)`` uint8 of 0/1 (rows top to bottom).

        Args:
            n: number of ticks (≥ 0).
            out: optional C-contiguous ``(n, H, W)`` uint8 array to fill and return.
        """
        from spikeview.sim import _kernels

        n = int(n)
        if n < 0:
            raise ParameterError(f"Cannot simulate {n} ticks: give a number ≥ 0.")
        self.check_ticks(self.tick + n)
        if out is None:
            out = np.empty((n, self.height, self.width), dtype=np.uint8)
        elif out.shape != (n, self.height, self.width) or out.dtype != np.uint8 or not out.flags.c_contiguous:
            raise ParameterError(f"out must be a C-contiguous uint8 array of shape {(n, self.height, self.width)}.")
        if self._table is None:
            self._table, self._step = _kernels.normal_table(12)
        cfg = self.config
        threads = _kernels.default_threads() if self.height * self.width >= PARALLEL_MIN_PIXELS else 1
        s = self.sensor
        jitter = cfg.jitter_std_v / cfg.threshold_v if cfg.threshold_jitter else 0.0
        reset = cfg.reset_factor if cfg.reset_slowdown else 1.0
        for a in range(0, n, self.chunk_ticks):
            m = min(self.chunk_ticks, n - a)
            index: dict[Key, int] = {}
            ia = np.empty(m, dtype=np.int64)
            ib = np.empty(m, dtype=np.int64)
            wts = np.empty(m, dtype=np.float64)
            for k in range(m):
                ka, kb, w = self.scene.key_at(self.time_of(self.tick + k))
                if w == 0.0:
                    kb = ka
                ia[k] = index.setdefault(ka, len(index))
                ib[k] = index.setdefault(kb, len(index))
                wts[k] = w
            planes = np.stack([self._plane(key) for key in index])
            _kernels.run_rows(_kernels.integrate_fire, self.height, threads, planes, ia, ib, wts, self.tick, s.drive,
                              s.dark, s.cap_ratio, s.theta, self._volt, self._fired, out[a:a + m], self._key_noise,
                              self._key_knuth, float(cfg.electrons_per_threshold), bool(cfg.shot_noise), float(jitter),
                              float(reset), self._table, self._step)
            self.tick += m
        return out

    def chunks(self, chunk_ticks: int | None = None, progress: ProgressCallback | None = None,
               cancel: CancelCheck | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_tick, spikes)`` chunks until ``config.n_ticks`` ticks are done.

        Args:
            chunk_ticks: ticks per chunk (default: about 64 MiB of key planes, at most 1024).
            progress: called as ``progress(done_ticks, total_ticks)`` after each chunk.
            cancel: polled before each chunk; when it returns True, :class:`Cancelled` is raised.
        """
        total = self.config.n_ticks
        step = int(chunk_ticks or self.chunk_ticks)
        while self.tick < total:
            if cancel is not None and cancel():
                raise Cancelled(f"Simulation cancelled at tick {self.tick} of {total}.")
            a = self.tick
            spikes = self.run(min(step, total - a))
            yield a, spikes
            if progress is not None:
                progress(self.tick, total)

    def close(self) -> None:
        """Close the scene."""
        self.scene.close()


# ---------------------------------------------------------------------------------------------
# in-memory capture
# ---------------------------------------------------------------------------------------------
class SimulatedCapture(SpikeSource):
    """A simulated spike stream held in memory (bit-packed), with its ground truth.

    ``read(a, b)`` returns ``(b − a, H, W)`` uint8 in display orientation (no flips: ``info.cfa``
    is ``config.cfa``). Ground truth is the scene's clean linear RGB, *without* spectral gains or
    noise: :meth:`gt_at` renders it for any tick, and :attr:`gt_ticks` lists the ticks a file
    written with the same settings stores (every ``config.gt_every`` ticks).

    Attributes:
        config: the :class:`SimConfig` that made the stream.
        scene: the (cropped/resized) scene; closed by :meth:`close`.
        sensor: the :class:`SensorPattern` that was drawn.
    """

    def __init__(self, packed: np.ndarray, simulator: SpikeSimulator):
        self._packed = packed
        self.config = simulator.config
        self.scene = simulator.scene
        self.sensor = simulator.sensor
        self._sim = simulator
        self.info = StreamInfo(
            width=simulator.width, height=simulator.height, n_frames=packed.shape[0], tick_rate=self.config.tick_rate,
            cfa=self.config.cfa_or_none, format="sim",
            extra={"simulation": self.config.to_dict(), "scene": self.scene.describe()},
        )

    @property
    def gt_ticks(self) -> np.ndarray:
        """(N,) int64 ticks of the stored ground-truth frames: ``0, gt_every, …`` below ``n_frames``."""
        return np.arange(0, self.n_frames, self.config.gt_every, dtype=np.int64)

    def time_of(self, tick: int) -> float:
        """Scene time (seconds) of a tick: ``start_s + tick / tick_rate``."""
        return self._sim.time_of(int(tick))

    def gt_at(self, tick: int) -> np.ndarray:
        """Clean linear RGB the sensor saw at ``tick``: (H, W, 3) float32 in [0, 1].

        Raises:
            ParameterError: ``tick`` outside ``[0, n_frames)``.
        """
        t = int(tick)
        if not 0 <= t < self.n_frames:
            raise ParameterError(f"Tick {t} is outside the simulated stream, which holds ticks [0, {self.n_frames}): choose one inside.")
        return self._sim.gt_at(t)

    def _read(self, a: int, b: int) -> np.ndarray:
        h, w = self.height, self.width
        bits = np.unpackbits(self._packed[a:b], axis=1, count=h * w, bitorder="little")
        return bits.reshape(b - a, h, w)

    def count(self, a: int, b: int) -> np.ndarray:
        a, b = self.check_range(a, b)
        total = np.zeros((self.height, self.width), dtype=np.uint16)
        step = max(1, (16 << 20) // (self.height * self.width))  # unpack ≈ 16 MiB at a time
        for s in range(a, b, step):
            total += self._read(s, min(b, s + step)).sum(axis=0, dtype=np.uint16)
        return total

    @property
    def packed(self) -> np.ndarray:
        """(T, ceil(H·W/8)) uint8: each tick packed LSB-first in reading order, not flipped (read-only view)."""
        view = self._packed.view()
        view.setflags(write=False)
        return view

    def close(self) -> None:
        self.scene.close()


def packed_bytes(config: SimConfig, height: int, width: int) -> int:
    """Bytes an in-memory capture of ``config.n_ticks`` ticks of ``height × width`` takes."""
    return config.n_ticks * ((height * width + 7) // 8)


def simulate(scene: Scene | str | Path, config: SimConfig | None = None, *, progress: ProgressCallback | None = None,
             cancel: CancelCheck | None = None, max_bytes: int = 2 << 30) -> SimulatedCapture:
    """Simulate ``config.n_ticks`` ticks of ``scene`` into memory.

    Args:
        scene: a :class:`Scene`, or a path :func:`~spikeview.sim.scenes.open_scene` opens.
        config: settings (default :class:`SimConfig()`: RGGB, rate 0.6, all noise on).
        progress: ``progress(done_ticks, total_ticks)`` after each chunk.
        cancel: polled between chunks; returning True raises :class:`~spikeview.errors.Cancelled`.
        max_bytes: refuse runs whose packed stream would exceed this (default 2 GiB).

    Returns:
        The :class:`SimulatedCapture`.

    Raises:
        ParameterError: bad settings, a scene shorter than the run, or a run too big for memory
            (use :func:`spikeview.sim.write.simulate_to_file` for those).
    """
    config = config or SimConfig()
    sim = SpikeSimulator(scene, config)
    need = packed_bytes(config, sim.height, sim.width)
    if need > max_bytes:
        sim.close()
        raise ParameterError(
            f"n_ticks={config.n_ticks} at {sim.width}x{sim.height} needs {need / 2**30:.1f} GiB in memory: "
            "simulate to a file with simulate_to_file, or use fewer ticks."
        )
    npix = sim.height * sim.width
    packed = np.empty((config.n_ticks, (npix + 7) // 8), dtype=np.uint8)
    for a, spikes in sim.chunks(progress=progress, cancel=cancel):
        packed[a:a + len(spikes)] = np.packbits(spikes.reshape(len(spikes), npix), axis=1, bitorder="little")
    return SimulatedCapture(packed, sim)
