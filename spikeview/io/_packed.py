"""Counting spikes directly on packed bytes (the TFP hot path), with numba.

Imported lazily by the readers (``import numba`` is slow and ``spikeview --help`` must stay quick).

Layout the kernel understands: a frame is ``n_rows`` storage rows of ``row_bytes`` bytes each
(``row_bytes * 8`` pixels, least significant bit first), starting at an arbitrary byte offset of
a 1-D uint8 buffer (a memmap or a ``bytes`` object). Output rows are storage rows, optionally in
reverse order (vertical flip); output columns are copied from the storage row by *segments*
``(src_col, dst_col, length)`` (which is how raw formats drop their tag bits), optionally mirrored.

How it counts without unpacking every frame:

1. **Bit-sliced vertical counters.** For a chunk of about 1 KiB of storage bytes, P uint8 "planes"
   hold bit k of the running count of every pixel (pixel ``8*i + j`` uses bit ``j`` of byte ``i``
   of each plane). Adding a frame is a ripple-carry add of its bytes into the planes: two bitwise
   operations per plane on 32 bytes at a time (AVX2), i.e. 256 pixels per instruction.
   P = 4 covers windows up to 15 frames, P = 8 up to 255; longer windows run several passes.
2. **Extraction** (once per window, not per frame): for each 64-bit word of the planes, masks and
   shifts merge the planes into 2-bit, 4-bit and (P = 8) 8-bit count fields, giving eight words
   ``c_j`` whose byte ``m`` is the count of pixel ``8m + j``; an 8×8 byte transpose (three delta
   swaps) then puts the uint8 counts in pixel order (SWAR: no tables, vectorisable).
3. **Copy-out** of whole rows into the output, widening to uint16 and applying the flips and the
   column segments (contiguous loops, vectorised).

Work is split across a small thread pool (``nogil`` kernels): by windows when there are several,
otherwise by rows. The pool is safe to use from several threads at once.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

#: the most frames one kernel pass accumulates (8 bit planes); longer windows take several passes
MAX_FRAMES_PER_PASS = 255
#: the most frames counted into uint16 (longer windows are summed in uint32 from uint16 parts)
_MAX_UINT16_FRAMES = 65535
#: target size of the per-thread working chunk (bytes of one frame); keeps the planes in L1
_CHUNK_BYTES = 1024

_M55 = np.uint64(0x5555555555555555)
_MAA = np.uint64(0xAAAAAAAAAAAAAAAA)
_M33 = np.uint64(0x3333333333333333)
_MCC = np.uint64(0xCCCCCCCCCCCCCCCC)
_M0F = np.uint64(0x0F0F0F0F0F0F0F0F)
_MF0 = np.uint64(0xF0F0F0F0F0F0F0F0)
_K32 = np.uint64(0x00000000FFFFFFFF)
_K16 = np.uint64(0x0000FFFF0000FFFF)
_K8 = np.uint64(0x00FF00FF00FF00FF)
_S = tuple(np.uint64(i) for i in range(33))


@njit(cache=True, nogil=True, inline="always")
def _swap(a, b, s, mask):
    # delta swap: exchanges the bits of ``a >> s`` and ``b`` selected by ``mask``
    t = ((a >> s) ^ b) & mask
    return a ^ (t << s), b ^ t


@njit(cache=True, nogil=True, inline="always")
def _nibbles(a, b, c, d):
    # bit planes of weight 1, 2, 4, 8 (bit p = pixel p) -> n_r with nibble t = count of pixel 4t + r
    e = (a & _M55) | ((b & _M55) << _S[1])  # 2-bit fields at 2s: A + 2B of pixel 2s
    o = ((a >> _S[1]) & _M55) | (b & _MAA)  # ... of pixel 2s + 1
    e2 = (c & _M55) | ((d & _M55) << _S[1])
    o2 = ((c >> _S[1]) & _M55) | (d & _MAA)
    n0 = (e & _M33) | ((e2 & _M33) << _S[2])
    n1 = (o & _M33) | ((o2 & _M33) << _S[2])
    n2 = ((e >> _S[2]) & _M33) | (e2 & _MCC)
    n3 = ((o >> _S[2]) & _M33) | (o2 & _MCC)
    return n0, n1, n2, n3


@njit(cache=True, nogil=True)
def _count_kernel(buf, offsets, f0, f1, w0, w1, r0, r1, row_bytes, chunk_rows, segs, flip_v, flip_h, accumulate, out):
    """Count frames ``offsets[w, f0:f1]`` for windows ``w0..w1`` and storage rows ``r0..r1``.

    ``out[w]`` receives (or, with ``accumulate``, adds) the counts of window ``w``; see the module
    docstring for the layout. ``f1 - f0`` must be at most 255.
    """
    n_per = f1 - f0
    eight = n_per > 15
    n_out_rows = out.shape[1]
    w_out = out.shape[2]
    w_store = row_bytes * 8
    cb = chunk_rows * row_bytes
    nwords = (cb + 7) // 8
    nbytes = nwords * 8
    # separate local arrays, so that LLVM knows they do not alias and vectorises the loops
    p0 = np.zeros(nbytes, np.uint8)
    p1 = np.zeros(nbytes, np.uint8)
    p2 = np.zeros(nbytes, np.uint8)
    p3 = np.zeros(nbytes, np.uint8)
    p4 = np.zeros(nbytes, np.uint8)
    p5 = np.zeros(nbytes, np.uint8)
    p6 = np.zeros(nbytes, np.uint8)
    p7 = np.zeros(nbytes, np.uint8)
    q0 = p0.view(np.uint64)
    q1 = p1.view(np.uint64)
    q2 = p2.view(np.uint64)
    q3 = p3.view(np.uint64)
    q4 = p4.view(np.uint64)
    q5 = p5.view(np.uint64)
    q6 = p6.view(np.uint64)
    q7 = p7.view(np.uint64)
    cnt = np.zeros(nwords * 64, np.uint8)  # one count per pixel (< 256 per pass); widened on copy-out
    cnt64 = cnt.view(np.uint64)
    n_segs = segs.shape[0]
    for w in range(w0, w1):
        for rs in range(r0, r1, chunk_rows):
            re = min(rs + chunk_rows, r1)
            nb = (re - rs) * row_bytes
            nw = (nb + 7) // 8
            for i in range(nw * 8):
                p0[i] = 0
                p1[i] = 0
                p2[i] = 0
                p3[i] = 0
            if eight:
                for i in range(nw * 8):
                    p4[i] = 0
                    p5[i] = 0
                    p6[i] = 0
                    p7[i] = 0
            # 1. ripple-carry add of each frame's bytes into the bit planes
            for f in range(f0, f1):
                base = offsets[w, f] + rs * row_bytes
                src = buf[base:base + nb]
                if eight:
                    for i in range(nb):
                        x = src[i]
                        a = p0[i]
                        p0[i] = a ^ x
                        x = a & x
                        a = p1[i]
                        p1[i] = a ^ x
                        x = a & x
                        a = p2[i]
                        p2[i] = a ^ x
                        x = a & x
                        a = p3[i]
                        p3[i] = a ^ x
                        x = a & x
                        a = p4[i]
                        p4[i] = a ^ x
                        x = a & x
                        a = p5[i]
                        p5[i] = a ^ x
                        x = a & x
                        a = p6[i]
                        p6[i] = a ^ x
                        x = a & x
                        p7[i] = p7[i] | x
                else:
                    for i in range(nb):
                        x = src[i]
                        a = p0[i]
                        p0[i] = a ^ x
                        x = a & x
                        a = p1[i]
                        p1[i] = a ^ x
                        x = a & x
                        a = p2[i]
                        p2[i] = a ^ x
                        x = a & x
                        p3[i] = p3[i] | x
            # 2. planes -> uint8 counts in pixel order
            for q in range(nw):
                n0, n1, n2, n3 = _nibbles(q0[q], q1[q], q2[q], q3[q])
                if eight:
                    m0, m1, m2, m3 = _nibbles(q4[q], q5[q], q6[q], q7[q])
                    c0 = (n0 & _M0F) | ((m0 & _M0F) << _S[4])
                    c1 = (n1 & _M0F) | ((m1 & _M0F) << _S[4])
                    c2 = (n2 & _M0F) | ((m2 & _M0F) << _S[4])
                    c3 = (n3 & _M0F) | ((m3 & _M0F) << _S[4])
                    c4 = ((n0 >> _S[4]) & _M0F) | (m0 & _MF0)
                    c5 = ((n1 >> _S[4]) & _M0F) | (m1 & _MF0)
                    c6 = ((n2 >> _S[4]) & _M0F) | (m2 & _MF0)
                    c7 = ((n3 >> _S[4]) & _M0F) | (m3 & _MF0)
                else:
                    c0 = n0 & _M0F
                    c1 = n1 & _M0F
                    c2 = n2 & _M0F
                    c3 = n3 & _M0F
                    c4 = (n0 >> _S[4]) & _M0F
                    c5 = (n1 >> _S[4]) & _M0F
                    c6 = (n2 >> _S[4]) & _M0F
                    c7 = (n3 >> _S[4]) & _M0F
                # c_j byte m = count of pixel 64q + 8m + j; transpose so that word m byte j holds it
                c0, c4 = _swap(c0, c4, _S[32], _K32)
                c1, c5 = _swap(c1, c5, _S[32], _K32)
                c2, c6 = _swap(c2, c6, _S[32], _K32)
                c3, c7 = _swap(c3, c7, _S[32], _K32)
                c0, c2 = _swap(c0, c2, _S[16], _K16)
                c1, c3 = _swap(c1, c3, _S[16], _K16)
                c4, c6 = _swap(c4, c6, _S[16], _K16)
                c5, c7 = _swap(c5, c7, _S[16], _K16)
                c0, c1 = _swap(c0, c1, _S[8], _K8)
                c2, c3 = _swap(c2, c3, _S[8], _K8)
                c4, c5 = _swap(c4, c5, _S[8], _K8)
                c6, c7 = _swap(c6, c7, _S[8], _K8)
                b = 8 * q
                cnt64[b] = c0
                cnt64[b + 1] = c1
                cnt64[b + 2] = c2
                cnt64[b + 3] = c3
                cnt64[b + 4] = c4
                cnt64[b + 5] = c5
                cnt64[b + 6] = c6
                cnt64[b + 7] = c7
            # 3. rows -> output, with flips and column segments (explicit loops vectorise; slices do not)
            for r in range(rs, re):
                orow = n_out_rows - 1 - r if flip_v else r
                o = out[w, orow]
                rb = (r - rs) * w_store
                for s in range(n_segs):
                    sc = rb + segs[s, 0]
                    dc = segs[s, 1]
                    ln = segs[s, 2]
                    # slices + 0-based range indices: no negative-index checks, so LLVM vectorises
                    cs = cnt[sc:sc + ln]
                    if flip_h:
                        # separate variable: a reversed view has 'A' layout, which would de-optimise
                        # the contiguous branch if they shared a name
                        odr = o[w_out - dc - ln:w_out - dc][::-1]
                        if accumulate:
                            for j in range(ln):
                                odr[j] += cs[j]
                        else:
                            for j in range(ln):
                                odr[j] = cs[j]
                    else:
                        od = o[dc:dc + ln]
                        if accumulate:
                            for j in range(ln):
                                od[j] += cs[j]
                        else:
                            for j in range(ln):
                                od[j] = cs[j]


# ----------------------------------------------------------------------------- thread pool
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()
_N_THREADS: int | None = None


def default_threads() -> int:
    """Worker threads used by the counting kernels: ``$SPIKEVIEW_THREADS`` or the usable CPUs (≤ 8)."""
    env = os.environ.get("SPIKEVIEW_THREADS")
    if env and env.isdigit() and int(env) > 0:
        return int(env)
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(8, n))


def set_threads(n: int | None) -> None:
    """Set the number of counting threads (``None``: :func:`default_threads`)."""
    global _POOL, _N_THREADS
    with _POOL_LOCK:
        if _POOL is not None:
            _POOL.shutdown(wait=True)
            _POOL = None
        _N_THREADS = None if n is None else max(1, int(n))


def _pool() -> tuple[ThreadPoolExecutor | None, int]:
    global _POOL, _N_THREADS
    with _POOL_LOCK:
        if _N_THREADS is None:
            _N_THREADS = default_threads()
        if _N_THREADS > 1 and _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=_N_THREADS, thread_name_prefix="spikeview-count")
        return _POOL, _N_THREADS


def _split(n: int, parts: int) -> list[tuple[int, int]]:
    edges = np.linspace(0, n, parts + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


# ----------------------------------------------------------------------------- public entry
def count_frames(buf: np.ndarray, offsets: np.ndarray, *, row_bytes: int, n_rows: int, segments: np.ndarray,
                 width: int, flip_vertical: bool, flip_horizontal: bool, out: np.ndarray | None = None) -> np.ndarray:
    """Spike counts per pixel for windows of frames stored packed in ``buf``.

    Args:
        buf: 1-D uint8 array (memmap or in-memory bytes) holding the frames.
        offsets: ``(n_windows, n_per_window)`` int64 byte offsets of each frame's first byte.
            Every frame of a window is counted into that window's output.
        row_bytes: bytes per storage row (``row_bytes * 8`` pixels, least significant bit first).
        n_rows: storage rows per frame (the output height).
        segments: ``(n, 3)`` int64 rows ``(src_col, dst_col, length)``: which storage columns are
            copied to which output columns.
        width: output width in pixels.
        flip_vertical, flip_horizontal: output row ``n_rows-1-r`` / mirrored columns.
        out: optional C-contiguous ``(n_windows, n_rows, width)`` array of the returned dtype
            to fill (reusing one buffer avoids page faults on fresh memory).

    Returns:
        ``(n_windows, n_rows, width)`` counts, uint16 when windows hold at most 65,535 frames,
        else uint32.
    """
    buf = np.asarray(buf)
    if isinstance(buf, np.memmap):
        buf = buf.view(np.ndarray)
    offsets = np.ascontiguousarray(offsets, dtype=np.int64)
    if offsets.ndim != 2:
        raise ValueError("offsets must be 2-D (n_windows, n_per_window)")
    n_win, n_per = offsets.shape
    if n_win and n_per and (offsets.min() < 0 or offsets.max() + n_rows * row_bytes > buf.size):
        raise ValueError("frame offsets run past the end of the buffer")
    dtype = np.uint16 if n_per <= _MAX_UINT16_FRAMES else np.uint32
    if out is None:
        out = np.empty((n_win, n_rows, width), dtype=dtype)
    elif out.shape != (n_win, n_rows, width) or not out.flags.c_contiguous or out.dtype != dtype:
        raise ValueError(f"out must be a C-contiguous {np.dtype(dtype).name} array of shape {(n_win, n_rows, width)}")
    if n_win == 0:
        return out
    if n_per == 0:
        out[...] = 0
        return out
    if dtype == np.uint32:
        # the kernel counts in uint16 (one compiled variant): sum uint16 parts of <= 65535 frames
        out[...] = 0
        for g0 in range(0, n_per, _MAX_UINT16_FRAMES):
            part = count_frames(buf, offsets[:, g0:g0 + _MAX_UINT16_FRAMES], row_bytes=row_bytes, n_rows=n_rows,
                                segments=segments, width=width, flip_vertical=flip_vertical,
                                flip_horizontal=flip_horizontal)
            out += part
        return out
    segs = np.ascontiguousarray(segments, dtype=np.int64).reshape(-1, 3)
    chunk_rows = max(1, _CHUNK_BYTES // row_bytes)
    pool, n_threads = _pool()
    if n_threads > 1 and pool is not None and n_win >= n_threads:
        tasks = [(a, b, 0, n_rows) for a, b in _split(n_win, n_threads)]
    elif n_threads > 1 and pool is not None and n_rows >= 2 * chunk_rows:
        # split rows on chunk boundaries so that every task keeps full-size chunks
        n_chunks = -(-n_rows // chunk_rows)
        tasks = [(0, n_win, a * chunk_rows, min(b * chunk_rows, n_rows)) for a, b in _split(n_chunks, n_threads)]
    else:
        tasks = [(0, n_win, 0, n_rows)]
    for f0 in range(0, n_per, MAX_FRAMES_PER_PASS):
        f1 = min(f0 + MAX_FRAMES_PER_PASS, n_per)
        acc = f0 > 0
        args = [(buf, offsets, f0, f1, w0, w1, r0, r1, row_bytes, chunk_rows, segs, bool(flip_vertical),
                 bool(flip_horizontal), acc, out) for (w0, w1, r0, r1) in tasks]
        if len(args) == 1:
            _count_kernel(*args[0])
        else:
            futures = [pool.submit(_count_kernel, *a) for a in args]
            for fut in futures:
                fut.result()
    return out


def warm_up() -> None:
    """Load the counting kernel (numba's on-disk cache, or a compile) in the calling thread, for the argument
    types a file source passes (a read-only byte buffer). Loading takes the interpreter lock for tens of ms:
    done by the app's window before its workers start, a first file open no longer stalls the window on it."""
    buf = np.zeros(64, dtype=np.uint8)
    buf.flags.writeable = False
    count_frames(buf, np.zeros((1, 2), dtype=np.int64), row_bytes=2, n_rows=2, segments=np.array([[0, 0, 16]]), width=16,
                 flip_vertical=True, flip_horizontal=False)
