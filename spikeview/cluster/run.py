"""The batch driver: split the windows into chunks, run them in-process or on Dask, resume, report.

::

    job = BatchJob(input=..., open_kwargs=..., recipe=..., centres=..., chunk=16, store="out.zarr")
    report = run_batch(job, state, cluster="local:2", progress=bar.update)

Each work chunk is one task: the worker opens the source from ``job.input`` (once per process, see
:func:`spikeview.cluster._compute.worker_resources`), computes the chunk's frames and writes them
straight into the store on the shared file system, then marks the chunk done. Only the small job
description and a small result go through the scheduler.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from spikeview.cluster._compute import (
    DEFAULT_KEYFRAME,
    chained,
    compute_chunk,
    state_from_attrs,
    state_to_attrs,
    worker_resources,
)
from spikeview.errors import Cancelled, ParameterError, SpikeviewError

#: how often Dask retries a chunk whose task raised (a worker that dies is rescheduled by Dask itself)
RETRIES = 2


@dataclasses.dataclass(frozen=True)
class BatchJob:
    """What the workers need (each task gets :meth:`for_chunk`: only its own windows' ticks).

    Attributes:
        input: absolute path of the spike file, readable by every worker.
        open_kwargs: :func:`spikeview.io.open_source` arguments (format, geometry, CFA, flips…).
        recipe: the preset tables (``run``, ``stream``, ``classical`` / ``guided``, ``export``).
        centres: centre ticks of windows ``offset, offset + 1, …`` in output order (all of them in
            the driver's job; a task's own windows and lead-in in :meth:`for_chunk`).
        chunk: windows per work chunk (= the Zarr chunk along the window axis).
        store: absolute path of the ``.zarr`` store.
        keyframe: guided reuse / warm-start chains restart at window indices that are multiples of it.
        offset: index of the window ``centres[0]`` is the centre of.
        n_windows: windows of the whole run (``None``: ``len(centres)``).
    """

    input: str
    open_kwargs: dict[str, Any]
    recipe: dict[str, Any]
    centres: tuple[int, ...]
    chunk: int
    store: str
    keyframe: int = DEFAULT_KEYFRAME
    offset: int = 0
    n_windows: int | None = None

    @property
    def total(self) -> int:
        return len(self.centres) if self.n_windows is None else self.n_windows

    @property
    def n_chunks(self) -> int:
        return -(-self.total // self.chunk)

    def bounds(self, index: int) -> tuple[int, int]:
        """Window indices ``[lo, hi)`` of work chunk ``index``."""
        lo = index * self.chunk
        return lo, min(lo + self.chunk, self.total)

    def chain_start(self, lo: int) -> int:
        """First window to compute for a chunk starting at ``lo``: the previous keyframe when windows chain."""
        return (lo // self.keyframe) * self.keyframe if chained(self.recipe) else lo

    def for_chunk(self, index: int) -> BatchJob:
        """The job a task of chunk ``index`` needs: the ticks of its windows and lead-in only (a 20,000-window
        run would otherwise send every task all 20,000 ticks through the scheduler)."""
        lo, hi = self.bounds(index)
        start = self.chain_start(lo)
        return dataclasses.replace(self, centres=self.centres[start - self.offset:hi - self.offset], offset=start,
                                   n_windows=self.total)


@dataclasses.dataclass
class BatchReport:
    """What a run did: chunks and windows computed now, wall time, per-chunk results."""

    chunks_done: int = 0
    chunks_skipped: int = 0
    windows: int = 0
    seconds: float = 0.0
    results: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    #: the Dask event topic of the workers' progress inside chunks (``None`` in-process)
    topic: str | None = None

    @property
    def windows_per_second(self) -> float:
        return self.windows / self.seconds if self.seconds > 0 else float("nan")


def _in_dask_worker() -> bool:
    if "distributed" not in sys.modules:
        return False
    from distributed import get_worker

    try:
        get_worker()
    except ValueError:
        return False
    return True


_TORCH_THREADS_SET = False


#: seconds between a worker's progress events for one chunk (the chunk's end is always reported)
EVENT_INTERVAL = 1.0


def run_chunk(job: BatchJob, index: int, state: dict[str, Any], topic: str | None = None,
              on_window: Callable[[int, int], Any] | None = None) -> dict[str, Any]:
    """Compute and store work chunk ``index`` (runs on a worker, or in-process); returns a small report.

    Progress inside the chunk: ``on_window(index, windows_done)`` in-process, or on a Dask worker an
    event ``{"chunk": index, "done": windows_done}`` on ``topic`` at most every :data:`EVENT_INTERVAL` s.
    """
    global _TORCH_THREADS_SET
    from spikeview.cluster.store import write_chunk

    in_worker = _in_dask_worker()
    if not _TORCH_THREADS_SET and in_worker and job.recipe.get("run", {}).get("method") == "guided":
        # one task per worker thread: torch must not start its own pool on top of the worker's threads
        import torch

        torch.set_num_threads(1)
        _TORCH_THREADS_SET = True
    recipe = _worker_recipe(job.recipe, in_worker)
    source, sampler = worker_resources(job.input, job.open_kwargs, recipe)
    lo, hi = job.bounds(index)
    start = job.chain_start(lo)
    t0 = time.perf_counter()
    last = [t0]

    def window_done(k: int) -> None:
        k -= lo - start  # lead-in windows are not output
        if k <= 0 or k >= hi - lo:
            return  # the chunk's end is reported by its result
        if on_window is not None:
            on_window(index, k)
        elif topic is not None and in_worker and time.perf_counter() - last[0] >= EVENT_INTERVAL:
            from distributed import get_worker

            last[0] = time.perf_counter()
            get_worker().log_event(topic, {"chunk": index, "done": k})

    centres = job.centres[start - job.offset:hi - job.offset]
    frames = compute_chunk(source, centres, recipe, state_from_attrs(state), sampler=sampler, on_window=window_done)
    frames = frames[lo - start:]
    seconds = time.perf_counter() - t0
    write_chunk(job.store, index, lo, frames, seconds)
    return {"index": index, "windows": hi - lo, "lead_in": lo - start, "seconds": seconds, "pid": os.getpid(),
            "max_rss_mb": _max_rss_mb()}


def _max_rss_mb() -> float:
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return float("nan")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 1024.0 if sys.platform != "darwin" else rss / (1024.0 * 1024.0)


# ------------------------------------------------------------------------------------ clients
def parse_cluster(text: str) -> tuple[str, Any]:
    """``"local:N"`` → ``("local", N)``; ``"tcp://HOST:PORT"`` (or another Dask scheme) → ``("address", text)``."""
    t = text.strip()
    if t.startswith("local:") or t == "local":
        try:
            n = int(t.partition(":")[2] or os.cpu_count() or 1)
        except ValueError:
            n = 0
        if n < 1:
            raise ParameterError(f"--cluster {text!r}: local:N needs a whole number of workers >= 1, e.g. local:2.")
        cores = os.cpu_count() or 1
        if n > 4 * cores:  # each worker is a process with its own copy of the prior: thousands never start
            raise ParameterError(f"--cluster {text!r}: {n} worker processes is far more than this machine's {cores} "
                                 f"cores; use at most local:{4 * cores} (local:{cores} is usually fastest).")
        return "local", n
    if "://" in t and t.split("://", 1)[1]:
        return "address", t
    raise ParameterError(f"--cluster {text!r} is neither local:N nor a scheduler address such as tcp://HOST:8786.")


def _worker_recipe(recipe: dict[str, Any], in_worker: bool) -> dict[str, Any]:
    """The chunk's recipe on this worker: with several GPUs and ``guided.device`` auto or cuda, Dask worker N
    of ``local:N`` takes GPU ``N mod GPUs`` (one worker per GPU; the pixels do not depend on which GPU)."""
    guided = recipe.get("guided", {})
    if not in_worker or recipe.get("run", {}).get("method") != "guided" or guided.get("device", "auto") not in ("auto", "cuda"):
        return recipe
    from spikeview.guided.device import cuda_count

    count = cuda_count()
    if count < 2:
        return recipe
    from distributed import get_worker

    name = get_worker().name
    index = (name if isinstance(name, int) else abs(hash(str(name)))) % count
    return {**recipe, "guided": {**guided, "device": f"cuda:{index}"}}


def connect(cluster: str, timeout: float = 10.0):
    """A Dask client for ``cluster`` and a function that closes it (and the local cluster it started).

    Raises:
        ParameterError: bad ``--cluster`` text, or no scheduler answering at the address.
    """
    kind, value = parse_cluster(cluster)
    import logging

    from distributed import Client, LocalCluster

    if kind == "local":
        # workers inherit an ignored SIGINT: Ctrl-C stops the run through this process (one message, the
        # finished chunks kept) instead of printing a KeyboardInterrupt traceback from every worker
        import signal

        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            # dashboard on a free port: the default 8787 may belong to another cluster on this machine
            lc = LocalCluster(n_workers=value, threads_per_worker=1, processes=True, dashboard_address=":0",
                              silence_logs=logging.ERROR)
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, previous)
        client = Client(lc)

        def close() -> None:
            client.close()
            lc.close()

        return client, close
    def unreachable(e: BaseException) -> ParameterError:
        return ParameterError(
            f"cannot reach a Dask scheduler at {value} within {timeout:g} s ({type(e).__name__}); "
            "check the address (dask scheduler prints it) and that the scheduler is running."
        )

    if value.startswith("tcp://"):
        # probe first: a Client that fails to connect leaves sockets behind
        import socket

        host, _, port = value[len("tcp://"):].rstrip("/").rpartition(":")
        try:
            with socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout):
                pass
        except ValueError:
            raise ParameterError(f"--cluster {value!r}: the address needs a port, e.g. tcp://HOST:8786.") from None
        except OSError as e:
            raise unreachable(e) from None
    try:
        client = Client(value, timeout=timeout)
    except (OSError, TimeoutError) as e:
        raise unreachable(e) from None
    return client, client.close


def run_batch(job: BatchJob, state: Any, *, cluster: str | None = None,
              progress: Callable[[int], Any] | None = None, cancel: Callable[[], bool] | None = None,
              client: Any = None) -> BatchReport:
    """Run every chunk of ``job`` that the store does not yet mark done.

    Args:
        job: the work (its store must exist, see :func:`spikeview.cluster.store.create_store`).
        state: the sequence-wide state (:func:`spikeview.pipeline.prepare_sequence`), computed once before the split.
        cluster: ``None`` (in-process, chunk after chunk), ``"local:N"`` or a scheduler address.
        progress: called with the number of windows this call has finished so far (stored chunks
            plus the windows finished inside running chunks; never decreasing).
        cancel: polled after every finished chunk; true stops the run (:class:`Cancelled`) leaving the
            finished chunks marked, so ``--resume`` continues from them.
        client: an existing Dask client to use instead of ``cluster`` (left open).

    Raises:
        Cancelled: ``cancel`` fired.
        ParameterError: bad ``cluster``, or a worker died repeatedly on one chunk.
    """
    from spikeview.cluster.store import done_mask, open_store

    done = done_mask(open_store(job.store))
    pending = [i for i in range(job.n_chunks) if not done[i]]
    report = BatchReport(chunks_skipped=job.n_chunks - len(pending))
    sd = state_to_attrs(state)
    t0 = time.perf_counter()
    lock = threading.Lock()
    inflight: dict[int, int] = {}
    shown = [0]

    def show() -> None:  # under the lock
        n = report.windows + sum(inflight.values())
        if n > shown[0]:
            shown[0] = n
            if progress is not None:
                progress(n)

    stored: set[int] = set()

    def partial(index: int, k: int) -> None:
        with lock:
            if index in stored:
                return  # a late event of a chunk already stored
            inflight[index] = k
            show()

    def finished(res: dict[str, Any]) -> None:
        with lock:
            stored.add(res["index"])
            inflight.pop(res["index"], None)
            report.results.append(res)
            report.chunks_done += 1
            report.windows += res["windows"]
            show()

    if cluster is None and client is None:
        from spikeview.cluster._compute import clear_cache

        try:
            for i in pending:
                finished(run_chunk(job.for_chunk(i), i, sd, on_window=partial))
                if cancel is not None and cancel():
                    raise Cancelled()
        finally:
            clear_cache()
        report.seconds = time.perf_counter() - t0
        return report

    close = None
    if client is None:
        client, close = connect(cluster)
    from distributed import as_completed

    token = os.urandom(4).hex()
    topic = report.topic = f"spikeview-progress-{token}"

    def on_event(event: Any) -> None:
        msg = event[1]
        if isinstance(msg, dict) and "chunk" in msg:
            partial(int(msg["chunk"]), int(msg["done"]))

    client.subscribe_topic(topic, on_event)
    futures = [client.submit(run_chunk, job.for_chunk(i), i, sd, topic, pure=False, retries=RETRIES,
                             key=f"spikeview-chunk-{i}-{token}")
               for i in pending]
    try:
        for fut in as_completed(futures):
            try:
                finished(fut.result())
            except SpikeviewError:
                raise
            except Exception as e:
                if type(e).__name__ == "KilledWorker":
                    raise ParameterError(
                        f"a Dask worker died {RETRIES + 1} or more times on one chunk ({e}); the finished chunks are "
                        "kept: look for out-of-memory kills, give workers more memory or use a smaller --chunk, then --resume."
                    ) from None
                raise
            if cancel is not None and cancel():
                raise Cancelled()
    finally:
        for f in futures:
            if not f.done():
                f.cancel()
        try:
            client.unsubscribe_topic(topic)
        except Exception:  # noqa: BLE001 - a client that is already gone has nothing to unsubscribe
            pass
        if close is not None:
            close()
    report.seconds = time.perf_counter() - t0
    return report

