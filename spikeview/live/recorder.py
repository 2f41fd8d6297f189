"""Recording live frames to a plain ``.dat`` file and its sidecar, from a writer thread of its own.

The acquisition thread hands each batch of packed frames to :meth:`Recorder.submit`, which only
appends it to an in-memory queue (a lock held for a few microseconds): acquisition never waits on
the disk. A writer thread empties the queue into a
:class:`~spikeview.io.plain.PlainDatWriter`.

**When the disk is slower than the camera** the queue grows; it is bounded by
``max_queue_bytes`` (default 2 GiB, about 5 s of a saturated USB 3 link, or minutes at the rates
a disk usually sustains). Only beyond that bound are frames dropped, whole batches at a time, and
counted (``buffer_dropped_frames``, written to the sidecar); nothing is dropped silently.
Spilling to a second file would not help: the disk that is too slow would have to take the
spill too.

**What is on disk when a recording ends** (stopped by the user, device disconnected, app
closed): every frame submitted before :meth:`Recorder.stop` — the writer drains the queue, then
flushes, fsyncs and writes the sidecar with the ``[recording]`` table (frame count, drop
counters, why it ended). The sidecar is also written when the recording starts, so even a killed
process leaves a readable file (its last frame may then be partial; readers report it).
**When the disk fills up** the recording stops there: the file is trimmed back to the whole
frames written before the failed write (readable, no partial frame), the state becomes
``"failed"`` with one sentence saying the disk is full, and later frames are counted as dropped.
Writer threads are not daemons, and :func:`stop_all` (run before Python joins threads at exit)
stops every recording still running, so leaving the interpreter finalises the files too.
"""

from __future__ import annotations

import os
import threading
import time
import weakref
from collections import deque
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import OutputFileError, ParameterError, SpikeviewError
from spikeview.io.plain import PlainDatWriter
from spikeview.io.sidecar import sidecar_path
from spikeview.io.source import DEFAULT_TICK_RATE

#: default bound of the writer queue (bytes)
DEFAULT_MAX_QUEUE_BYTES = 2 << 30
#: the writer thread wakes at least this often (s) to notice a stop
_WAKE_S = 0.1

_RECORDERS: "weakref.WeakSet[Recorder]" = weakref.WeakSet()


@dataclass
class RecordingSummary:
    """How a recording went.

    Attributes:
        path: the ``.dat`` file (its sidecar is ``<path>.toml``).
        state: ``"recording"``, ``"finishing"`` (stopped, queue still being written), ``"done"``
            or ``"failed"`` (see ``message``).
        frames: frames on disk.
        bytes: bytes on disk (``frames × frame_bytes``).
        queued_frames: frames still waiting in the queue.
        buffer_dropped_frames: frames dropped because the queue was full or the disk failed.
        duration_s: wall-clock seconds from start to stop (or until now).
        message: one sentence on how it ended (or why it failed).
    """

    path: Path
    state: str
    frames: int
    bytes: int
    queued_frames: int
    buffer_dropped_frames: int
    duration_s: float
    message: str = ""

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["path"] = str(self.path)
        return d


