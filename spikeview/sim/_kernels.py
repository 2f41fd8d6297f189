"""Numba kernels of the simulator: counter-based random numbers, integrate-and-fire, warps, fans.

Imported lazily (numba costs about a second to import and compiles on first use; compiled code is
cached next to this file). Nothing here validates its inputs: the callers in
:mod:`spikeview.sim.simulator` and :mod:`spikeview.sim.scenes` do.

Random numbers are *counter-based*: the value for (tick, pixel, draw) is a hash of those indices
and a key derived from the seed (the SplitMix64 output function). So a run is bit-identical for a
seed whatever the chunk size or the number of threads, with no random state to carry around.
"""

from __future__ import annotations

import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2**-53
_S52 = np.uint64(52)
_S20 = np.uint64(20)
_S8 = np.uint64(8)
_MASK32 = np.uint64(0xFFFFFFFF)
_MASK12 = np.uint64(0xFFF)
_MASK8 = np.uint64(0xFF)
_INV32 = 1.0 / 4294967296.0
_INV8 = 1.0 / 256.0

#: the photo-electron count of a tick is drawn exactly (Knuth) below this mean, from the normal
#: approximation N(λ, λ) above it (the two differ by < 1 % in every quantile used here at λ = 20)
POISSON_EXACT_BELOW = 20.0
_KNUTH_MAX_DRAWS = 64


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, inline="always")
def _uniform(key, index):
    """Uniform float64 in [0, 1) for a counter ``index`` (uint64) under ``key`` (uint64)."""
    return np.float64(_mix(key + index * _GOLDEN) >> _S11) * _INV53


