"""glibc's allocator kept from page-faulting the prior's large float32 buffers afresh on every layer.

Why: torch allocates every FFDNet layer's output anew (a 96-feature float32 strip of a 1000×1000
frame is ~54 MB). glibc's ``malloc`` serves a request above its mmap threshold (dynamic, at most
32 MiB on 64-bit) with a fresh ``mmap`` and returns it with ``munmap`` on ``free``, so every layer
touches new zeroed pages: ~270,000 minor page faults per 1000² RGB float32 pass, a fifth of its time.
:func:`reuse_large_buffers` raises glibc's thresholds so that the same memory comes from the heap layer
after layer: no faults after the first pass in the main thread (the CLI; 1000² ``--precision float32``
frame 7.59 → 5.81 s). The arithmetic is unchanged. Other threads' glibc heaps hold at most 64 MiB each, so
there the reuse is partial and the heap grows from run to run; there the fused float32 path writes its
outputs into two buffers of the pass instead (:func:`spikeview.guided.priors.ffdnet._conv_fused_into`,
whatever the C library). NNPACK (``float32-fast``) can only have the heap.

Who sets it, and when: the FFDNet prior, right before a float32 pass whose layer outputs outgrow glibc's
dynamic threshold (in the main thread, or NNPACK anywhere), once per process (``mallopt`` is process-wide
and cannot be given back to glibc's dynamic threshold) — never at import: a process that never runs such a
pass is untouched, and every caller of the prior (CLI, cluster workers, a notebook) is served alike without
an entry-point call. What it costs: freed buffers stay resident in the heap for the next pass (~+300 MB
after a 1000² pass); :func:`release_free_memory` (``malloc_trim``) gives them back.

Nothing happens (and nothing fails) where the C library is not glibc (musl, macOS, Windows), where the
environment already sets the thresholds (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``,
``GLIBC_TUNABLES=glibc.malloc.mmap_threshold…``: the user's choice wins), or with
``SPIKEVIEW_MALLOC_TUNE=0``. :func:`state` says which, in a few words (the benchmark's machine line).
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import threading

__all__ = ["GLIBC_DYNAMIC_MAX", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "glibc_default", "release_free_memory", "reuse_large_buffers",
           "state"]

#: glibc's dynamic mmap threshold never grows past this on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX): larger
#: requests are always fresh mmaps, i.e. page faults on every use
GLIBC_DYNAMIC_MAX = 32 << 20
#: requests up to this come from the heap once :func:`reuse_large_buffers` ran: above a 2000×2000 float32
#: layer strip (~108 MB; the widest the prior makes is ~54 MB per 1000 columns of frame) and below what
#: would make the heap hold huge long-lived arrays (a capture, a video), which stay mmaps returned on free
MMAP_THRESHOLD = 256 << 20
#: the heap's free top is given back to the OS only above this: a 1000² pass frees up to ~3 strips at
#: the top between layers (measured per pass after the first: trim 64 MiB → 13–25k faults, 128 MiB → 0–13k,
#: 256–512 MiB → 0–563)
TRIM_THRESHOLD = 512 << 20
#: environment variables through which the user sets glibc's thresholds (then left alone)
_USER_VARS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")
_OFF_VAR = "SPIKEVIEW_MALLOC_TUNE"

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_lock = threading.Lock()
_state: str | None = None  # None: not asked yet; otherwise "on …" / "off (…)"


@functools.lru_cache(maxsize=1)
def _glibc() -> ctypes.CDLL | None:
    """The running process's glibc, or None (another C library, or none that ctypes can open)."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return None
        libc = ctypes.CDLL(None)
        for name in ("mallopt", "malloc_trim", "malloc", "free"):
            getattr(libc, name)
    except (AttributeError, OSError, ValueError, TypeError):
        return None
    libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    libc.mallopt.restype = ctypes.c_int
    libc.malloc_trim.argtypes = [ctypes.c_size_t]
    libc.malloc_trim.restype = ctypes.c_int
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.malloc.restype = ctypes.c_void_p
    libc.free.argtypes = [ctypes.c_void_p]
    libc.free.restype = None
    return libc


def _mmapped_bytes(libc: ctypes.CDLL) -> int | None:
    """glibc's count of bytes in mmapped chunks (``mallinfo2().hblkhd``; ``mallinfo`` before 2.33)."""
    fields = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                                              "uordblks", "fordblks", "keepcost")]

    class _Info2(ctypes.Structure):
        _fields_ = fields

    class _Info(ctypes.Structure):
        _fields_ = [(n, ctypes.c_int) for n, _ in fields]

    for name, struct in (("mallinfo2", _Info2), ("mallinfo", _Info)):
        fn = getattr(libc, name, None)
        if fn is not None:
            fn.argtypes = []
            fn.restype = struct
            return int(fn().hblkhd)
    return None


