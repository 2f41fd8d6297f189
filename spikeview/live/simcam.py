"""A simulated live camera: a simulated scene or a spike file, played at the camera's pace.

:class:`SimCamera` is a :class:`~spikeview.live.source.LiveSource` like the USB camera (ring buffer,
status, recording, ``latest``), fed by

* a :class:`~spikeview.sim.simulator.SpikeSimulator` (:meth:`SimCamera.from_scene`,
  :meth:`SimCamera.demo`): ticks are simulated as they are streamed, until the scene ends;
* any :class:`~spikeview.io.source.SpikeSource` (a file, a capture in memory): its ticks
  ``0, 1, …`` in order, looping at the end unless ``loop=False``.

**Pacing.** Frames ``[k, k + m)`` are handed out when the wall clock reaches
``(k + m) · slowdown / tick_rate`` seconds after the start, as a camera delivers them once they
are read out: ``slowdown=1`` is real time, ``10`` ten times slower, ``0`` as fast as possible.
When producing the frames takes longer than that (the simulator runs far below 20 kHz on a
laptop at any useful size), the camera simply runs slower; :attr:`SimCamera.speed` and the
status message say how fast it really goes.

Frames come in display orientation (no flips, the source's CFA); ROI/decimation/frame step work
as for the USB camera (:class:`~spikeview.live.decode.FrameShaper`), in display coordinates.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from spikeview.errors import ParameterError
from spikeview.io.source import SpikeSource
from spikeview.live.decode import FrameShaper
from spikeview.live.source import DEFAULT_RING_MB, LiveSource, LiveStatus, StatusCallback, StreamEnded

#: stream time covered by one default chunk (s of camera time): the display updates this often
_CHUNK_S = 0.02
#: bound on the unpacked frames of one chunk (bytes)
_CHUNK_BYTES = 16 << 20


class SimCamera(LiveSource):
    """A simulated camera (see the module docstring).

    Args:
        producer: a :class:`~spikeview.io.source.SpikeSource` to replay, or a
            :class:`~spikeview.sim.simulator.SpikeSimulator` to run.
        slowdown: ``1`` real time, ``k`` k times slower, ``0`` as fast as possible.
        chunk_ticks: ticks produced per step (default: 20 ms of camera time, at most 16 MiB).
        loop: replay a source from its start again at its end (sources only).
        roi, decimate, frame_step: host-side reduction (:class:`~spikeview.live.decode.FrameShaper`),
            in display coordinates.
        ring_mb, record_queue_mb: buffer sizes (see :class:`~spikeview.live.source.LiveSource`).
        label: name for people.
        close_producer: close the source/simulator when the camera is closed.
        on_status: status callback.
    """

    def __init__(self, producer: Any, *, slowdown: float = 1.0, chunk_ticks: int | None = None, loop: bool = True,
                 roi: Sequence[int] | None = None, decimate: int = 1, frame_step: int = 1,
                 ring_mb: float = DEFAULT_RING_MB, record_queue_mb: float = 2048.0, label: str | None = None,
                 close_producer: bool = False, on_status: StatusCallback | None = None):
        from spikeview.sim.simulator import SpikeSimulator

        if isinstance(producer, SpikeSimulator):
            self._sim: SpikeSimulator | None = producer
            self._src: SpikeSource | None = None
            height, width = producer.height, producer.width
            cfa, rate = producer.config.cfa_or_none, producer.config.tick_rate
            kind = "simulated scene"
        elif isinstance(producer, SpikeSource):
            self._sim, self._src = None, producer
            if producer.n_frames < 1:
                raise ParameterError("The spike source to replay holds no frames; pick a capture with at least one tick.")
            height, width, cfa, rate = producer.height, producer.width, producer.cfa, producer.tick_rate
            kind = "replay"
        else:
            raise ParameterError(f"SimCamera plays a SpikeSource or a SpikeSimulator, got {type(producer).__name__}; "
                                 f"open the file with spikeview.io.open_source first.")
        if not (slowdown >= 0 and np.isfinite(slowdown)):
            raise ParameterError(f"slowdown must be ≥ 0 (1 = real time, 0 = as fast as possible), got {slowdown}.")
        self.slowdown = float(slowdown)
        self.loop = bool(loop)
        self.shaper = FrameShaper(height, width, roi=roi, decimate=decimate, frame_step=frame_step, colour=cfa is not None)
        if chunk_ticks is None:
            chunk_ticks = 1024 if self.slowdown == 0 else round(_CHUNK_S * rate / self.slowdown)
            chunk_ticks = min(chunk_ticks, _CHUNK_BYTES // (height * width))
        self.chunk_ticks = max(1, int(chunk_ticks))
        self.input_rate = float(rate)
        self._close_producer = bool(close_producer)
        self._k = 0  # input ticks produced
        self._t0 = 0.0
        self._speed = 0.0
        self._speed_mark = (0.0, 0)
        extra = {"kind": kind, "slowdown": self.slowdown, **self.shaper.settings()}
        super().__init__(width=self.shaper.out_width, height=self.shaper.out_height, cfa=cfa,
                         tick_rate=rate / self.shaper.frame_step, label=label or f"simulated camera ({kind})",
                         ring_mb=ring_mb, record_queue_mb=record_queue_mb, extra=extra, on_status=on_status)

    # ------------------------------------------------------------------------------ constructors
    @classmethod
    def from_scene(cls, scene: Any, config: Any = None, **kwargs: Any) -> "SimCamera":
        """A camera that simulates ``scene`` (a :class:`~spikeview.sim.scenes.Scene` or a path) with ``config``."""
        from spikeview.sim.config import SimConfig
        from spikeview.sim.simulator import SpikeSimulator

        sim = SpikeSimulator(scene, config if config is not None else SimConfig())
        kwargs.setdefault("close_producer", True)
        return cls(sim, **kwargs)

    @classmethod
    def demo(cls, size: int = 128, seed: int = 0, **kwargs: Any) -> "SimCamera":
        """The demo scene (:func:`~spikeview.sim.demo.demo_scene`: pan and a colour fan, RGGB) as a live camera."""
        from spikeview.sim.config import SimConfig
        from spikeview.sim.demo import demo_scene

        kwargs.setdefault("label", f"simulated camera (demo scene {size}×{size})")
        return cls.from_scene(demo_scene(size, seed), SimConfig(n_ticks=1, seed=seed), **kwargs)

    # ------------------------------------------------------------------------------ producing
    @property
    def speed(self) -> float:
        """Camera time streamed per wall-clock second over the last second or so (1 = real time)."""
        return self._speed

    def _open(self) -> None:
        self._t0 = time.perf_counter()
        self._speed_mark = (self._t0, 0)

    def _produce(self, m: int) -> np.ndarray:
        if self._sim is not None:
            try:
                self._sim.check_ticks(self._sim.tick + m)
            except ParameterError:
                raise StreamEnded() from None
            return self._sim.run(m)
        src = self._src
        assert src is not None
        n = src.n_frames
        a = self._k % n if self.loop else self._k
        if not self.loop:
            if a >= n:
                raise StreamEnded()
            return src.read(a, min(a + m, n))
        parts = []
        while m > 0:
            b = min(a + m, n)
            parts.append(src.read(a, b))
            m -= b - a
            a = 0
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def _next(self) -> np.ndarray:
        frames = self._produce(self.chunk_ticks)
        m = frames.shape[0]
        self._k += m
        now = time.perf_counter()
        if self.slowdown > 0:
            due = self._t0 + self._k * self.slowdown / self.input_rate
            if due > now:
                self._stop.wait(due - now)
                now = time.perf_counter()
        t, k0 = self._speed_mark
        if now - t >= 0.5:
            self._speed = (self._k - k0) / self.input_rate / (now - t)
            self._speed_mark = (now, self._k)
            behind = self.slowdown > 0 and self._speed * self.slowdown < 0.9
            note = f" at {self._speed:.3g}× real time" + (" (the producer is slower than the camera)" if behind else "")
            self._set_status(LiveStatus.RUNNING, f"{self.label}: streaming{note}.")
        elif self._status is not LiveStatus.RUNNING or self._k == m:
            self._set_status(LiveStatus.RUNNING, f"{self.label}: streaming.")
        keep = self.shaper.select(m)
        if keep.size != m:
            frames = frames[keep]
        return self.shaper.shape(frames)

    def _close_device(self) -> None:
        if self._close_producer:
            if self._sim is not None:
                self._sim.close()
            elif self._src is not None:
                self._src.close()