class Recorder:
    """Writes packed frames to a plain ``.dat`` file (with sidecar) from its own thread.

    Args:
        path: the ``.dat`` file to create.
        width, height: frame size in pixels (``width·height`` a multiple of 8).
        flip_vertical, flip_horizontal: the flips a reader applies to the frames as submitted
            (the frames are written as given; see :mod:`spikeview.live.decode`).
        cfa: CFA of the frames after the flips, or ``None``.
        tick_rate: frames per second of the recorded stream (Hz).
        tables: extra sidecar tables; ``tables["recording"]`` is completed with the counters.
        max_queue_bytes: bound of the in-memory queue (see the module docstring).
        overwrite: replace an existing file (otherwise :class:`OutputFileError`).
        inputs: files being read (the capture being replayed, its sidecar): never replaced, even
            with ``overwrite``.

    Raises:
        OutputFileError: the file exists (without ``overwrite``), is one of ``inputs``, or cannot
            be created.
    """

    def __init__(self, path: str | os.PathLike[str], width: int, height: int, *, flip_vertical: bool = False,
                 flip_horizontal: bool = False, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
                 tables: dict[str, dict[str, Any]] | None = None, max_queue_bytes: int = DEFAULT_MAX_QUEUE_BYTES,
                 overwrite: bool = False, inputs: Iterable[str | os.PathLike[str] | None] = ()):
        from spikeview._files import check_writable

        self.path = Path(path)
        protected = [p for p in inputs if p]
        protected += [sidecar_path(p) for p in protected]
        for out in (self.path, sidecar_path(self.path)):
            check_writable(out, overwrite, protected)
        if int(max_queue_bytes) < 1:
            raise ParameterError(f"max_queue_bytes must be positive, got {max_queue_bytes}; give the queue some memory.")
        self.max_queue_bytes = int(max_queue_bytes)
        tables = {k: dict(v) for k, v in (tables or {}).items()}
        self._recording = dict(tables.pop("recording", {}))
        self.started = datetime.now().astimezone()
        self._recording.setdefault("started", self.started.isoformat(timespec="seconds"))
        self._writer = PlainDatWriter(self.path, width, height, flip_vertical=flip_vertical,
                                      flip_horizontal=flip_horizontal, cfa=cfa, tick_rate=tick_rate, sidecar=True,
                                      extra_tables={**tables, "recording": {**self._recording, "state": "recording"}})
        self.frame_bytes = self._writer.frame_bytes
        self._cond = threading.Condition()
        self._queue: deque[np.ndarray] = deque()
        self._queued_bytes = 0
        self._received = 0
        self._dropped = 0
        self._written = 0
        self._stopping = False
        self._state = "recording"
        self._message = ""
        self._reason = ""
        self._final_tables: dict[str, dict[str, Any]] = {}
        self._t0 = time.perf_counter()
        self._t_stop: float | None = None
        self._thread = threading.Thread(target=self._run, name=f"spikeview-recorder {self.path.name}", daemon=False)
        self._thread.start()
        _RECORDERS.add(self)

    # ------------------------------------------------------------------------------------ feeding
    def submit(self, frames: np.ndarray) -> bool:
        """Queue packed frames ``(n, frame_bytes)`` uint8 for writing; never waits on the disk.

        The array is kept, not copied: do not change it afterwards. Returns ``False`` when the
        frames were dropped (queue full, writer failed, or the recording is stopping), counted in
        ``buffer_dropped_frames``.
        """
        frames = np.asarray(frames)
        if frames.ndim != 2 or frames.shape[1] != self.frame_bytes or frames.dtype != np.uint8:
            raise ParameterError(f"submit() takes packed uint8 frames of shape (n, {self.frame_bytes}), got "
                                 f"{frames.dtype} {frames.shape}; pack the frames first.")
        n = frames.shape[0]
        if n == 0:
            return True
        with self._cond:
            self._received += n
            if self._stopping or self._state == "failed" or self._queued_bytes + frames.nbytes > self.max_queue_bytes:
                self._dropped += n
                return False
            self._queue.append(frames)
            self._queued_bytes += frames.nbytes
            self._cond.notify()
        return True

    # ------------------------------------------------------------------------------------ state
    @property
    def state(self) -> str:
        return self._state

    @property
    def frames_written(self) -> int:
        return self._written

    @property
    def queued_bytes(self) -> int:
        return self._queued_bytes

    @property
    def buffer_dropped_frames(self) -> int:
        return self._dropped

    @property
    def elapsed_s(self) -> float:
        end = self._t_stop if self._t_stop is not None else time.perf_counter()
        return end - self._t0

    @property
    def file_size(self) -> int:
        """Bytes written to the file so far (what a file browser shows, give or take the OS cache)."""
        return self._written * self.frame_bytes

    def summary(self) -> RecordingSummary:
        with self._cond:
            queued = sum(q.shape[0] for q in self._queue)
            return RecordingSummary(path=self.path, state=self._state, frames=self._written,
                                    bytes=self._written * self.frame_bytes, queued_frames=queued,
                                    buffer_dropped_frames=self._dropped, duration_s=self.elapsed_s,
                                    message=self._message)

    # ------------------------------------------------------------------------------------ stopping
    def stop(self, reason: str = "stopped by the user", tables: dict[str, dict[str, Any]] | None = None,
             timeout: float | None = None) -> RecordingSummary:
        """End the recording: the writer drains the queue, fsyncs and writes the final sidecar.

        Safe to call more than once and from any thread (the first reason and tables win).

        Args:
            reason: why it ended, one sentence (written to the sidecar as ``end``).
            tables: more sidecar tables; ``tables["recording"]`` is merged into the recording table
                (the live source passes its device-side drop counters here).
            timeout: seconds to wait for the writer (``None``: until the queue is on disk). When it
                runs out the writer goes on in the background and the summary says ``"finishing"``.
        """
        with self._cond:
            if not self._stopping:
                self._stopping = True
                self._t_stop = time.perf_counter()
                self._reason = str(reason)
                self._final_tables = {k: dict(v) for k, v in (tables or {}).items()}
                if self._state == "recording":
                    self._state = "finishing"
                self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        return self.summary()

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the writer thread has finished (after :meth:`stop`); returns whether it has."""
        self._thread.join(timeout)
        return not self._thread.is_alive()

    # ------------------------------------------------------------------------------------ writer thread
    def _run(self) -> None:
        w = self._writer
        while True:
            with self._cond:
                while not self._queue and not self._stopping:
                    self._cond.wait(_WAKE_S)
                if not self._queue:
                    break  # stopping and drained
                item = self._queue.popleft()
                self._queued_bytes -= item.nbytes
                idle = not self._queue
            if self._state == "failed":
                continue
            try:
                w.write_packed(item)
                self._written += item.shape[0]
                if idle:
                    w.flush()  # small frames: make the file size visible while recording
            except SpikeviewError as e:
                self._fail(str(e), item.shape[0])
        self._finish()

    def _fail(self, message: str, lost: int) -> None:
        with self._cond:
            self._state = "failed"
            self._message = message
            self._dropped += lost + sum(q.shape[0] for q in self._queue)
            self._queue.clear()
            self._queued_bytes = 0

    def _finish(self) -> None:
        w = self._writer
        rec = dict(self._recording)
        rec.update(self._final_tables.pop("recording", {}))
        rec.update(frames=self._written, buffer_dropped_frames=self._dropped, received_frames=self._received,
                   duration_s=round(self.elapsed_s, 3), end=self._reason or "stopped",
                   state="failed" if self._state == "failed" else "complete")
        if self._message:
            rec["error"] = self._message
        for name, table in self._final_tables.items():
            w.set_table(name, table)
        w.set_table("recording", rec)
        try:
            w.close()
        except SpikeviewError as e:
            with self._cond:
                self._state = "failed"
                self._message = self._message or str(e)
        with self._cond:
            if self._state != "failed":
                self._state = "done"
                self._message = f"Recorded {self._written} frames to {self.path.name}."
                if self._reason and self._reason != "stopped by the user":
                    self._message += f" {self._reason}"
                if self._dropped:
                    self._message += f" {self._dropped} frames were dropped because the disk could not keep up."
        _RECORDERS.discard(self)

    @property
    def sidecar(self) -> Path:
        return sidecar_path(self.path)


def stop_all(reason: str = "the program exited", timeout: float | None = 30.0) -> None:
    """Stop every recording still running (used at interpreter exit)."""
    for rec in list(_RECORDERS):
        rec.stop(reason, timeout=timeout)
