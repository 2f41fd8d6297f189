"""The live source: an acquisition thread, a ring buffer, a status, and recording.

:class:`LiveSource` is a :class:`~spikeview.io.source.SpikeSource` whose stream grows while it
runs: ``info.n_frames`` counts the frames acquired so far (ticks from the first frame), and
``read(a, b)`` serves what the ring buffer still holds (older ticks raise
:class:`~spikeview.live.ring.RingOverrun`, saying which ticks are still there). The app's panels
therefore work on live data unchanged; the display follows the stream with :meth:`latest`.

Threads:

* the **acquisition thread** (started by :meth:`LiveSource.start`) reads the device, decodes,
  pushes packed frames into the ring and hands the same frames to the recorder, and never waits
  on a reader or on the disk;
* the recorder's **writer thread** (:mod:`spikeview.live.recorder`);
* readers (the GUI's workers) copy from the ring.

**Status.** Nothing a device does raises out of the acquisition thread: every outcome becomes a
:class:`LiveStatus` and a one-sentence :attr:`LiveSource.status_message` that says what to do
(poll them, or pass ``on_status``). When the acquisition ends, for whatever reason, a running
recording is finalised with every complete frame that arrived.

Subclasses (:class:`~spikeview.live.usb.UsbCamera`, :class:`~spikeview.live.simcam.SimCamera`)
implement ``_open``, ``_next`` and ``_close_device``; see :class:`LiveSource`.
"""

from __future__ import annotations

from abc import abstractmethod

import enum
import os
import threading
import time
import weakref
from collections.abc import Callable
from typing import Any

import numpy as np

from spikeview.errors import ParameterError, SpikeviewError
from spikeview.io.source import DEFAULT_TICK_RATE, SpikeSource, StreamInfo
from spikeview.live.decode import unpack_frames
from spikeview.live.recorder import DEFAULT_MAX_QUEUE_BYTES, Recorder, RecordingSummary
from spikeview.live.recorder import stop_all as _stop_all_recordings
from spikeview.live.ring import FrameRing

#: default ring buffer size (MiB): 2,147 frames of 1000×1000, 32,768 of 256×256
DEFAULT_RING_MB = 256
#: how long :meth:`LiveSource.close` waits for the threads by default (s)
DEFAULT_CLOSE_TIMEOUT_S = 30.0


class LiveStatus(str, enum.Enum):
    """Where a live source stands. ``str`` values, so they print and compare as plain words."""

    IDLE = "idle"  #: created, not started
    CONNECTING = "connecting"  #: opening the device
    RUNNING = "running"  #: frames are arriving
    WAITING = "waiting"  #: no data for a while (timeouts), still trying
    ENDED = "ended"  #: the simulated or replayed stream came to its end
    STOPPED = "stopped"  #: closed by the user
    NOT_FOUND = "not_found"  #: no such USB device
    PERMISSION_DENIED = "permission_denied"  #: the OS refused access (udev rule missing)
    NO_BACKEND = "no_backend"  #: pyusb found no libusb
    TIMEOUT = "timeout"  #: gave up after too many timeouts in a row
    PIPE_ERROR = "pipe_error"  #: the endpoint stalled and did not recover
    DISCONNECTED = "disconnected"  #: the device went away
    ERROR = "error"  #: anything else (the message says what)

    @property
    def active(self) -> bool:
        """The acquisition thread is (or is about to be) reading."""
        return self in (LiveStatus.CONNECTING, LiveStatus.RUNNING, LiveStatus.WAITING)

    @property
    def failed(self) -> bool:
        """The acquisition ended on a problem (not by the user or the end of the stream)."""
        return self not in (LiveStatus.IDLE, LiveStatus.CONNECTING, LiveStatus.RUNNING, LiveStatus.WAITING,
                            LiveStatus.ENDED, LiveStatus.STOPPED)