def normal_table(bits: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Inverse normal CDF at the centres of ``2**bits`` equal cells of (0, 1), and its steps.

    Returns ``(table, step)``, both ``(2**bits,)`` float64: a normal is drawn as
    ``table[j] + f * step[j]`` with ``j`` a random cell and ``f`` uniform in [0, 1) (linear
    interpolation of the quantile function). With 4096 cells the quantiles are exact to about
    1e-4 σ in the body and the draws are bounded by ±3.67 σ (a 1-in-4,000 tail is folded
    in), which neither the shot noise nor the threshold jitter can show in a spike stream. It
    is ten times faster than Box-Muller here, because it vectorises.
    """
    from scipy.special import ndtri

    n = 1 << bits
    centres = (np.arange(n + 1, dtype=np.float64) + 0.5) / (n + 1)
    q = ndtri(centres)
    return np.ascontiguousarray(q[:-1]), np.ascontiguousarray(np.diff(q))


@njit(cache=True, inline="always")
def _if_row(y, planes, ia, ib, wts, tick0, drive, dark, cap_ratio, theta, volt, fired, out,
            key_noise, key_knuth, ne0, shot, jitter_std, reset_factor, table, step):
    wd = drive.shape[1]
    npix = np.uint64(drive.shape[0] * wd)
    use_rng = shot or jitter_std > 0.0
    inv_ne0 = 1.0 / ne0
    qbuf = np.empty(wd, dtype=np.float64)
    zbuf = np.zeros(wd, dtype=np.float64)
    for t in range(ia.shape[0]):
        pa = planes[ia[t], y]
        pb = planes[ib[t], y]
        w = wts[t]
        base = (np.uint64(tick0) + np.uint64(t)) * npix + np.uint64(y * wd)
        # pass 1: expected charge of the tick in threshold units (photo-current + dark current)
        qmin = np.inf
        for x in range(wd):
            q = max(drive[y, x] * ((1.0 - w) * pa[x] + w * pb[x]) + dark[y, x], 0.0)
            qbuf[x] = q
            qmin = min(qmin, q)
        if use_rng:
            # pass 2 (vectorised): two normals from one 64-bit hash of (seed, tick, pixel): bits
            # 52-63 pick a table cell and bits 20-51 place within it for the jitter; bits 8-19
            # and 0-7 likewise for the shot noise (normal approximation of Poisson(λ = q·ne0))
            if shot:
                for x in range(wd):
                    bits = _mix(key_noise + (base + np.uint64(x)) * _GOLDEN)
                    j1 = np.int64(bits >> _S52)
                    f1 = np.float64(np.int64((bits >> _S20) & _MASK32)) * _INV32
                    zbuf[x] = table[j1] + f1 * step[j1]
                    j2 = np.int64((bits >> _S8) & _MASK12)
                    f2 = np.float64(np.int64(bits & _MASK8)) * _INV8
                    q = qbuf[x]
                    qbuf[x] = max(q + math.sqrt(q * inv_ne0) * (table[j2] + f2 * step[j2]), 0.0)
            else:
                for x in range(wd):
                    bits = _mix(key_noise + (base + np.uint64(x)) * _GOLDEN)
                    j1 = np.int64(bits >> _S52)
                    f1 = np.float64(np.int64((bits >> _S20) & _MASK32)) * _INV32
                    zbuf[x] = table[j1] + f1 * step[j1]
            if shot and qmin * ne0 < POISSON_EXACT_BELOW:
                # pass 3 (rare: dark pixels only): exact Poisson draws, by Knuth's product of
                # uniforms, where the mean electron count is too small for the normal approximation
                for x in range(wd):
                    lam = ne0 * max(drive[y, x] * ((1.0 - w) * pa[x] + w * pb[x]) + dark[y, x], 0.0)
                    if lam < POISSON_EXACT_BELOW:
                        idx = (base + np.uint64(x)) * np.uint64(_KNUTH_MAX_DRAWS)
                        limit = math.exp(-lam)
                        p = 1.0
                        n = -1.0
                        for j in range(_KNUTH_MAX_DRAWS):
                            n += 1.0
                            p *= _uniform(key_knuth, idx + np.uint64(j))
                            if p <= limit:
                                break
                        qbuf[x] = n * inv_ne0
        # pass 4: integrate and fire, branch-free (spikes are unpredictable; branches cost ~5x)
        for x in range(wd):
            dv = qbuf[x] * cap_ratio[y, x] * (1.0 - (1.0 - reset_factor) * fired[y, x])
            v = volt[y, x] + dv
            th = theta[y, x]
            s = v >= th + jitter_std * zbuf[x]
            out[t, y, x] = s
            fired[y, x] = s
            # reset by subtraction; the photodiode holds at most one threshold beyond the reset level
            volt[y, x] = min(v - th * s, th)


@njit(cache=True, nogil=True)
def integrate_fire(planes, ia, ib, wts, tick0, drive, dark, cap_ratio, theta, volt, fired, out,
                   key_noise, key_knuth, ne0, shot, jitter_std, reset_factor, table, step, y0, y1):
    """Advance the photosites of rows ``[y0, y1)`` by ``n = len(ia)`` ticks of integrate-and-fire.

    Releases the GIL: :func:`run_rows` runs bands of rows in threads (rows are independent, and
    the random numbers depend only on (seed, tick, pixel), so results are bit-identical).

    Args:
        planes: (K, H, W) float32 mosaicked linear intensity key planes (the channel each
            photosite sees, or its luminance for monochrome sensors).
        ia, ib: (n,) int64 key planes of each tick; wts: (n,) float64 blend weights, so tick t sees
            ``(1 - wts[t]) * planes[ia[t]] + wts[t] * planes[ib[t]]``.
        tick0: absolute index of the first tick (keys the counter-based random numbers).
        drive: (H, W) float32 threshold units per tick at intensity 1 (rate · spectral gain · PRNU).
        dark: (H, W) float32 dark charge per tick in threshold units (0 when off).
        cap_ratio: (H, W) float32 nominal / actual capacitance (1 when off).
        theta: (H, W) float32 pixel threshold in units of the nominal threshold (1 when off).
        volt: (H, W) float64 integrator state in units of the nominal threshold (updated).
        fired: (H, W) uint8, 1 where the pixel fired on the previous tick (updated).
        out: (n, H, W) uint8 spikes (written).
        key_noise, key_knuth: uint64 stream keys.
        ne0: photo-electrons per nominal threshold (scale of the shot noise).
        shot: draw the electron count of each tick from a Poisson law.
        jitter_std: per-comparison threshold jitter in threshold units (0 = off).
        reset_factor: integration factor of the tick right after a reset (1 = off).
        table, step: :func:`normal_table` (4096 cells: the bit layout above assumes 12 bits).
    """
    for y in range(y0, y1):
        _if_row(y, planes, ia, ib, wts, tick0, drive, dark, cap_ratio, theta, volt, fired, out,
                key_noise, key_knuth, ne0, shot, jitter_std, reset_factor, table, step)


def run_rows(kernel, height: int, n_threads: int, *args) -> None:
    """Call ``kernel(*args, y0, y1)`` over bands of rows, in ``n_threads`` threads when > 1."""
    if n_threads <= 1 or height < 2 * n_threads:
        kernel(*args, 0, height)
        return
    pool = _pool(n_threads)
    edges = np.linspace(0, height, n_threads + 1).round().astype(int)
    futures = [pool.submit(kernel, *args, int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    for f in futures:
        f.result()


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOL_LOCK = threading.Lock()


def _pool(n: int) -> ThreadPoolExecutor:
    with _POOL_LOCK:
        pool = _POOLS.get(n)
        if pool is None:
            pool = _POOLS[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="spikeview-sim")
        return pool


def default_threads() -> int:
    """Threads for large frames: ``$SPIKEVIEW_THREADS`` or the usable CPUs (at most 8)."""
    env = os.environ.get("SPIKEVIEW_THREADS", "")
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(8, n))


@njit(cache=True, inline="always")
def _mirror(i, n):
    """Index ``i`` reflected into [0, n) (symmetric boundary, period 2n)."""
    p = 2 * n
    i = i % p
    if i < 0:
        i += p
    if i >= n:
        i = p - 1 - i
    return i


@njit(cache=True, inline="always")
def _warp_row(y, src, out, m00, m01, m10, m11, tx, ty):
    h, w = src.shape[0], src.shape[1]
    sx = m01 * y + tx
    sy = m11 * y + ty
    for x in range(out.shape[1]):
        x0f = math.floor(sx)
        y0f = math.floor(sy)
        fx = np.float32(sx - x0f)
        fy = np.float32(sy - y0f)
        x0 = np.int64(x0f)
        y0 = np.int64(y0f)
        if 0 <= x0 and x0 + 1 < w and 0 <= y0 and y0 + 1 < h:
            x1 = x0 + 1
            y1 = y0 + 1
        else:
            x1 = _mirror(x0 + 1, w)
            y1 = _mirror(y0 + 1, h)
            x0 = _mirror(x0, w)
            y0 = _mirror(y0, h)
        gx = np.float32(1.0) - fx
        gy = np.float32(1.0) - fy
        for c in range(3):
            top = gx * src[y0, x0, c] + fx * src[y0, x1, c]
            bot = gx * src[y1, x0, c] + fx * src[y1, x1, c]
            out[y, x, c] = gy * top + fy * bot
        sx += m00
        sy += m10


@njit(cache=True, nogil=True)
def warp_affine(src, out, m00, m01, m10, m11, tx, ty, y0, y1):
    """Bilinear resampling with mirrored borders: ``out[y, x] = src(M · (x, y) + t)`` for rows ``[y0, y1)``.

    Args:
        src: (h, w, 3) float32 source image.
        out: (H, W, 3) float32 destination (written).
        m00, m01, m10, m11, tx, ty: source x = m00·x + m01·y + tx, source y = m10·x + m11·y + ty
            (pixel-centre coordinates).
        y0, y1: the rows to render (see :func:`run_rows`).
    """
    for y in range(y0, y1):
        _warp_row(y, src, out, m00, m01, m10, m11, tx, ty)


@njit(cache=True, inline="always")
def _clip01(v):
    return 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)


@njit(cache=True)
def draw_fan(out, cx, cy, radius, hub_radius, n_blades, blade_fraction, phase, colours, hub_colour):
    """Draw an anti-aliased fan over ``out`` (H, W, 3) float32, in place.

    Args:
        cx, cy: centre in pixel coordinates.
        radius, hub_radius: outer and hub radii in pixels.
        n_blades: number of blades; blade k starts at angle ``phase + 2πk/n_blades``.
        blade_fraction: fraction of the circle covered by blades (0–1).
        phase: rotation in radians (angles grow clockwise on screen, rows pointing down).
        colours: (n_blades, 3) float32 blade colours (linear RGB), shaded darker towards the hub.
        hub_colour: (3,) float32 hub colour.
    """
    hh, ww = out.shape[0], out.shape[1]
    sector = 2.0 * math.pi / n_blades
    wb = blade_fraction * sector
    y_lo = max(0, int(math.floor(cy - radius - 1)))
    y_hi = min(hh, int(math.ceil(cy + radius + 2)))
    x_lo = max(0, int(math.floor(cx - radius - 1)))
    x_hi = min(ww, int(math.ceil(cx + radius + 2)))
    for y in range(y_lo, y_hi):
        for x in range(x_lo, x_hi):
            dx = x - cx
            dy = y - cy
            r = math.sqrt(dx * dx + dy * dy)
            cov_r = _clip01(radius - r + 0.5)
            if cov_r <= 0.0:
                continue
            rel = (math.atan2(dy, dx) - phase) % (2.0 * math.pi)
            k = int(rel // sector)
            within = rel - k * sector
            if within < wb:
                d = min(within, wb - within) * r
                blade = k
            else:
                d = -min(within - wb, sector - within) * r
                blade = k if within - wb < sector - within else k + 1
            blade = blade % n_blades
            cov = cov_r * _clip01(0.5 + d)
            shade = 0.55 + 0.45 * (r / radius)
            cov_h = _clip01(hub_radius - r + 0.5)
            for c in range(3):
                v = (1.0 - cov) * out[y, x, c] + cov * colours[blade, c] * shade
                out[y, x, c] = (1.0 - cov_h) * v + cov_h * hub_colour[c]
