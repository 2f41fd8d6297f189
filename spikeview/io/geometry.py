"""Guessing the geometry of a plain ``.dat`` file that has no sidecar, and checking a given one.

A plain file has no header: only its size is known, and many ``width × height`` pairs divide it.
The file's own bits say which one is right, from two facts about real captures:

1. **Frame size: a pixel keeps its firing rate from tick to tick.** Cut a block of the file into
   frames of a candidate size and average the spike counts of each byte position over those
   frames. At the true frame size (or a multiple of it) a position is always the same 8 pixels,
   so the average keeps the scene's spatial variation; at any other size a position wanders over
   the scene and the variation averages away (:func:`frame_signal`: the covariance of the averages
   of the first and the second half of the frames, which the tick-to-tick noise does not reach). The frame size is the *smallest* one that keeps at least 90 % of the best signal
   (multiples keep it too: this is the "many ticks rather than one" rule).
2. **Width: images are smooth in space, so rows line up.** For each width that fits the frame
   size, the firing-rate image (spikes summed over up to 8 MB of frames, horizontal neighbours
   added to hide a Bayer pattern) is correlated with itself 1–4 rows down, less its correlation
   half or a third of a row along (:func:`spatial_score`). At the right width the row below
   matches better than anything along the row; at twice the width each "row" holds two real
   rows side by side, so half a row along matches as well and the score falls to about 0; at
   half the width, every other "row" below is half a real row along and matches little.

Integrate-and-fire pixels mark the frame size more directly, flat scenes included: a pixel whose
voltage resets by a threshold after each spike fires on two consecutive ticks less often than
chance, so at the true frame size a bit and the bit one frame later co-fire clearly less often than
their neighbours do (:func:`tick_correlation`, about −0.2 … −0.75 on simulator and Spike-Zoo
captures, about 0 at other sizes). When a frame size shows it, the smallest such size goes first
(:func:`tick_frame_size`; Bernoulli spikes show nothing and keep the ranking above). With a colour
filter, the rows are scored at every width with the filter's 2×2 pattern taken out where it is
sharpest, so the filter's own row pattern does not line up the rows at twice the width.

Ties fall back on known sensor sizes (1000×1000, 400×250), then square and common aspect ratios;
when the file shows no scene at all (black, uniform or random) the order is known sizes, common
shapes, then more ticks. Only a sample is read (a 2 MB block, then up to 8 MB of frames), so
ranking a 1 GB file takes well under a second (``benchmarks/bench_geometry.py``).

:func:`rate_warnings` uses the same measures on an opened stream to say when the rates suggest a
wrong width, colour filter phase or flip.
"""

from __future__ import annotations

import bisect
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: plain-file geometries of known sensors, as (width, height)
KNOWN_SIZES: tuple[tuple[int, int], ...] = ((1000, 1000), (400, 250))
#: a known sensor size that does not divide the file is still a candidate with this many whole frames
PARTIAL_MIN_FRAMES = 8
#: common aspect ratios (w, h) preferred on ties
COMMON_ASPECTS: tuple[tuple[int, int], ...] = ((1, 1), (4, 3), (3, 2), (16, 9), (8, 5), (5, 4), (2, 1))
#: widest aspect ratio considered (either way); known sizes are always considered
MAX_ASPECT = 4.0
#: smallest side considered (pixels)
MIN_SIDE = 8
#: largest frame considered (bytes): 16 megapixels, far above any spike sensor (1 megapixel)
MAX_FRAME_BYTES = 2 << 20
#: bytes of the file read to measure the spatial score
SAMPLE_BYTES = 8 << 20
#: bytes folded at every candidate frame size to find the frame size
BLOCK_BYTES = 2 << 20
#: a frame size whose signal reaches this fraction of the best is consistent with the file
TEMPORAL_TOLERANCE = 0.9

_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.float32)


@dataclass
class GeometryGuess:
    """One candidate geometry of a plain file, with its plausibility.

    Attributes:
        width, height: frame size in pixels.
        n_frames: whole frames the file holds at this size.
        temporal: tick-to-tick correlation at this frame size, relative to the best frame size
            (1 = as good as the best; 0 when there is a single frame).
        spatial: mean correlation of the rate image with itself 1–4 rows down (−1 … 1).
        known: a known sensor size.
        pattern: sharpness of a colour filter's 2×2 site pattern at this width, relative to the
            sharpest width of the same frame size (0 when the file shows no filter pattern).
        reasons: short phrases for people ("known sensor size", "rows line up" …).
        trailing: bytes after the last whole frame (a known sensor size in a file cut short; 0 when
            the frames divide the file).
    """

    width: int
    height: int
    n_frames: int
    temporal: float = 0.0
    spatial: float = 0.0
    known: bool = False
    reasons: list[str] = field(default_factory=list)
    pattern: float = 0.0
    trailing: int = 0

    @property
    def size(self) -> tuple[int, int]:
        return (self.width, self.height)

    def describe(self) -> str:
        return f"{self.width}x{self.height} ({self.n_frames} ticks)"


def _factorise(n: int) -> dict[int, int]:
    out: dict[int, int] = {}
    d = 2
    while d * d <= n:
        while n % d == 0:
            out[d] = out.get(d, 0) + 1
            n //= d
        d += 1 if d == 2 else 2
    if n > 1:
        out[n] = out.get(n, 0) + 1
    return out