def _served_from_heap(libc: ctypes.CDLL) -> bool:
    """A request between glibc's dynamic maximum and :data:`MMAP_THRESHOLD` is no longer an mmap (checked,
    not taken from ``mallopt``'s return value: an old glibc capped the threshold at 32 MiB). The block is
    never written, so it costs address space, not memory."""
    before = _mmapped_bytes(libc)
    if before is None:
        return True  # no way to check; mallopt said yes
    p = libc.malloc(GLIBC_DYNAMIC_MAX + (8 << 20))
    if not p:
        return False
    after = _mmapped_bytes(libc)
    libc.free(p)
    return after is not None and after - before < GLIBC_DYNAMIC_MAX


def _user_set(environ) -> str | None:
    """The environment variable through which the user already tunes glibc's thresholds, if any."""
    for var in _USER_VARS:
        if environ.get(var):
            return var
    tunables = environ.get("GLIBC_TUNABLES", "")
    if any(t in tunables for t in ("malloc.mmap_threshold", "malloc.trim_threshold", "malloc.top_pad")):
        return "GLIBC_TUNABLES"
    return None


def reuse_large_buffers(environ=None) -> bool:
    """Let glibc serve requests up to :data:`MMAP_THRESHOLD` from its heap and keep up to
    :data:`TRIM_THRESHOLD` of freed heap (``mallopt``), once per process; True when that is in effect.

    Called by the FFDNet prior before a float32 pass in the main thread (or an NNPACK one anywhere) with layer
    outputs over :data:`GLIBC_DYNAMIC_MAX`. Does nothing (False) on another C library, where the environment already
    sets glibc's thresholds, with ``SPIKEVIEW_MALLOC_TUNE=0``, or where glibc refuses the values; never raises.
    ``environ`` (default ``os.environ``) is for tests.
    """
    global _state
    if _state is not None:
        return _state.startswith("on")
    with _lock:
        if _state is None:
            _state = _apply(os.environ if environ is None else environ)
    return _state.startswith("on")


def _apply(environ) -> str:
    if environ.get(_OFF_VAR, "").strip().lower() in ("0", "off", "no", "false"):
        return f"off ({_OFF_VAR}={environ.get(_OFF_VAR)})"
    var = _user_set(environ)
    if var:
        return f"off ({var} set in the environment)"
    libc = _glibc()
    if libc is None:
        return "off (not glibc)"
    try:
        ok = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1 and libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
        if not ok or not _served_from_heap(libc):
            return "off (glibc refused the thresholds)"
    except (OSError, ValueError, TypeError, ctypes.ArgumentError):
        return "off (mallopt failed)"
    return f"on (glibc heap serves up to {MMAP_THRESHOLD >> 20} MiB, keeps {TRIM_THRESHOLD >> 20} MiB free)"


def state() -> str:
    """``"on (…)"``, ``"off (reason)"``, or ``"not needed yet"`` (no large float32 pass has asked for it in this process)."""
    return _state if _state is not None else "not needed yet"


def release_free_memory() -> bool:
    """Give the heap's free pages back to the OS (``malloc_trim(0)``) where :func:`reuse_large_buffers`
    kept them; True when something was released. For long-lived processes between runs (the app after a
    guided run); the next large pass faults its buffers in once more (~75k faults at 1000², a few tens of ms)."""
    if _state is None or not _state.startswith("on"):
        return False
    libc = _glibc()
    try:
        return bool(libc is not None and libc.malloc_trim(0))
    except (OSError, ValueError, TypeError, ctypes.ArgumentError):
        return False


@contextlib.contextmanager
def glibc_default():
    """Within the block, requests above glibc's dynamic maximum (32 MiB) are fresh mmaps again, as in a process
    where :func:`reuse_large_buffers` never ran. For benchmarks: "before" rows and today's eager baseline measured
    in the same process as the rows with the heap reuse.

    Lowering the threshold alone is not enough: glibc serves a request from a free heap chunk that fits before it
    asks the system, so the heap kept by earlier passes would keep serving. The block therefore also takes every
    free stretch of heap of more than 32 MiB out of reach for its duration (allocated, never written: no memory)
    and gives it back on exit."""
    libc = _glibc() if state().startswith("on") else None
    plugs: list[int] = []
    if libc is not None:
        libc.mallopt(_M_MMAP_THRESHOLD, GLIBC_DYNAMIC_MAX)
        libc.mallopt(_M_TRIM_THRESHOLD, 2 * GLIBC_DYNAMIC_MAX)  # glibc's dynamic trim threshold at its maximum
        size = GLIBC_DYNAMIC_MAX + (1 << 20)
        while len(plugs) < 4096:
            before = _mmapped_bytes(libc)
            p = libc.malloc(size)
            if not p:
                break
            if before is None or _mmapped_bytes(libc) - before >= size:  # an mmap: no free heap of this size is left
                libc.free(p)
                break
            plugs.append(p)
    try:
        yield
    finally:
        if libc is not None:
            for p in plugs:
                libc.free(p)
            libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
            libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