class LiveFailure(Exception):
    """Raised inside the acquisition thread to end it with a status and a message for people."""

    def __init__(self, status: LiveStatus, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


class StreamEnded(Exception):
    """Raised by ``_next`` when a finite stream (replay, simulated scene) has no more frames."""


StatusCallback = Callable[[LiveStatus, str], None]

_LIVE: "weakref.WeakSet[LiveSource]" = weakref.WeakSet()


class LiveSource(SpikeSource):
    """Base of live sources (see the module docstring).

    Args:
        width, height: output frame size (after ROI/decimation).
        flip_vertical, flip_horizontal: flips from the stored orientation of the packed frames
            to display orientation (see :mod:`spikeview.live.decode`).
        cfa: CFA of the frames as read (after the flips), or ``None``.
        tick_rate: frames per second of the output stream (Hz).
        label: a short name for people ("USB camera 1234:5678", "simulated camera").
        ring_mb: ring buffer size in MiB (at least 2 frames are held).
        record_queue_mb: bound of the recorder's queue in MiB.
        extra: metadata for ``info.extra`` (and the recording's sidecar).
        on_status: called as ``on_status(status, message)`` from the acquisition thread when the
            status changes (keep it short; GUIs should rather poll).

    Subclasses implement:

    * ``_open()``: open the device; raise :class:`LiveFailure` when it cannot be;
    * ``_next()``: the next packed frames ``(n, frame_bytes)`` (stored orientation; ``n`` may be
      0), raising :class:`LiveFailure` to end with a problem or :class:`StreamEnded`;
    * ``_close_device()``: release the device (errors there are ignored);
    * ``device_counters()``: device-side counters (dropped frames, skipped bytes …).
    """

    def __init__(self, *, width: int, height: int, flip_vertical: bool = False, flip_horizontal: bool = False,
                 cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE, label: str = "live camera",
                 ring_mb: float = DEFAULT_RING_MB, record_queue_mb: float = DEFAULT_MAX_QUEUE_BYTES / 2**20,
                 extra: dict[str, Any] | None = None, on_status: StatusCallback | None = None):
        self.info = StreamInfo(width=int(width), height=int(height), n_frames=0, tick_rate=tick_rate, cfa=cfa,
                               format="camera", flip_vertical=bool(flip_vertical), flip_horizontal=bool(flip_horizontal),
                               extra={"live": dict(extra or {}, label=label)})
        if (self.info.width * self.info.height) % 8:
            raise ParameterError(f"a live {self.info.width}x{self.info.height} frame is not a whole number of bytes; "
                                 f"choose a size whose pixel count is a multiple of 8.")
        self.label = label
        self.frame_bytes = self.info.width * self.info.height // 8
        if not (ring_mb > 0):
            raise ParameterError(f"ring_mb must be positive, got {ring_mb}; give the ring buffer some memory (e.g. 256).")
        capacity = max(2, int(ring_mb * 2**20) // self.frame_bytes)
        self.ring = FrameRing(self.frame_bytes, capacity)
        self.record_queue_bytes = int(record_queue_mb * 2**20)
        self._on_status = on_status
        self._status = LiveStatus.IDLE
        self._message = f"{label}: not started."
        self._status_lock = threading.Lock()
        self._ingest_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._recorder: Recorder | None = None
        self._rec_base: dict[str, int] = {}
        self._rec_first_tick = 0
        self._last_summary: RecordingSummary | None = None
        self._rate = (0.0, 0.0)  # bytes/s, frames/s over the last ~0.5 s
        self._rate_mark = (time.perf_counter(), 0, 0)
        self._closed = False
        _LIVE.add(self)

    # ================================================================================ subclass API
    def _open(self) -> None:
        """Open the device (raise :class:`LiveFailure` on failure)."""

    @abstractmethod
    def _next(self) -> np.ndarray:
        """Next packed frames ``(n, frame_bytes)``; may block up to a device timeout (every camera implements it)."""

    def _close_device(self) -> None:
        """Release the device."""

    def _finish_stream(self) -> None:
        """After the last read: account bytes still buffered in decoders."""

    def device_counters(self) -> dict[str, int]:
        """Device-side counters: ``dropped_frames``, ``skipped_bytes``, ``resyncs``, ``timeouts``, ``pipe_errors``, ``bytes_in``."""
        return {"dropped_frames": 0, "skipped_bytes": 0, "resyncs": 0, "timeouts": 0, "pipe_errors": 0, "bytes_in": 0}

    # ================================================================================ status
    @property
    def status(self) -> LiveStatus:
        return self._status

    @property
    def status_message(self) -> str:
        """One sentence for people about the current status (with the fix, for problems)."""
        return self._message

    def _set_status(self, status: LiveStatus, message: str) -> None:
        with self._status_lock:
            changed = (status, message) != (self._status, self._message)
            self._status, self._message = status, message
        if changed and self._on_status is not None:
            try:
                self._on_status(status, message)
            except Exception:  # a broken callback must not end the acquisition
                pass

    @property
    def running(self) -> bool:
        """The acquisition thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    # ================================================================================ lifecycle
    def start(self) -> "LiveSource":
        """Start the acquisition thread (once); returns ``self``."""
        if self._closed or self._stop.is_set():
            raise ParameterError(f"{self.label} was stopped; open the camera again to restart it.")
        if self._thread is None:
            self._set_status(LiveStatus.CONNECTING, f"{self.label}: connecting…")
            self._thread = threading.Thread(target=self._run, name=f"spikeview-live {self.label}", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float | None = DEFAULT_CLOSE_TIMEOUT_S) -> bool:
        """Stop acquiring (finalising a running recording); returns whether the threads ended in time."""
        self._stop.set()
        ok = True
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)
            ok = not t.is_alive()
        if t is None:
            self.stop_recording("the camera was closed", timeout=timeout)
            try:
                self._close_device()
            except Exception:
                pass
            if self._status in (LiveStatus.IDLE, LiveStatus.CONNECTING):
                self._set_status(LiveStatus.STOPPED, f"{self.label}: closed.")
        rec = self._recorder
        if rec is not None:  # the thread did not end in time: still make sure the file is finalised
            rec.stop("the camera was closed", timeout=0)
        return ok

    def close(self, timeout: float | None = DEFAULT_CLOSE_TIMEOUT_S) -> None:
        """Stop acquiring, finalise any recording and release the device. Safe to call twice."""
        if self._closed:
            return
        self.stop(timeout)
        self._closed = True
        _LIVE.discard(self)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the acquisition thread has ended (device gone, stream ended, stopped)."""
        t = self._thread
        if t is None:
            return True
        t.join(timeout)
        return not t.is_alive()

    def wait_frames(self, n: int, timeout: float) -> bool:
        """Wait until at least ``n`` frames were acquired or the acquisition ended; returns whether ``n`` arrived."""
        deadline = time.monotonic() + timeout
        while self.info.n_frames < n:
            if not self.running and self._thread is not None:
                return self.info.n_frames >= n
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    # ================================================================================ acquisition thread
    def _run(self) -> None:
        final: tuple[LiveStatus, str] | None = None
        try:
            self._open()
            self._set_status(LiveStatus.RUNNING, f"{self.label}: connected, waiting for frames.")
            while not self._stop.is_set():
                frames = self._next()
                if frames.shape[0]:
                    self._ingest(frames)
        except LiveFailure as e:
            final = (e.status, e.message)
        except StreamEnded:
            final = (LiveStatus.ENDED, f"{self.label}: the stream ended after {self.info.n_frames} frames.")
        except SpikeviewError as e:  # e.g. the replayed file became unreadable: already a sentence for people
            final = (LiveStatus.ERROR, f"{self.label}: {e}")
        except Exception as e:  # a bug: report it as a status, never crash the app
            final = (LiveStatus.ERROR, f"{self.label}: unexpected {type(e).__name__} ({e}); this is a bug, please report "
                                       f"it with the terminal output.")
        finally:
            try:
                self._close_device()
            except Exception:
                pass
            try:
                self._finish_stream()
            except Exception:
                pass
            if final is None:
                final = (LiveStatus.STOPPED, f"{self.label}: stopped after {self.info.n_frames} frames.")
            reason = final[1]
            self.stop_recording(reason)
            self._set_status(*final)

    def _ingest(self, frames: np.ndarray) -> None:
        with self._ingest_lock:
            total = self.ring.push(frames)
            self.info.n_frames = total
            rec = self._recorder
            if rec is not None:
                rec.submit(frames)
        now = time.perf_counter()
        t0, b0, f0 = self._rate_mark
        if now - t0 >= 0.5:
            b = self.device_counters()["bytes_in"] or total * self.frame_bytes
            self._rate = ((b - b0) / (now - t0), (total - f0) / (now - t0))
            self._rate_mark = (now, b, total)

    @property
    def rates(self) -> tuple[float, float]:
        """``(bytes per second in, frames per second out)`` over the last half second or so."""
        return self._rate

    # ================================================================================ reading
    def _read(self, a: int, b: int) -> np.ndarray:
        packed = self.ring.get(a, b)
        frames = unpack_frames(packed, self.info.height, self.info.width)
        if self.info.flip_vertical:
            frames = frames[:, ::-1]
        if self.info.flip_horizontal:
            frames = frames[:, :, ::-1]
        return np.ascontiguousarray(frames)

    def latest(self, window: int) -> np.ndarray:
        """The most recent ``window`` frames ``(n, H, W)`` uint8 0/1, flips applied (fewer at the start)."""
        return self.latest_window(window)[1]

    def latest_window(self, window: int) -> tuple[int, np.ndarray]:
        """``(first_tick, frames)`` of the most recent ``window`` frames; never falls behind (see :mod:`~spikeview.live.ring`)."""
        a, packed = self.ring.latest(window)
        frames = unpack_frames(packed, self.info.height, self.info.width)
        if self.info.flip_vertical:
            frames = frames[:, ::-1]
        if self.info.flip_horizontal:
            frames = frames[:, :, ::-1]
        return a, np.ascontiguousarray(frames)

    @property
    def oldest_tick(self) -> int:
        """The oldest tick :meth:`read` can still serve."""
        return self.ring.oldest

    # ================================================================================ recording
    @property
    def recorder(self) -> Recorder | None:
        """The running recording, if any."""
        return self._recorder

    @property
    def recording(self) -> bool:
        return self._recorder is not None

    @property
    def last_recording(self) -> RecordingSummary | None:
        """Summary of the last recording that was stopped."""
        return self._last_summary

    def start_recording(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Recorder:
        """Record every frame from now on to a plain ``.dat`` file (with sidecar) at ``path``.

        Raises:
            OutputFileError: the file exists (without ``overwrite``) or cannot be created.
            ParameterError: a recording is already running, or the source is closed.
        """
        if self._closed:
            raise ParameterError(f"{self.label} is closed; open the camera again to record.")
        if self._recorder is not None:
            raise ParameterError(f"{self.label} is already recording to {self._recorder.path}; stop that recording first.")
        if self._thread is not None and not self.running:
            raise ParameterError(f"{self.label} is no longer acquiring ({self._message}); open the camera again to record.")
        info = self.info
        table = {"source": self.label, **{k: v for k, v in info.extra.get("live", {}).items() if k != "label"}}
        with self._ingest_lock:
            self._rec_first_tick = info.n_frames
            table["first_tick"] = info.n_frames
            self._rec_base = dict(self.device_counters())
            self._recorder = Recorder(path, info.width, info.height, flip_vertical=info.flip_vertical,
                                      flip_horizontal=info.flip_horizontal, cfa=info.cfa, tick_rate=info.tick_rate,
                                      tables={"recording": table}, max_queue_bytes=self.record_queue_bytes,
                                      overwrite=overwrite)
        return self._recorder

    def stop_recording(self, reason: str = "stopped by the user", timeout: float | None = None) -> RecordingSummary | None:
        """Stop the recording (every frame acquired so far goes to disk); returns its summary, ``None`` if none ran."""
        with self._ingest_lock:
            rec, self._recorder = self._recorder, None
            if rec is None:
                return None
            now = self.device_counters()
        base = self._rec_base
        device = {f"device_{k}": int(now.get(k, 0) - base.get(k, 0)) for k in now}
        device["ring_overruns"] = int(self.ring.overruns)
        summary = rec.stop(reason, tables={"recording": device}, timeout=timeout)
        self._last_summary = summary
        return summary

    # ================================================================================ counters
    def stats(self) -> dict[str, Any]:
        """A snapshot of every counter, for status lines and tests."""
        dev = self.device_counters()
        bps, fps = self._rate
        out: dict[str, Any] = {
            "status": self._status.value, "message": self._message, "frames": int(self.info.n_frames),
            "oldest_tick": self.ring.oldest, "ring_capacity": self.ring.capacity, "ring_overruns": self.ring.overruns,
            "bytes_per_s": bps, "frames_per_s": fps, **{f"device_{k}": int(v) for k, v in dev.items()},
        }
        rec = self._recorder
        if rec is not None:
            out.update(recording=True, record_path=str(rec.path), record_frames=rec.frames_written,
                       record_bytes=rec.file_size, record_queued_bytes=rec.queued_bytes,
                       record_buffer_dropped=rec.buffer_dropped_frames, record_elapsed_s=rec.elapsed_s,
                       record_device_dropped=int(dev.get("dropped_frames", 0) - self._rec_base.get("dropped_frames", 0)))
        else:
            out["recording"] = False
        return out

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.label!r} {self._status.value}, {self.info.n_frames} frames>"


def close_all(timeout: float | None = DEFAULT_CLOSE_TIMEOUT_S) -> None:
    """Close every live source and recording still open (the app and interpreter exit call this)."""
    for src in list(_LIVE):
        try:
            src.close(timeout)
        except Exception:
            pass
    _stop_all_recordings()


def _register_exit_hook() -> None:
    # threading's own exit hook runs before Python joins the (non-daemon) writer threads; atexit
    # would run after, too late for a recording whose source is still acquiring
    register = getattr(threading, "_register_atexit", None)
    try:
        if register is not None:
            register(close_all)
            return
    except RuntimeError:  # interpreter already shutting down
        return
    import atexit

    atexit.register(close_all)


_register_exit_hook()
