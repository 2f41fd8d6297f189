"""Background workers: QThreads that run jobs, report progress and pass errors back.

A :class:`Worker` owns one :class:`QtCore.QThread` and runs plain-Python job functions on it, one
at a time. Jobs are submitted on named *channels*; per channel only the newest pending job is
kept (older pending ones are dropped unrun), so a burst of slider moves or scrub events costs one
computation. Every job gets an id; results, progress and errors come back as Qt signals carrying
``(channel, job_id, ...)`` and are delivered on the GUI thread, where the receiver drops any id
that is no longer the newest (:meth:`Worker.is_current`).

A job function receives a :class:`JobContext`: ``ctx.report(payload)`` sends progress,
``ctx.cancelled`` is a :class:`threading.Event` (``ctx.check()`` raises
:class:`~spikeview.errors.Cancelled` when it is set), and ``ctx.state`` is a dict that lives as long
as the worker — the guided worker keeps its loaded prior model there, so the model is built once
and owned by the worker thread.

Errors never escape: a :class:`~spikeview.errors.SpikeviewError` becomes its message; anything
else becomes a one-line "unexpected …" message (with the traceback on stderr for a bug report).
"""

from __future__ import annotations

import itertools
import os
import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from PySide6 import QtCore

from spikeview.errors import Cancelled, SpikeviewError

#: how often (s) a thread running Python code hands the interpreter lock to another: 1 ms instead of
#: Python's 5 ms, so the window gets it back quickly while a worker runs Python code
SWITCH_INTERVAL_S = 0.001


def configure_runtime() -> None:
    """Process settings the app needs to stay responsive while workers compute."""
    if sys.getswitchinterval() > SWITCH_INTERVAL_S:
        sys.setswitchinterval(SWITCH_INTERVAL_S)


@dataclass
class JobContext:
    """What a running job can use (see module docstring)."""

    job_id: int
    channel: str
    cancelled: threading.Event
    state: dict[str, Any]
    _report: Callable[[Any], None] = field(repr=False, default=lambda p: None)

    def report(self, payload: Any) -> None:
        self._report(payload)

    def check(self) -> None:
        if self.cancelled.is_set():
            raise Cancelled(f"job {self.job_id} cancelled")


@dataclass
class _Job:
    job_id: int
    channel: str
    fn: Callable[[JobContext], Any]
    cancelled: threading.Event = field(default_factory=threading.Event)


_ids = itertools.count(1)


class Worker(QtCore.QThread):
    """A thread running jobs by channel, newest-wins (see module docstring).

    Signals (delivered on the GUI thread):
        progress(channel, job_id, payload), finished(channel, job_id, result),
        failed(channel, job_id, message), cancelled(channel, job_id).
    """

    progress = QtCore.Signal(str, int, object)
    finished = QtCore.Signal(str, int, object)
    failed = QtCore.Signal(str, int, str)
    cancelled = QtCore.Signal(str, int)

    def __init__(self, name: str, priority: tuple[str, ...] = (), parent: QtCore.QObject | None = None,
                 *, nice: int = 0, torch_threads: int | None = None):
        super().__init__(parent)
        self.setObjectName(name)
        self.priority = priority
        self.nice = nice
        self.torch_threads = torch_threads
        self.state: dict[str, Any] = {}
        self._cond = threading.Condition()
        self._pending: dict[str, _Job] = {}
        self._latest: dict[str, int] = {}
        self._running: _Job | None = None
        self._stopping = False

    # --- GUI-thread API -------------------------------------------------------------------
    def submit(self, channel: str, fn: Callable[[JobContext], Any], *, cancel_running: bool = False) -> int:
        """Queue ``fn`` on ``channel`` (replacing a pending job there); returns the new job id.

        ``cancel_running=True`` also sets the cancel flag of a running job of the same channel
        (a restart); otherwise a running job finishes and its result is simply stale.
        """
        job = _Job(next(_ids), channel, fn)
        with self._cond:
            if self._stopping:
                return job.job_id
            self._pending[channel] = job
            self._latest[channel] = job.job_id
            if cancel_running and self._running is not None and self._running.channel == channel:
                self._running.cancelled.set()
            self._cond.notify()
        if not self.isRunning():
            self.start()
        return job.job_id

    def cancel(self, channel: str) -> None:
        """Drop the pending job of ``channel`` and ask its running job to stop."""
        with self._cond:
            self._pending.pop(channel, None)
            self._latest[channel] = next(_ids)  # anything still in flight is now stale
            if self._running is not None and self._running.channel == channel:
                self._running.cancelled.set()

    def is_current(self, channel: str, job_id: int) -> bool:
        """Whether ``job_id`` is the newest job submitted on ``channel`` (else its output is stale)."""
        with self._cond:
            return self._latest.get(channel) == job_id

    def is_active(self, channel: str | None = None) -> bool:
        """Whether a job (of ``channel``, or any) is running or pending."""
        with self._cond:
            if channel is None:
                return self._running is not None or bool(self._pending)
            return (self._running is not None and self._running.channel == channel) or channel in self._pending

    def stop(self, timeout_ms: int = 30_000) -> bool:
        """Cancel everything and end the thread; returns False if it did not end in time."""
        with self._cond:
            self._stopping = True
            self._pending.clear()
            if self._running is not None:
                self._running.cancelled.set()
            self._cond.notify_all()
        if self.isRunning():
            return self.wait(QtCore.QDeadlineTimer(timeout_ms))
        return True

    # --- worker thread ----------------------------------------------------------------------
    def _next_job(self) -> _Job | None:
        with self._cond:
            while not self._pending and not self._stopping:
                self._cond.wait()
            if self._stopping:
                return None
            order = [c for c in self.priority if c in self._pending] + [c for c in self._pending if c not in self.priority]
            job = self._pending.pop(order[0])
            self._running = job
            return job

    def _lower_priority(self) -> None:
        """Make this thread yield the CPU to the GUI thread (Linux: a per-thread nice value)."""
        if self.nice and hasattr(os, "setpriority") and sys.platform.startswith("linux"):
            try:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self.nice)
            except OSError:  # not permitted: run at normal priority
                pass
        if self.torch_threads is not None:
            import torch

            torch.set_num_threads(self.torch_threads)

    def run(self) -> None:
        self._lower_priority()
        while True:
            job = self._next_job()
            if job is None:
                return
            ctx = JobContext(job.job_id, job.channel, job.cancelled, self.state,
                             lambda p, j=job: self.progress.emit(j.channel, j.job_id, p))
            outcome: tuple[str, Any]
            try:
                result = job.fn(ctx)
            except Cancelled:
                outcome = ("cancelled", None)
            except SpikeviewError as e:
                outcome = ("failed", str(e))
            except MemoryError:
                outcome = ("failed", "Out of memory: use a smaller region (ROI) or a shorter range.")
            except Exception as e:  # noqa: BLE001 - a bug must not kill the thread or the window: report it
                traceback.print_exc(file=sys.stderr)
                outcome = ("failed", f"Unexpected {type(e).__name__}: {e} (this is a bug; please report it with the terminal output).")
            else:
                outcome = ("cancelled", None) if job.cancelled.is_set() else ("finished", result)
            # the job is over before anyone hears about it: a receiver may submit the next one at once
            with self._cond:
                self._running = None
            kind, payload = outcome
            if kind == "finished":
                self.finished.emit(job.channel, job.job_id, payload)
            elif kind == "failed":
                self.failed.emit(job.channel, job.job_id, payload)
            else:
                self.cancelled.emit(job.channel, job.job_id)