def _divisors(n: int) -> list[int]:
    divs = [1]
    for p, e in _factorise(n).items():
        divs = [d * p**k for d in divs for k in range(e + 1)]
    return sorted(divs)


def candidate_sizes(size: int) -> list[tuple[int, int]]:
    """Every ``(width, height)`` whose plain frames divide ``size`` bytes exactly.

    Both sides at least :data:`MIN_SIDE`, an aspect ratio within :data:`MAX_ASPECT`, frames of at
    most :data:`MAX_FRAME_BYTES` (known sensor sizes always included when they fit). Not ranked.
    """
    out: set[tuple[int, int]] = {(w, h) for (w, h) in KNOWN_SIZES if size > 0 and size % (w * h // 8) == 0}
    if size <= 0:
        return sorted(out)
    widths = _divisors(8 * size)  # every width is a divisor of 8·frame_bytes, hence of 8·size
    for fb in _divisors(size):
        pixels = 8 * fb
        if pixels < MIN_SIDE * MIN_SIDE or fb > MAX_FRAME_BYTES:
            continue
        lo = max(MIN_SIDE, math.ceil(math.sqrt(pixels / MAX_ASPECT)))
        hi = math.isqrt(int(pixels * MAX_ASPECT))
        for w in widths[bisect.bisect_left(widths, lo):bisect.bisect_right(widths, hi)]:
            if pixels % w == 0 and pixels // w >= MIN_SIDE:
                out.add((w, pixels // w))
    return sorted(out)


def _prior(w: int, h: int) -> float:
    """Small tie-breaking bonus: known sensor sizes, then square and common aspect ratios."""
    if (w, h) in KNOWN_SIZES:
        return 0.1
    if w == h:
        return 0.04
    g = math.gcd(w, h)
    if (w // g, h // g) in COMMON_ASPECTS or (h // g, w // g) in COMMON_ASPECTS:
        return 0.03 if w >= h else 0.02
    return 0.0


def read_block(buf: np.ndarray, n_bytes: int = BLOCK_BYTES) -> np.ndarray:
    """Spike counts per byte (0 … 8, float32) of a contiguous block from the middle of ``buf``."""
    n = min(int(n_bytes), buf.size)
    start = (buf.size - n) // 2
    return _POPCOUNT[buf[start:start + n]]


def frame_signal(block: np.ndarray, frame_bytes: int, buf: np.ndarray | None = None) -> float:
    """How much of the scene survives folding the stream at ``frame_bytes`` (spikes² per byte).

    The block of per-byte spike counts is cut into frames of ``frame_bytes`` and averaged over
    them. At the true frame size (or a multiple) every byte position is one set of pixels, so the
    average keeps the scene's full spatial variance; at any other size a position mixes different
    parts of the scene and most of that variance averages away. The estimate is the covariance
    across positions of the averages of the first and the second half of the frames, so noise
    (which differs between the halves) does not count, however it is correlated in time.

    Frames larger than a quarter of the block are taken from ``buf`` instead (a few spread over
    the file), when given.
    """
    m = block.size // frame_bytes
    if m >= 4:
        frames = block[:m * frame_bytes].reshape(m, frame_bytes)
    elif buf is not None and buf.size // frame_bytes >= 4:
        # large frames: the first bytes of a few frames spread over the file (positions are a sample)
        n = buf.size // frame_bytes
        m = min(n, 8)
        part = min(frame_bytes, BLOCK_BYTES // 16)
        idx = np.linspace(0, n - 1, m).astype(np.int64)
        frames = np.stack([_POPCOUNT[buf[i * frame_bytes:i * frame_bytes + part]] for i in idx])
    else:
        return 0.0
    # the covariance between the averages of the first and the second half of the frames: the
    # scene is in both, the tick-to-tick noise in one only (whatever its correlation in time:
    # integrate-and-fire pixels fire almost periodically, so the usual s²/m noise term is wrong)
    half = m // 2
    a = frames[:half].mean(axis=0, dtype=np.float64)
    b = frames[half:2 * half].mean(axis=0, dtype=np.float64)
    return max(0.0, float(np.mean((a - a.mean()) * (b - b.mean()))))


def repeats_within(block: np.ndarray, frame_bytes: int, multiple: int) -> float | None:
    """Whether the stream repeats every ``frame_bytes`` inside frames of ``multiple`` bytes: about 1 if so.

    Folding at a sub-period can keep most of the signal when the scene has little texture: a Bayer
    filter's row pattern repeats every two rows, so a flat colour scene folds as well at a few rows
    as at the whole frame. Only the pixels' own fixed pattern and the scene tell the two apart, and
    they repeat at the true frame size only. Fold at ``multiple`` (a multiple of ``frame_bytes``
    consistent with the file) and compare its consecutive ``frame_bytes`` parts: the covariance of
    part ``j`` (first half of the frames) with part ``j + 1`` (second half), over the covariance of
    each part with itself (the same halves). Noise is in one half only, so it cancels in both.

    Returns:
        The ratio (about 1 when ``frame_bytes`` is a period; the share of the signal that merely
        repeats when it is not), or ``None`` with too few frames to tell.
    """
    m = block.size // multiple
    k = multiple // frame_bytes
    if m < 8 or k < 2:
        return None
    frames = block[:m * multiple].reshape(m, k, frame_bytes)
    half = m // 2
    a = frames[:half].mean(axis=0, dtype=np.float64)
    b = frames[half:2 * half].mean(axis=0, dtype=np.float64)
    a -= a.mean()
    b -= b.mean()
    own = float(np.mean(a * b))
    if own <= 0:
        return None
    cross = float(np.mean(a * np.roll(b, -1, axis=0)))
    return cross / own


def bayer_contrast(rates: np.ndarray, width: int) -> float:
    """Relative spread of the four 2×2 site means of the rate image at ``width`` (0 for odd widths).

    A colour filter gives its four sites clearly different rates at the true width only: at twice
    the width every stored "row" holds two sensor rows (red-green, then green-blue) and at half the
    width two stored rows share one sensor row, so the sites mix and the spread shrinks.
    """
    if width % 2 or rates.size % width:
        return 0.0
    img = rates.reshape(-1, width)
    h = img.shape[0] - img.shape[0] % 2
    if h < 2:
        return 0.0
    sites = np.array([img[py:h:2, px::2].mean(dtype=np.float64) for py in (0, 1) for px in (0, 1)])
    m = float(sites.mean())
    return float(sites.std() / m) if m > 0 else 0.0


#: a 2×2 site spread (:func:`bayer_contrast`) above this is a colour filter's, not chance
BAYER_CONTRAST = 0.08
#: frame sizes whose parts repeat at or above this ratio (:func:`repeats_within`) are a period of the file
REPEAT_TOLERANCE = 0.8
#: a tick-to-tick correlation (:func:`tick_correlation`) below minus this is a pixel's own refractory
#: signature (other frame sizes read no lower than about −0.04 on the simulator's wider set, two seeds)
TICK_EVIDENCE = 0.08
#: bytes compared per frame size for :func:`tick_correlation`: chunks spread over the file
TICK_CHUNK, TICK_CHUNKS = 8192, 8


def tick_correlation(buf: np.ndarray, frame_bytes: int) -> float:
    """Correlation of a bit with the bit ``frame_bytes`` later, less that of its neighbours 8 pixels along.

    Spike pixels integrate and fire: the voltage resets by one threshold after a spike, so a pixel
    firing ``r`` spikes per tick fires on two consecutive ticks with probability ``max(0, 2r − 1)``,
    always below the ``r²`` of independent ticks (its lag-1 correlation is ``−min(r, 1−r) / max(r,
    1−r)``, whatever the scene, also a flat one). At the true frame size a bit and the bit one frame
    later are one pixel on consecutive ticks, so they co-fire clearly less often than chance; at any
    other size that is not a multiple they are two different pixels, with independent phases, which
    co-fire as often as the same bit and the bits one byte (8 pixels) before and after (the control,
    which keeps the scene's rates in both terms). Returns about −0.2 … −0.75 at the frame size of an
    integrate-and-fire capture (a multiple: the lag-k correlation, any sign), about 0 elsewhere, and
    about 0 or a little above at the frame size of Bernoulli spikes, which carry no such signature
    (a pixel keeps its rate, its neighbours 8 pixels along have slightly different ones).
    """
    n = int(buf.size)
    length = min(TICK_CHUNK, n - frame_bytes - 2)
    if frame_bytes < 1 or length < 64:
        return 0.0
    starts = np.unique(np.linspace(1, n - frame_bytes - length - 1, TICK_CHUNKS).astype(np.int64))
    a = np.concatenate([buf[o:o + length] for o in starts])
    b = np.stack([buf[o + frame_bytes - 1:o + frame_bytes + length + 1] for o in starts])
    mid = b[:, 1:-1].ravel()

    def bits(x: np.ndarray) -> float:  # numpy >= 2 counts bits natively; 1.26 (allowed) looks them up
        return float((np.bitwise_count(x) if hasattr(np, "bitwise_count") else _POPCOUNT[x]).sum(dtype=np.int64))

    both = bits(a & mid)
    ctrl = 0.5 * (bits(a & b[:, :-2].ravel()) + bits(a & b[:, 2:].ravel()))
    ones = 0.5 * (bits(a) + bits(mid))
    return (both - ctrl) / (ones - ctrl) if ones > ctrl else 0.0


def tick_frame_size(buf: np.ndarray, frame_sizes) -> tuple[int | None, dict[int, float]]:
    """The frame size an integrate-and-fire capture shows from tick to tick (:func:`tick_correlation`),
    or ``None`` when no size shows it (Bernoulli spikes, a dark or saturated file, a single tick).

    The smallest frame size whose correlation is below −:data:`TICK_EVIDENCE` and at least half the
    strongest: multiples of the frame size compare a pixel with itself a few ticks later and can
    read as low as the frame size itself, other sizes read about 0.
    """
    rho = {fb: tick_correlation(buf, fb) for fb in frame_sizes if buf.size // fb >= 2}
    low = min(rho.values(), default=0.0)
    if low >= -TICK_EVIDENCE:
        return None, rho
    return min(fb for fb, v in rho.items() if v < -TICK_EVIDENCE and v <= 0.5 * low), rho


def rate_vector(buf: np.ndarray, frame_bytes: int, budget: int = SAMPLE_BYTES, runs: int = 4) -> np.ndarray:
    """Mean spikes per tick of every stored pixel (``8·frame_bytes``, storage order) from a sample.

    Reads at most ``budget`` bytes: ``runs`` runs of consecutive frames spread over the file.
    """
    n = buf.size // frame_bytes
    per_run = max(1, min(n // runs if n >= runs else n, budget // (runs * frame_bytes)))
    starts = np.unique(np.linspace(0, n - per_run, min(runs, n)).astype(np.int64))
    total = np.zeros(8 * frame_bytes, dtype=np.float64)
    chunk = max(1, (1 << 20) // frame_bytes)  # unpack about 1 MB at a time
    count = 0
    for s in starts:
        for a in range(int(s), int(s) + per_run, chunk):
            b = min(int(s) + per_run, a + chunk)
            packed = buf[a * frame_bytes:b * frame_bytes].reshape(b - a, frame_bytes)
            total += np.unpackbits(packed, axis=1, bitorder="little").sum(axis=0, dtype=np.uint32)
            count += b - a
    return (total / max(1, count)).astype(np.float32)


def pair_sums(rates: np.ndarray) -> np.ndarray:
    """``rates[p] + rates[p + 1]`` (the last value repeated): hides a Bayer filter's column pattern.

    A colour filter alternates gains from pixel to pixel; summing horizontal neighbours gives
    R+G on one row and G+B on the next, nearly the same gain, so the vertical correlations that
    rank widths measure the scene, not the filter. It needs no width, so every candidate is
    scored on the same values.
    """
    out = np.empty_like(rates)
    out[:-1] = rates[:-1] + rates[1:]
    out[-1] = 2 * rates[-1]
    return out


#: pixel pairs compared per lag (a fixed random subset: enough for three decimals, cheap at 1000×1000)
_PAIRS = 1 << 16


class _Lags:
    """Correlation of a flat rate vector with itself at any lag, on a fixed random subset of pixels."""

    def __init__(self, flat: np.ndarray):
        c = np.asarray(flat, dtype=np.float64).ravel()
        self.c = (c - c.mean()).astype(np.float32)
        self.n = c.size
        self.var = float(np.mean(self.c.astype(np.float64) ** 2))
        rng = np.random.default_rng(self.n)
        self.pos = np.sort(rng.integers(0, self.n, _PAIRS)) if self.n > 2 * _PAIRS else np.arange(self.n)
        self.cache: dict[int, float] = {}

    def __call__(self, lag: int) -> float:
        if lag < 1 or lag >= self.n - 1 or self.var <= 0:
            return 0.0
        if lag not in self.cache:
            pos = self.pos[: np.searchsorted(self.pos, self.n - lag)]
            a, b = self.c[pos], self.c[pos + lag]
            self.cache[lag] = float(np.dot(a, b)) / (len(pos) * self.var) if len(pos) else 0.0
        return self.cache[lag]


def spatial_score(image: np.ndarray, max_lag: int = 4, lags: _Lags | None = None) -> float:
    """How well the rows of a rate image line up: a score in about −1 … 1, higher is better.

    The mean correlation of the image with itself 1 … ``max_lag`` rows down, less the larger
    correlation at a shift of a half or a third of a row. At the right width rows are a peak:
    the row below matches better than a part of a row further along. At twice the right width
    each row holds two real rows side by side, so half a row along matches as well as the row
    below and the score drops to about 0. ``lags`` reuses the correlations of one flat vector
    across the widths tried.
    """
    h, w = image.shape
    corr = lags if lags is not None else _Lags(image)
    steps = [k * w for k in range(1, max_lag + 1) if k < h]
    if not steps:
        return 0.0
    rows = float(np.mean([corr(lag) for lag in steps]))
    part = max(corr(round(w / k)) for k in (2, 3)) if w >= 6 else 0.0
    return rows - max(0.0, part)


def rank_plain_geometries(path: str | os.PathLike[str], *, limit: int | None = 8) -> list[GeometryGuess]:
    """Candidate geometries of a plain ``.dat`` file, most plausible first (see the module docstring).

    Args:
        path: the file (only a sample of it is read).
        limit: at most this many guesses (``None``: all).

    Returns:
        :class:`GeometryGuess` list; empty when no frame size divides the file.

    Raises:
        InputFileError: missing, empty or unreadable file.
    """
    from spikeview.io._base import open_bytes

    _, buf = open_bytes(Path(path), "plain .dat")
    return rank_geometries(buf, limit=limit)


def rank_geometries(buf: np.ndarray, *, limit: int | None = 8) -> list[GeometryGuess]:
    """:func:`rank_plain_geometries` on the bytes of a file (a 1-D uint8 array or memory map)."""
    size = int(buf.size)
    sizes = candidate_sizes(size)
    # a known sensor size is also a candidate when the file ends in a partial tick (a copy or capture cut
    # short): whole frames read, the rest is left out with a warning when the file is opened
    partial = {(w, h) for (w, h) in KNOWN_SIZES if size % (w * h // 8) and size // (w * h // 8) >= PARTIAL_MIN_FRAMES}
    sizes = sorted(set(sizes) | partial)
    if not sizes:
        return []
    by_fb: dict[int, list[tuple[int, int]]] = {}
    for w, h in sizes:
        by_fb.setdefault(w * h // 8, []).append((w, h))
    # 1. frame size: the smallest that keeps the scene when the stream is folded at it
    block = read_block(buf)
    t_raw = {fb: (frame_signal(block, fb, buf) if size // fb >= 4 else 0.0) for fb in by_fb}
    # a scene holds a good part of the per-byte variance; noise alone leaves a few hundredths by chance.
    # A flat scene holds little (only the pixels' fixed pattern), but with many positions and frames even
    # that stands far above the chance level of the estimate: noise variance / (frames / 2) / sqrt(positions)
    var = max(float(block.var()), 1e-12)

    def _chance(fb: int) -> float:
        whole = block.size // fb >= 4
        m = block.size // fb if whole else min(size // fb, 8)
        return var / max(1, m // 2) / math.sqrt(max(1, fb if whole else min(fb, BLOCK_BYTES // 16)))

    chance = {fb: _chance(fb) for fb in t_raw}
    signal = max(t_raw.values()) > 0.05 * var or max(t_raw[fb] / chance[fb] for fb in t_raw) > 20
    # the scale: the best signal, measured where many frames fold (>= 50). Multiples of the frame size
    # folded over a few frames read high: integrate-and-fire pixels fire almost periodically, so every
    # k-th tick of a flat scene can repeat (aliasing) and both halves keep the same offset
    best_t = max(max(t_raw.values()), 1e-30)
    many = [t_raw[fb] for fb in t_raw if block.size // fb >= 50]
    if many and max(many) >= 0.5 * best_t:
        best_t = max(many)
    t_rel = {fb: (min(1.0, v / best_t) if signal else 0.0) for fb, v in t_raw.items()}
    consistent = sorted(fb for fb, v in t_raw.items() if v + 2 * chance[fb] >= TEMPORAL_TOLERANCE * best_t) if signal else []
    # a consistent frame size that the larger consistent ones do not repeat within is only a sub-period
    # (a Bayer row pattern on a flat scene): move it behind the sizes that do repeat
    if len(consistent) > 1:
        def _period(fb: int) -> bool:
            larger = [f for f in consistent if f > fb and f % fb == 0 and block.size // f >= 8]
            ratios = [r for f in larger[:2] if (r := repeats_within(block, fb, f)) is not None]
            return not ratios or min(ratios) >= REPEAT_TOLERANCE
        periods = [fb for fb in consistent if _period(fb)]
        if periods:
            consistent = periods + [fb for fb in consistent if fb not in periods]
    frame_order = consistent + sorted((fb for fb in by_fb if fb not in consistent), key=lambda fb: (-t_rel[fb], fb))
    # an integrate-and-fire capture names its frame size from tick to tick, flat scenes included: it goes first
    tick_fb, _ = tick_frame_size(buf, by_fb)
    if tick_fb is not None:
        frame_order = [tick_fb] + [fb for fb in frame_order if fb != tick_fb]
        signal = True
        t_rel[tick_fb] = 1.0

    # 2. width from the spatial smoothness, for the most plausible frame sizes
    guesses: list[GeometryGuess] = []
    for rank, fb in enumerate(frame_order):
        group = []
        # the best frame size is measured; the next two only when small (they order the rest of the list)
        measure = (rank == 0 and fb <= SAMPLE_BYTES) or (0 < rank < 3 and signal and fb <= SAMPLE_BYTES // 8)
        raw = rate_vector(buf, fb, SAMPLE_BYTES if rank == 0 else SAMPLE_BYTES // 8) if measure else None
        contrast = {w: bayer_contrast(raw, w) for w, _ in by_fb[fb]} if raw is not None else {}
        top = max(contrast.values(), default=0.0)
        if top > BAYER_CONTRAST:  # only a colour filter's signature counts: one diagonal alike (the greens)
            wt = max(contrast, key=contrast.get)
            if guess_cfa(raw.reshape(-1, wt)) is None:
                top = 0.0
        if top > BAYER_CONTRAST:
            # the filter's row pattern (R+G rows, G+B rows) also lines up rows at twice the width: score the
            # rows at every width with the filter taken out where it is sharpest (each site over its mean there)
            img = raw.reshape(-1, wt).astype(np.float64)
            for py in (0, 1):
                for px in (0, 1):
                    m = float(img[py::2, px::2].mean())
                    img[py::2, px::2] /= m if m > 0 else 1.0
            rates = pair_sums(img.ravel())
        else:
            rates = pair_sums(raw) if raw is not None else None
        lags = _Lags(rates) if rates is not None else None
        for w, h in by_fb[fb]:
            g = GeometryGuess(w, h, size // fb, temporal=round(t_rel[fb], 4), known=(w, h) in KNOWN_SIZES,
                              trailing=size % fb)
            if rates is not None:
                g.spatial = round(spatial_score(rates.reshape(h, w), lags=lags), 4)
            if top > BAYER_CONTRAST:  # a colour filter: its 2x2 pattern is sharpest at the true width
                g.pattern = round(contrast[w] / top, 4)
            group.append(g)
        group.sort(key=lambda g: (-(g.spatial + 0.5 * g.pattern + _prior(g.width, g.height)), -g.width))
        guesses += group
    if not signal:  # nothing to measure (a black, uniform or random file): known sizes, common shapes, more ticks
        guesses.sort(key=lambda g: (g.trailing > 0, -_prior(g.width, g.height), -g.n_frames, -g.width))
    for i, g in enumerate(guesses):
        if g.known:
            g.reasons.append("known sensor size")
        if signal and g.temporal >= TEMPORAL_TOLERANCE:
            g.reasons.append("pixels match from tick to tick")
        if g.spatial > 0.3:
            g.reasons.append("rows line up")
        if g.n_frames == 1:
            g.reasons.append("a single tick")
        if g.trailing:
            g.reasons.append(f"{g.trailing} bytes of a partial last tick left out")
    return guesses[:limit] if limit else guesses


# ------------------------------------------------------------------------- checking a stream
def _mean_rates(src, max_ticks: int = 512, windows: int = 8) -> np.ndarray:
    n = src.n_frames
    win = max(1, min(n, max_ticks // windows))
    k = max(1, min(windows, n // win))
    starts = np.linspace(0, n - win, k).round().astype(int)
    total = np.zeros((src.height, src.width), dtype=np.float64)
    for a in starts:
        total += src.count(int(a), int(a) + win)
    return total / (k * win)


def _file_guess(src) -> GeometryGuess | None:
    """The most plausible geometry of the plain file behind ``src`` (``None`` without a file or a scene)."""
    path = getattr(src.info, "path", None)
    if path is None or getattr(src.info, "format", None) != "plain":
        return None
    guesses = rank_plain_geometries(path, limit=1)
    return guesses[0] if guesses and guesses[0].temporal > 0 else None


def _whole_frames(src) -> bool:
    path = getattr(src.info, "path", None)
    if path is None or getattr(src.info, "format", None) != "plain":
        return True
    try:
        return Path(path).stat().st_size % (src.width * src.height // 8) == 0
    except OSError:
        return True


def _imbalance(a: float, b: float) -> float:
    m = (a + b) / 2
    return abs(a - b) / m if m > 0 else 0.0


#: leading bytes of formats people open by mistake
_MAGIC = ((b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
          (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"), (b"BM", "a BMP image"),
          (b"v/1\x01", "an OpenEXR image"), (b"%PDF", "a PDF document"), (b"PK\x03\x04", "a zip archive"),
          (b"\x1f\x8b", "a gzip archive"), (b"\x93NUMPY", "a .npy array without the .npy suffix"))


def not_spike_data(buf: np.ndarray, structure: bool = True) -> str | None:
    """Why the bytes of a file offered as a plain spike stream are not one, or ``None`` if they may be.

    A plain stream has no header, so only what it is not can be told: a known file signature (an
    image, an archive), text (every byte printable), or random bytes with no row structure (each bit
    set half the time, byte values uniform, and no frame size at which pixels repeat from tick to
    tick, :func:`rank_geometries`; only with ``structure``: with the geometry given, a noisy capture is
    the user's to read).
    """
    head = bytes(np.asarray(buf[:16]))
    for magic, what in _MAGIC:
        if head.startswith(magic):
            return what
    if len(head) >= 12 and head[4:8] == b"ftyp":
        return "an MP4/MOV video"
    sample = np.asarray(buf[: 1 << 16])
    if sample.size == 0:
        return None
    text = (sample >= 0x20) & (sample != 0x7F) | np.isin(sample, (0x09, 0x0A, 0x0D))
    if text.all():
        try:
            bytes(sample).decode("utf-8")
            return "it holds text"
        except UnicodeDecodeError:
            pass
    if structure and buf.size >= 4096:
        hist = np.bincount(sample, minlength=256).astype(np.float64)
        expected = sample.size / 256.0
        chi2_stat = float(((hist - expected) ** 2 / expected).sum())
        # uniform bytes: chi-square near its 255 degrees of freedom (p < 1e-6 above about 385)
        if chi2_stat < 400 and not any(g.temporal > 0 for g in rank_geometries(buf, limit=3)):
            return "random bytes with no row structure"
    return None


def guess_cfa(rates: np.ndarray) -> str | None:
    """The colour filter a mean rate image ``(H, W)`` (flips applied) shows, or ``None`` (monochrome).

    A Bayer filter makes its four 2×2 sites fire at clearly different rates while the two greens (one
    diagonal) fire alike: the sites are a filter's when their spread (:func:`bayer_contrast`) exceeds
    :data:`BAYER_CONTRAST` and stands far above the spread of the site means (z > 8), and one diagonal
    is much closer than the other. Green is that diagonal; of the other two, red is taken to be the
    brighter (the usual sensor response; the warning names the alternative). The app's open dialog
    and ``spikeview info`` start from this guess.
    """
    h, w = rates.shape
    he, we = h - h % 2, w - w % 2
    if he < 2 or we < 2:
        return None
    sites = {(py, px): rates[py:he:2, px:we:2].ravel() for py in (0, 1) for px in (0, 1)}
    means = {k: float(v.mean()) for k, v in sites.items()}
    m = float(np.mean(list(means.values())))
    if m <= 0 or bayer_contrast(np.ascontiguousarray(rates[:he, :we]).ravel(), we) <= BAYER_CONTRAST:
        return None
    se = math.sqrt(max(float(v.var()) / max(1, v.size) for v in sites.values()))
    spread = max(means.values()) - min(means.values())
    if se > 0 and spread / se < 8:
        return None
    main = _imbalance(means[(0, 0)], means[(1, 1)])
    anti = _imbalance(means[(0, 1)], means[(1, 0)])
    if anti < 0.5 * main:  # greens on the anti-diagonal: RGGB or BGGR
        return "RGGB" if means[(0, 0)] >= means[(1, 1)] else "BGGR"
    if main < 0.5 * anti:  # greens on the main diagonal: GRBG or GBRG
        return "GRBG" if means[(0, 1)] >= means[(1, 0)] else "GBRG"
    return None


def mean_rates(src, max_ticks: int = 512, windows: int = 8) -> np.ndarray:
    """Mean spikes per tick of every pixel ``(H, W)`` over up to ``max_ticks`` ticks in ``windows``
    windows spread over the stream."""
    return _mean_rates(src, max_ticks, windows)


_ALTERNATIVE = {"RGGB": "BGGR", "BGGR": "RGGB", "GRBG": "GBRG", "GBRG": "GRBG"}


def monochrome_cfa_warning(rates: np.ndarray) -> str | None:
    """The sentence for a stream read as monochrome whose 2×2 sites fire like a colour filter's, naming
    the ``--cfa`` value to use (:func:`guess_cfa`), or ``None``."""
    cfa = guess_cfa(rates)
    if cfa is None:
        return None
    he, we = rates.shape[0] - rates.shape[0] % 2, rates.shape[1] - rates.shape[1] % 2
    site = [float(rates[py:he:2, px:we:2].mean()) for py in (0, 1) for px in (0, 1)]
    return (f"read as monochrome (--cfa none), but its 2x2 sites fire at clearly different rates "
            f"({' / '.join(f'{v:.3f}' for v in site)} spikes per tick), as behind a colour filter: pass --cfa {cfa} "
            f"(or --cfa {_ALTERNATIVE[cfa]} if red and blue come out swapped).")


#: a colour filter's four 2×2 sites fire within this relative spread (:func:`bayer_contrast`) only if the
#: sensor is monochrome (or the scene exactly balanced): a Spike-Zoo clip read as RGGB spreads 0.3 %,
#: a filter's sites tens of percent (the simulator's demo: its gray-world gains deviate 52 % from neutral)
ALIKE_CONTRAST = 0.01


def colour_filter_alike_warning(rates: np.ndarray, cfa: str) -> str | None:
    """The sentence for a stream read with a colour filter whose four 2×2 sites fire alike (within
    :data:`ALIKE_CONTRAST`, with enough spikes to tell), as a monochrome sensor's do, or ``None``."""
    h, w = rates.shape
    he, we = h - h % 2, w - w % 2
    if he < 2 or we < 2:
        return None
    sites = np.stack([rates[py:he:2, px:we:2].ravel() for py in (0, 1) for px in (0, 1)]).astype(np.float64)
    means = sites.mean(axis=1)
    m = float(means.mean())
    # the uncertainty of each site's offset from its 2x2 blocks' mean (the scene, shared by a block's four
    # sites, cancels): small where there are enough spikes to tell the sites apart
    dev = sites - sites.mean(axis=0)
    se = math.sqrt(float(dev.var(axis=1).max()) / sites.shape[1])
    if m <= 0 or float(means.std()) / m >= ALIKE_CONTRAST or se > 0.25 * ALIKE_CONTRAST * m:
        return None  # sites that differ, or too few spikes to say they do not
    return (f"read with a colour filter (--cfa {cfa}), but its four 2x2 sites fire alike "
            f"({' / '.join(f'{v:.3f}' for v in means)} spikes per tick, within {100 * float(means.std()) / m:.1f} %), "
            "as on a monochrome sensor: pass --cfa none if the capture is monochrome.")


def odd_width_warning(cfa: str, width: int) -> str:
    """The one sentence for a colour filter on frames of odd width (what the file says, whatever its rates)."""
    return (f"a colour filter ({cfa}) with an odd width ({width}) shifts the Bayer pattern on every row, which no "
            "sensor does; check --width, or pass --cfa none for a monochrome capture.")


#: the frame size the rates point to is taken as the likely one (the CLI refuses the given one) only when its rows
#: line up at least this well (mean correlation 1–4 rows down; a sheared Spike-Zoo clip's true size: 0.98, a dark
#: simulated 256² capture's: 0.53, the 64x64 demo's: 0.48, read at width 65 it was only warned about) and it holds
#: at least LIKELY_SIDE pixels a side (a 16x16 flat test stream's rates "line up" best at 15x8). The given width
#: must look sheared first (:func:`rate_warnings`), so this bounds only how sure the size it names must be
LIKELY_SPATIAL = 0.4
LIKELY_SIDE = 16


def _likely(src, width: int, height: int, spatial: float) -> None:
    if spatial >= LIKELY_SPATIAL and min(width, height) >= LIKELY_SIDE:
        src.info.likely_size = (int(width), int(height))


def rate_warnings(src, *, check_width: bool = True) -> list[str]:
    """Sentences for people when the firing rates suggest a wrong width, colour filter or flip.

    Looks at the mean rate image of a few hundred ticks: rows that do not line up (another width
    with the same frame size lines them up much better), an odd width with a colour filter, and
    green sites of the filter that fire at clearly different rates while the other diagonal fires
    alike (the filter phase, or the vertical flip that changes it, is wrong).

    Args:
        src: an open :class:`~spikeview.io.source.SpikeSource`.
        check_width: also try the other widths of the same frame size (plain files).

    Where the rows look sheared and another frame size lines them up well (:data:`LIKELY_SPATIAL`), that size is
    also set as ``src.info.likely_size`` (the CLI refuses to write frames at a sheared width).
    """
    from spikeview.cfa import cfa_to_str, parse_cfa

    w, h = src.width, src.height
    if src.n_frames < 1 or w < 2 or h < 2:
        return []
    rates = _mean_rates(src)
    out: list[str] = []
    if rates.max() <= 0:
        return out
    # back to storage order (undo the reader's flips), where another width is just another reshape
    stored = rates[::-1] if src.info.flip_vertical else rates
    stored = stored[:, ::-1] if src.info.flip_horizontal else stored
    flat = pair_sums(np.ascontiguousarray(stored).ravel())
    lags = _Lags(flat)
    here = spatial_score(flat.reshape(h, w), lags=lags)
    if check_width:
        pixels = w * h
        best = (here, w, h)
        for w2 in range(max(MIN_SIDE, math.ceil(math.sqrt(pixels / MAX_ASPECT))), math.isqrt(int(pixels * MAX_ASPECT)) + 1):
            if pixels % w2 or w2 == w:
                continue
            s = spatial_score(flat.reshape(pixels // w2, w2), lags=lags)
            if s > best[0]:
                best = (s, w2, pixels // w2)
        if here < 0.3 or (best[1] != w and here < 0.5 * best[0]):
            # the rows look wrong: let the whole file say what it holds (the frame size may be wrong too)
            guess = _file_guess(src)
            if guess is not None and guess.size == (w, h) and guess.spatial > 0.3:
                # the whole file's spikes line up best at the given size: only the mean rates look sheared (a dim scene
                # panning along the rows smears them; a noise-free one read as 512x128 by them was refused)
                pass
            elif guess is not None and guess.size != (w, h) and guess.spatial > 0.3 and here < 0.5 * guess.spatial:
                out.append(f"the rows do not line up at width {w} (the rates look sheared); judging by the spikes the "
                           f"frames are {guess.width}x{guess.height}: check --width and --height.")
                _likely(src, guess.width, guess.height, guess.spatial)
            elif not _whole_frames(src):
                out.append(f"the rows do not line up at width {w} and the file is not whole {w}x{h} frames, so the "
                           "frame size is probably wrong: check --width and --height.")
            elif best[1] != w and best[0] > 0.3 and here < 0.5 * best[0]:
                out.append(f"the rows do not line up at width {w} (the rates look sheared); the frames are probably "
                           f"{best[1]}x{best[2]}: check --width and --height.")
                _likely(src, best[1], best[2], best[0])
    cfa = parse_cfa(src.cfa) if src.cfa is not None else None
    if cfa is None and not out:
        note = monochrome_cfa_warning(rates)
        if note is not None:
            out.append(note)
    if cfa is not None and w % 2:
        out.append(odd_width_warning(cfa_to_str(cfa), w))
    elif cfa is not None and not out and (note := colour_filter_alike_warning(rates, cfa_to_str(cfa))):
        out.append(note)
    elif cfa is not None and not out:
        he, we = h - h % 2, w - w % 2
        sites = {(py, px): rates[py:he:2, px:we:2].ravel() for py in (0, 1) for px in (0, 1)}
        site = {k: float(v.mean()) for k, v in sites.items()}
        g_pos = [p for p, c in zip(((0, 0), (0, 1), (1, 0), (1, 1)), cfa) if c == "G"]
        other = [p for p in site if p not in g_pos]
        g_imb = _imbalance(site[g_pos[0]], site[g_pos[1]])
        o_imb = _imbalance(site[other[0]], site[other[1]])
        # evidence, not chance: the difference must stand far above the spread of the site means
        se = math.sqrt(sum(float(sites[p].var()) / max(1, sites[p].size) for p in g_pos))
        z = abs(site[g_pos[0]] - site[g_pos[1]]) / se if se > 0 else 0.0
        if g_imb > 0.1 and g_imb > 3 * o_imb and z > 8:
            names = ("GRBG or GBRG") if (0, 1) in g_pos else ("RGGB or BGGR")
            out.append(f"the two green sites of the {cfa_to_str(cfa)} filter fire at different rates "
                       f"({site[g_pos[0]]:.3f} and {site[g_pos[1]]:.3f} spikes per tick) while the other two fire "
                       f"alike, so the filter phase is probably wrong: try --cfa {names.split(' or ')[0]} (or "
                       f"{names.split(' or ')[1]}), or check --flip-vertical.")
    return out
