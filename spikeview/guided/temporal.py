"""Motion-aware temporal support: borrow the photons of neighbouring windows where the motion allows.

The output frame stays the instant at its window's centre, but the guided reconstruction may draw on
the spikes of the ``radius`` windows of ``window`` ticks on each side (``guided.temporal_radius``;
0 = the paper's single window). It is a burst-merging problem (METHOD.md "Video"): align each
neighbour to the centre window, then merge with per-photosite weights that fall back to the centre
window where the match fails.

**Align.** Each window's counts are summed over 2×2 super-pixels (one CFA period: every shift keeps
the Bayer phase; monochrome alike, which also quarters the search) and smoothed by a Gaussian (σ =
:data:`SMOOTH` super-pixels). Per :data:`TILE`-photosite tile one constant velocity is searched for
all neighbours at once (:func:`estimate_motion`: exhaustive, up to :data:`MAX_SPEED` photosites per
window, neighbour ``k`` read at ``round(k·v)``), with a small penalty on speed so that static and
flat tiles keep ``v = 0``. Using every neighbour for one velocity gives a usable estimate where one
pair of 10-tick windows is dominated by noise; a rotating or deforming object is matched locally,
tile by tile.

**Decide.** A neighbour's tile is accepted when the SSD of its *unsmoothed* super-pixel counts at the
chosen shift is within :data:`TILE_CHI` times what the noise alone gives (64 independent values
per tile; counts' variance ``κ·g(1 − g/cap)``, binomial-shaped because an integrate-and-fire pixel
is far from Poisson, with the scale κ measured on the centre window, :func:`count_dispersion`;
adjacent windows' counts anti-correlate, :data:`ADJACENT_DISPERSION`). Inside an accepted tile
every photosite is checked too: the 3×3 sum of same-colour photosites of the aligned neighbour must
agree within :data:`PIXEL_Z` standard deviations with what was pooled so far (the centre window and
the accepted nearer windows), and a photosite takes window ``k`` only if it took every window
between ``k`` and the centre. No neighbour is pooled where its displacement exceeds
:data:`MAX_SHIFT` photosites (a rotating or deforming object is only roughly a translation per
tile). Weights are 0 or 1: a photosite takes a neighbour's whole window or
none of it, and falls back to its own window where nothing matches (occlusions, fast or
non-rigid motion, a flash).

**What the data term sees.** The pooled observation is ``y = N / Δτ_eff`` with ``N`` the pooled
count and ``Δτ_eff = window · (1 + pooled neighbours)`` per photosite
(:attr:`~spikeview.guided.observation.Observation.dtau`), so the binomial noise model and the noise
weights stay exact for every photosite. ``y`` is also the mean of the ``1 + n`` aligned windows' TFP
values ``n_k/Δτ``, each on the ``1/Δτ`` grid, so the quantiser Q keeps its ``1/Δτ`` step and its
sharpness ``k``, and the plan decides Q from the count per ``Δτ``-tick window
(:meth:`~spikeview.guided.observation.Observation.window_count`). Measured on the tuning sequences
(128², 8 frames, against Q off): Q with step ``1/Δτ_eff`` lost 0.7 and 2.3 dB; with ``k`` also
scaled by ``Δτ_eff/Δτ`` it was within 0.1 dB (SSIM +0.03); with the ``1/Δτ`` grid it gained +0.6 and
+0.1 dB, SSIM +0.09 and +0.07 (without Q's soft floor the sampler lifts the black level of dark scenes).

**What the plan says.** :class:`Pooling` carries the map of pooled neighbours per photosite, the
tiles' shifts and one sentence (``"static: ±3 windows pooled on 97% of photosites …"``, ``"fast
motion: own window only on 88% of photosites …"``), which :func:`spikeview.guided.plan.make_plan`
reports as its ``temporal`` row.

Neighbours are read from the source at absolute ticks, so a frame does not depend on which other
frames are reconstructed with it (chunked batches, ``--at``, the app's Run): only windows wholly
inside the capture are used.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: tile size (pixels) of the alignment
TILE = 16
#: Gaussian σ (guide pixels) of the smoothing before block matching
SMOOTH = 1.0
#: largest speed searched (photosites per window; faster tiles find no match and keep their own window)
MAX_SPEED = 3.0
#: cost per guide pixel per window of speed, in units of the normalised SSD
SHIFT_PENALTY = 0.1
#: adjacent windows' counts anti-correlate (an integrate-and-fire pixel that fired late in one window
#: fires late in the next): their difference has about this much more variance than two independent
#: windows' (measured on static simulated scenes: 1.39 to 1.45)
ADJACENT_DISPERSION = 1.4
#: a tile's match is accepted when the SSD of its unsmoothed super-pixel counts is at most this many
#: times the noise-only SSD (64 super-pixels per tile: a static tile exceeds 1.5 with probability ~0.5 %)
TILE_CHI = 1.5
#: per-photosite test: 3×3 same-colour sums must agree within this many standard deviations
PIXEL_Z = 2.5
#: largest displacement (photosites, either axis) at which a neighbour is still pooled: farther, a
#: tile's single shift no longer fits rotating or deforming content (chosen on the tuning sequences of
#: spikeview.bench.temporal, 6 frames: fast pan −0.15 dB, fans +0.34 dB against no limit; 6 px: −0.01, +0.10)
MAX_SHIFT = 4



@dataclass
class Pooling:
    """What the temporal support of one window pooled, and why (see the module docstring).

    Attributes:
        radius: the requested radius (windows on each side).
        window: Δτ of one window in ticks.
        offsets: the neighbouring windows (in windows, negative = earlier) that lie inside the capture.
        dtau: ``(H, W)`` float32 effective window per photosite in ticks (``window`` = own window only).
        shifts: offset → ``(tiles_y, tiles_x, 2)`` int ``(dy, dx)`` in photosites of each tile's match.
        accepted: offset → ``(tiles_y, tiles_x)`` bool: the tile's match is within its noise.
        kind: ``"off"``, ``"unavailable"``, ``"static"``, ``"aligned"``, ``"mixed"`` or ``"fast motion"``.
        reason: one sentence for the plan.
    """

    radius: int
    window: int
    offsets: tuple[int, ...] = ()
    dtau: np.ndarray | None = None
    shifts: dict[int, np.ndarray] = field(default_factory=dict)
    accepted: dict[int, np.ndarray] = field(default_factory=dict)
    kind: str = "off"
    reason: str = ""

    @property
    def active(self) -> bool:
        """Whether neighbours could be pooled at all (radius > 0 and neighbouring windows exist)."""
        return self.radius > 0 and bool(self.offsets)

    def crop(self, y0: int, y1: int, x0: int, x1: int) -> "Pooling":
        """The same pooling on the photosites ``[y0:y1, x0:x1]`` (tile maps kept whole)."""
        d = None if self.dtau is None else self.dtau[y0:y1, x0:x1]
        return Pooling(self.radius, self.window, self.offsets, d, self.shifts, self.accepted, self.kind, self.reason)


#: run the torch alignment (:func:`_align_torch`) on the CPU too (tests hold the GPU path to the numpy one with it)
TORCH_ON_CPU = False


# --------------------------------------------------------------------------------- window reads
class WindowCache:
    """Counts of recently read windows (a sequence's consecutive frames share most neighbours)."""

    def __init__(self, size: int = 24):
        import threading

        self.size = int(size)
        self._d: OrderedDict[tuple[int, int, int], np.ndarray] = OrderedDict()
        self._lock = threading.Lock()  # a GPU run prepares windows ahead in threads (spikeview.guided.video)

    def counts(self, source: Any, a: int, b: int) -> np.ndarray:
        with self._lock:
            return self._counts(source, a, b)

    def _counts(self, source: Any, a: int, b: int) -> np.ndarray:
        from spikeview.classical.tfp import window_counts

        key = (id(source), int(a), int(b))
        hit = self._d.get(key)
        if hit is not None:
            self._d.move_to_end(key)
            return hit
        c = np.asarray(window_counts(source, a, b), dtype=np.float32)
        self._d[key] = c
        while len(self._d) > self.size:
            self._d.popitem(last=False)
        return c


def neighbour_offsets(a: int, b: int, n_frames: int, radius: int) -> tuple[int, ...]:
    """Offsets ``k`` (``0 < |k| <= radius``, nearest first) whose window ``[a + kΔτ, b + kΔτ)`` lies in ``[0, n_frames)``."""
    w = b - a
    out = []
    for d in range(1, int(radius) + 1):
        for k in (-d, d):
            if a + k * w >= 0 and b + k * w <= n_frames:
                out.append(k)
    return tuple(out)


# ------------------------------------------------------------------------------------ alignment
def _guide_raw(counts: np.ndarray, cfa: str | None = None) -> np.ndarray:
    """Counts summed over 2×2 super-pixels (one CFA period of a Bayer mosaic; monochrome alike), float32."""
    c = counts.astype(np.float32, copy=False)
    h2, w2 = (c.shape[0] // 2) * 2, (c.shape[1] // 2) * 2
    return c[0:h2:2, 0:w2:2] + c[1:h2:2, 0:w2:2] + c[0:h2:2, 1:w2:2] + c[1:h2:2, 1:w2:2]


def _binvar(g: np.ndarray, cap: float) -> np.ndarray:
    """Binomial-shaped variance ``g (1 − g/cap)`` of counts ``g`` out of at most ``cap`` (before the scale κ)."""
    return np.maximum(g * (1.0 - g / cap), 0.0)


def count_dispersion(raw: np.ndarray, cap: float, keep: float = 0.9) -> float:
    """Scale κ of the counts' variance ``κ · g (1 − g/cap)`` (``cap``: the most spikes a value can hold), in [0.05, 4].

    Integrate-and-fire counts are far from Poisson: a bright photosite fires almost regularly. Per
    2×2 block of ``raw`` the finest diagonal Haar detail ``HH = (a − b − c + d)/2`` has the counts'
    variance and is nearly blind to smooth content; ``κ = Σ HH² / Σ m (1 − m/cap)`` over the blocks
    (``m`` their mean), leaving out the ``1 − keep`` of blocks with the largest ratio (edges) and
    corrected for that trimming as in :func:`spikeview.guided.observation.haar_noise_variance`.
    """
    from spikeview.classical.noise import trim_factor as _trim_factor

    h2, w2 = (raw.shape[0] // 2) * 2, (raw.shape[1] // 2) * 2
    if h2 < 2 or w2 < 2:
        return 1.0
    p = raw[:h2, :w2].astype(np.float64)
    a, b, c, d = p[0::2, 0::2], p[0::2, 1::2], p[1::2, 0::2], p[1::2, 1::2]
    hh2 = (((a - b - c + d) / 2.0) ** 2).ravel()
    v = _binvar((a + b + c + d).ravel() / 4.0, cap)
    ratio = hh2 / (v + 1.0)
    kept = ratio <= np.quantile(ratio, keep)
    if float(v[kept].sum()) <= 0:
        return 1.0
    return float(np.clip(hh2[kept].sum() / v[kept].sum() / (_trim_factor(keep) / keep), 0.05, 4.0))


def _tile_sum(x: np.ndarray, t: int) -> np.ndarray:
    h, w = x.shape
    th, tw = -(-h // t), -(-w // t)
    if h != th * t or w != tw * t:
        p = np.zeros((th * t, tw * t), dtype=x.dtype)
        p[:h, :w] = x
        x = p
    # rows of each tile first (contiguous runs), then the columns: the same float64 sums as
    # ``sum(axis=(1, 3))`` at a quarter of the time (1000×1000: ~1100 calls per window's pooling)
    return x.reshape(th, t, tw * t).sum(axis=1, dtype=np.float64).reshape(th, tw, t).sum(axis=2)


def _tile_chi(g0: np.ndarray, gk: np.ndarray, pad: int, dy: int, dx: int, tile: int, noise: float,
              cap: float, v0: np.ndarray | None = None, vk: np.ndarray | None = None) -> np.ndarray:
    """Per tile: SSD between ``g0`` and the edge-padded ``gk`` read at ``(y + dy, x + dx)``, over the
    noise-only SSD ``Σ noise·(v(g₀) + v(g_k))`` with ``v`` = :func:`_binvar` (``v0``: ``v(g₀)``, ``vk``:
    ``v`` of the padded ``gk``, precomputed by callers that read many shifts: the same numbers).
    Each call checks the job's Cancel (the motion search and the match test are hundreds of calls: seconds at 1000×1000)."""
    from spikeview.errors import check_cancelled

    check_cancelled("while aligning the neighbouring windows")
    h, w = g0.shape
    s = gk[pad + dy:pad + dy + h, pad + dx:pad + dx + w]
    d = g0 - s
    v0 = _binvar(g0, cap) if v0 is None else v0
    vs = _binvar(s, cap) if vk is None else vk[pad + dy:pad + dy + h, pad + dx:pad + dx + w]
    return _tile_sum(d * d, tile) / (noise * _tile_sum(v0 + vs, tile) + 1e-6)


def estimate_motion(g0: np.ndarray, guides: dict[int, np.ndarray], tile: int, kappa: float,
                    kernel_energy: float, radius: int, max_speed: float = MAX_SPEED, cap: float = np.inf) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Per tile, one constant velocity ``v`` (guide pixels per window) for all neighbours, by exhaustive search.

    Candidates: ``v`` on a grid of step ``1/radius`` within ``±max_speed`` guide pixels per window;
    the neighbour ``k`` windows away is read at the integer shift ``round(k·v)``. The cost of ``v`` is
    the mean over neighbours of the tile's SSD over its noise-only SSD (:func:`_tile_chi`), plus
    :data:`SHIFT_PENALTY` per guide pixel per window of speed, so that a static or flat tile keeps
    ``v = 0`` unless motion explains the data clearly better. Using every neighbour for one velocity
    gives a robust estimate where one pair of 10-tick windows would be dominated by noise.

    Returns:
        ``(shifts, chi)``: per offset ``k``, ``(ty, tx, 2)`` int ``(dy, dx)`` in guide pixels (content
        at ``(y, x)`` of the centre window is at ``(y + dy, x + dx)`` of window ``k``) and the ``(ty, tx)``
        normalised SSD of that shift.
    """
    ks = sorted(guides)
    step = 1.0 / max(1, radius)
    n = int(np.floor(max_speed / step + 1e-9))
    grid = [i * step for i in range(-n, n + 1)]
    pad = int(np.ceil(max_speed * max(abs(k) for k in ks))) + 1
    padded = {k: np.pad(guides[k], pad, mode="edge") for k in ks}
    vpad = {k: _binvar(padded[k], cap) for k in ks}  # elementwise, so slicing it equals v of the slice
    memo: dict[tuple[int, int, int], np.ndarray] = {}
    v0 = _binvar(g0, cap)

    def chi(k: int, dy: int, dx: int) -> np.ndarray:
        key = (k, dy, dx)
        if key not in memo:
            factor = ADJACENT_DISPERSION if abs(k) == 1 else 1.0
            memo[key] = _tile_chi(g0, padded[k], pad, dy, dx, tile, factor * kappa * kernel_energy, cap, v0, vpad[k])
        return memo[key]

    best_cost = best_v = None
    for vy in grid:
        for vx in grid:
            cost = sum(chi(k, int(round(k * vy)), int(round(k * vx))) for k in ks) / len(ks)
            cost = cost + SHIFT_PENALTY * float(np.hypot(vy, vx))
            if best_cost is None:
                best_cost = cost
                best_v = np.zeros(cost.shape + (2,))
                best_v[..., 0], best_v[..., 1] = vy, vx
                continue
            better = cost < best_cost
            best_cost = np.where(better, cost, best_cost)
            best_v[better] = (vy, vx)
    assert best_v is not None
    shifts, chis = {}, {}
    for k in ks:
        sh = np.rint(k * best_v).astype(np.int64)
        c = np.empty(sh.shape[:2])
        for dy, dx in {tuple(v) for v in sh.reshape(-1, 2).tolist()}:
            sel = (sh[..., 0] == dy) & (sh[..., 1] == dx)
            c[sel] = chi(k, dy, dx)[sel]
        shifts[k], chis[k] = sh, c
    return shifts, chis


def match_quality(raw0: np.ndarray, rawk: np.ndarray, shifts: np.ndarray, tile: int, noise: float, cap: float) -> np.ndarray:
    """Per tile, the SSD of the unsmoothed super-pixel counts at the tile's shift over its noise-only SSD.

    The search ran on smoothed guides (robust, but a tile then has only ~5 independent values); the
    acceptance uses the raw counts, whose 64 independent values per tile make the test both sharper
    and less often wrong on a static tile.
    """
    pad = int(np.abs(shifts).max(initial=0)) + 1
    padded = np.pad(rawk, pad, mode="edge")
    v0, vk = _binvar(raw0, cap), _binvar(padded, cap)
    out = np.empty(shifts.shape[:2])
    for dy, dx in {tuple(v) for v in shifts.reshape(-1, 2).tolist()}:
        sel = (shifts[..., 0] == dy) & (shifts[..., 1] == dx)
        out[sel] = _tile_chi(raw0, padded, pad, dy, dx, tile, noise, cap, v0, vk)[sel]
    return out


def _fit_tiles(a: np.ndarray, th: int, tw: int) -> np.ndarray:
    """``a`` cut or edge-extended to ``th × tw`` tiles (first two axes)."""
    a = a[:th, :tw]
    pad = [(0, th - a.shape[0]), (0, tw - a.shape[1])] + [(0, 0)] * (a.ndim - 2)
    return np.pad(a, pad, mode="edge") if pad[0][1] or pad[1][1] else a


def _box_same_colour(c: np.ndarray, cfa: str | None) -> np.ndarray:
    """3×3 sums over photosites of the same colour (within each Bayer plane)."""
    from scipy.ndimage import uniform_filter

    if cfa is None:
        return uniform_filter(c, size=3, mode="nearest") * 9.0
    out = np.empty_like(c)
    for i in (0, 1):
        for j in (0, 1):
            out[i::2, j::2] = uniform_filter(c[i::2, j::2], size=3, mode="nearest") * 9.0
    return out


# ---------------------------------------------------------------------------------------- pooling
def pool_counts(source: Any, a: int, b: int, radius: int, cfa: str | None,
                cache: WindowCache | None = None, device: Any = None) -> tuple[np.ndarray, Pooling]:
    """Pooled counts of the window ``[a, b)`` with its aligned neighbours (see the module docstring).

    ``device``: where the alignment runs (``guided.device``; ``None``/CPU: numpy, as always). On a CUDA
    device the motion search, the match test and the per-photosite decisions run in torch there
    (:func:`_align_torch`: the same rules, sums in float64; counting and the smoothed guides stay on the CPU).

    Returns:
        ``(counts, pooling)``: ``(H, W)`` float32 pooled spike counts (``counts / pooling.dtau`` is
        the pooled TFP) and what was pooled.
    """
    from scipy.ndimage import gaussian_filter

    from spikeview.errors import check_cancelled

    cache = cache if cache is not None else WindowCache()
    window = int(b - a)
    n0 = cache.counts(source, a, b)
    radius = int(radius)
    if radius <= 0:
        return n0, Pooling(0, window, kind="off",
                           reason="off (temporal_radius = 0): the window alone, as in the paper")
    offsets = neighbour_offsets(a, b, int(source.n_frames), radius)
    if not offsets:
        return n0, Pooling(radius, window, kind="unavailable",
                           reason=(f"the capture holds {int(source.n_frames)} ticks: no whole {window}-tick window beside this "
                                   "one to borrow from (own window only)"))
    if min(n0.shape) < 2:  # no 2×2 super-pixel: nothing to align
        h0, w0 = n0.shape
        return n0, Pooling(radius, window, kind="unavailable",
                           reason=f"a {w0}x{h0} frame is too small to align neighbouring windows (own window only)")
    f = 2  # guide pixels are 2×2 super-pixels: shifts keep the CFA phase, and the search costs a quarter
    tile_g = max(1, TILE // f)
    raw0 = _guide_raw(n0, cfa)
    cap = 4.0 * window  # a super-pixel holds at most 4 photosites × window spikes
    kappa = count_dispersion(raw0, cap)
    # variance of a Gaussian-smoothed white-noise image: Σ k² = 1 / (4πσ²) (σ >= ~0.7)
    kernel_energy = 1.0 / (4.0 * np.pi * SMOOTH ** 2)
    g0 = gaussian_filter(raw0, SMOOTH, mode="reflect")
    h, w = n0.shape
    total = n0.astype(np.float32).copy()
    pooled = np.zeros((h, w), dtype=np.float32)
    shifts: dict[int, np.ndarray] = {}
    accepted: dict[int, np.ndarray] = {}
    # photosite -> tile index (tiles of TILE photosites)
    th, tw = -(-h // TILE), -(-w // TILE)
    ty_of, tx_of = np.arange(h) // TILE, np.arange(w) // TILE
    counts = {k: cache.counts(source, a + k * window, b + k * window) for k in offsets}
    guides = {k: gaussian_filter(_guide_raw(counts[k], cfa), SMOOTH, mode="reflect") for k in offsets}
    if getattr(device, "type", "cpu") != "cpu" or TORCH_ON_CPU:  # a resolved torch.device (Observation.from_source)
        total, pooled, shifts, accepted = _align_torch(n0, raw0, g0, counts, guides, cfa, window, radius, kappa,
                                                       kernel_energy, device if device is not None else "cpu")
        dtau = (window * (1.0 + pooled)).astype(np.float32)
        pool = Pooling(radius, window, offsets, dtau, shifts, accepted)
        pool.kind, pool.reason = describe(pool)
        return total, pool
    motion, _ = estimate_motion(g0, guides, tile_g, kappa, kernel_energy, radius, MAX_SPEED / f, cap)
    chis = {k: match_quality(raw0, _guide_raw(counts[k], cfa), motion[k], tile_g,
                             (ADJACENT_DISPERSION if abs(k) == 1 else 1.0) * kappa, cap) for k in offsets}
    # nearest windows first; a photosite takes window k only if it took every window between k and the
    # centre (motion grows with the distance), and window k is compared with what was pooled so far
    # (the centre and the accepted nearer windows: a less noisy reference than the centre alone)
    chain = {-1: np.ones((h, w), dtype=bool), 1: np.ones((h, w), dtype=bool)}
    for d in sorted({abs(k) for k in offsets}):
        box_total = _box_same_colour(total, cfa)
        box_n = _box_same_colour(1.0 + pooled, cfa)
        ref = 9.0 * box_total / box_n  # 3×3 same-colour sum per window of the reference
        factor = ADJACENT_DISPERSION if d == 1 else 1.0
        new_total, new_pooled = np.zeros((h, w), np.float32), np.zeros((h, w), np.float32)
        for k in (-d, d):
            if k not in counts:
                continue
            check_cancelled("while pooling the neighbouring windows")  # each window's pooling: ~0.1 s at 1000×1000
            nk = counts[k]
            # tiles of the guide are tiles of TILE photosites (an odd last row/column of a Bayer frame
            # has no super-pixel: it takes its neighbour tile's match)
            best, chi = _fit_tiles(motion[k], th, tw), _fit_tiles(chis[k], th, tw)
            ok_tile = (chi <= TILE_CHI) & (np.abs(best * f).max(axis=-1) <= MAX_SHIFT)
            shifts[k] = best * f
            accepted[k] = ok_tile
            # every photosite reads the neighbour at its tile's shift (the 3×3 same-colour sums shift with it)
            tile_ok_px = ok_tile[ty_of][:, tx_of]
            best_px = best[ty_of][:, tx_of] * f
            ys = np.arange(h)[:, None] + best_px[..., 0]
            xs = np.arange(w)[None, :] + best_px[..., 1]
            inside = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
            ys, xs = np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)
            aligned = nk[ys, xs]
            boxk = _box_same_colour(nk, cfa)[ys, xs]
            # a shifted 3×3 sum that reaches past the frame's border (edge-extended there) is not the sum
            # the centre window's photosite sees: such photosites are left out unless the shift is zero
            margin = (ys >= 2) & (ys < h - 2) & (xs >= 2) & (xs < w - 2)
            zero = (best_px[..., 0] == 0) & (best_px[..., 1] == 0)
            cap9 = 9.0 * window  # a 3×3 same-colour sum holds at most 9 × window spikes per window
            z2 = (ref - boxk) ** 2 / (factor * kappa * (_binvar(ref, cap9) * 9.0 / box_n + _binvar(boxk, cap9)) + 1.0)
            weight = chain[1 if k > 0 else -1] & tile_ok_px & inside & (margin | zero) & (z2 <= PIXEL_Z ** 2)
            chain[1 if k > 0 else -1] = weight
            new_total += np.where(weight, aligned, 0.0).astype(np.float32)
            new_pooled += weight
        total += new_total
        pooled += new_pooled
    dtau = (window * (1.0 + pooled)).astype(np.float32)
    pool = Pooling(radius, window, offsets, dtau, shifts, accepted)
    pool.kind, pool.reason = describe(pool)
    return total, pool


def _align_torch(n0: np.ndarray, raw0: np.ndarray, g0: np.ndarray, counts: dict[int, np.ndarray],
                 guides: dict[int, np.ndarray], cfa: str | None, window: int, radius: int, kappa: float,
                 kernel_energy: float, device: Any) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray], dict[int, np.ndarray]]:
    """:func:`pool_counts`'s alignment and merge in torch on ``device`` (a GPU; tests run it on the CPU).

    The rules of the numpy path, computed for every candidate shift at once: the per-tile normalised SSD of
    every shift of every neighbour (:func:`_tile_chi`, float64 tile sums), the velocity search with its
    speed penalty (the first minimum in the same grid order), the match test on the unsmoothed counts, then
    the per-photosite chain and 3×3 same-colour test. Returns ``(total, pooled, shifts, accepted)`` as numpy.
    """
    import torch
    import torch.nn.functional as F

    from spikeview.errors import check_cancelled

    dev = torch.device(device)
    f = 2
    tile = max(1, TILE // f)
    cap = 4.0 * window
    ks = sorted(guides)
    step = 1.0 / max(1, radius)
    n = int(np.floor((MAX_SPEED / f) / step + 1e-9))
    grid = [(i * step, j * step) for i in range(-n, n + 1) for j in range(-n, n + 1)]  # vy outer, vx inner

    def up(x: np.ndarray) -> Any:
        return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32)).to(dev, non_blocking=True)

    def binvar(g: Any, c: float) -> Any:
        return torch.clamp(g * (1.0 - g / c), min=0.0)

    def tile_sums(x: Any) -> Any:  # (S, h, w) float32 -> (S, th, tw) float64 sums over tile × tile blocks
        s_, h_, w_ = x.shape
        th_, tw_ = -(-h_ // tile), -(-w_ // tile)
        x = F.pad(x, (0, tw_ * tile - w_, 0, th_ * tile - h_)).double()
        return x.view(s_, th_, tile, tw_, tile).sum(dim=(2, 4))

    def chi_all(ref: Any, other: Any, shifts: list[tuple[int, int]], noise: float) -> Any:
        """(S, th, tw) normalised SSD of ``ref`` against the edge-padded ``other`` at each shift."""
        pad = max(max(abs(dy), abs(dx)) for dy, dx in shifts) + 1
        padded = F.pad(other[None, None], (pad, pad, pad, pad), mode="replicate")[0, 0]
        h_, w_ = ref.shape
        v0 = binvar(ref, cap)
        out = []
        for i in range(0, len(shifts), 32):  # bounded memory: 32 shifted copies at a time
            check_cancelled("while aligning the neighbouring windows")
            sl = torch.stack([padded[pad + dy:pad + dy + h_, pad + dx:pad + dx + w_] for dy, dx in shifts[i:i + 32]])
            d = ref[None] - sl
            out.append(tile_sums(d * d) / (noise * tile_sums(v0[None] + binvar(sl, cap)) + 1e-6))
        return torch.cat(out)

    g0_t = up(g0)
    raw0_t = up(raw0)
    # --- the velocity search (estimate_motion): cost of every grid velocity, mean over neighbours
    cost = None
    cand: dict[int, list[tuple[int, int]]] = {}
    index: dict[int, Any] = {}
    chis_sm: dict[int, Any] = {}
    for k in ks:
        sh = [(int(round(k * vy)), int(round(k * vx))) for vy, vx in grid]
        uniq = sorted(set(sh))
        cand[k] = uniq
        pos = {s_: i for i, s_ in enumerate(uniq)}
        index[k] = torch.tensor([pos[s_] for s_ in sh], device=dev)
        factor = ADJACENT_DISPERSION if abs(k) == 1 else 1.0
        chis_sm[k] = chi_all(g0_t, up(guides[k]), uniq, factor * kappa * kernel_energy)
        term = chis_sm[k][index[k]]  # (V, th, tw)
        cost = term if cost is None else cost + term
    assert cost is not None
    pen = torch.tensor([SHIFT_PENALTY * float(np.hypot(vy, vx)) for vy, vx in grid], dtype=torch.float64, device=dev)
    cost = cost / len(ks) + pen[:, None, None]
    best = torch.argmin(cost, dim=0)  # the first minimum, as the numpy search's strict "<" keeps
    vel = torch.tensor(grid, dtype=torch.float64, device=dev)[best]  # (th, tw, 2)
    h, w = n0.shape
    th, tw = -(-h // TILE), -(-w // TILE)
    ty_of, tx_of = torch.arange(h, device=dev) // TILE, torch.arange(w, device=dev) // TILE

    def fit(a_: Any) -> Any:  # _fit_tiles: cut or edge-extend the first two axes to th × tw
        a_ = a_[:th, :tw]
        if a_.shape[0] < th:
            a_ = torch.cat([a_, a_[-1:].expand(th - a_.shape[0], *a_.shape[1:])], 0)
        if a_.shape[1] < tw:
            a_ = torch.cat([a_, a_[:, -1:].expand(a_.shape[0], tw - a_.shape[1], *a_.shape[2:])], 1)
        return a_

    def box3(c: Any) -> Any:  # _box_same_colour: 3×3 sums within each Bayer plane (edges repeated)
        def one(p_: Any) -> Any:
            q = F.pad(p_[None, None], (1, 1, 1, 1), mode="replicate")
            return F.avg_pool2d(q, 3, stride=1)[0, 0] * 9.0
        if cfa is None:
            return one(c)
        out_ = torch.empty_like(c)
        for i in (0, 1):
            for j in (0, 1):
                out_[i::2, j::2] = one(c[i::2, j::2])
        return out_

    total = up(n0).clone()
    pooled = torch.zeros((h, w), dtype=torch.float32, device=dev)
    cnt = {k: up(v) for k, v in counts.items()}
    motion: dict[int, Any] = {}
    chis: dict[int, Any] = {}
    for k in ks:
        sh = torch.round(k * vel).long()  # (th_g, tw_g, 2): np.rint, half to even, as torch.round
        motion[k] = sh
        lut = {s_: i for i, s_ in enumerate(cand[k])}
        keys = sh.view(-1, 2).tolist()
        sel = torch.tensor([lut[(dy, dx)] for dy, dx in keys], device=dev).view(sh.shape[:2])
        factor = ADJACENT_DISPERSION if abs(k) == 1 else 1.0
        raw_chi = chi_all(raw0_t, up(_guide_raw(counts[k], cfa)), cand[k], factor * kappa)
        chis[k] = torch.gather(raw_chi, 0, sel[None]).squeeze(0)
    shifts_out: dict[int, np.ndarray] = {}
    accepted_out: dict[int, np.ndarray] = {}
    chain = {-1: torch.ones((h, w), dtype=torch.bool, device=dev), 1: torch.ones((h, w), dtype=torch.bool, device=dev)}
    yy = torch.arange(h, device=dev)[:, None]
    xx = torch.arange(w, device=dev)[None, :]
    cap9 = 9.0 * window
    for d in sorted({abs(k) for k in ks}):
        box_total = box3(total)
        box_n = box3(1.0 + pooled)
        ref = 9.0 * box_total / box_n
        factor = ADJACENT_DISPERSION if d == 1 else 1.0
        new_total = torch.zeros((h, w), dtype=torch.float32, device=dev)
        new_pooled = torch.zeros((h, w), dtype=torch.float32, device=dev)
        for k in (-d, d):
            if k not in cnt:
                continue
            check_cancelled("while pooling the neighbouring windows")
            nk = cnt[k]
            best_k, chi_k = fit(motion[k]), fit(chis[k])
            ok_tile = (chi_k <= TILE_CHI) & ((best_k * f).abs().amax(dim=-1) <= MAX_SHIFT)
            shifts_out[k] = (best_k * f).cpu().numpy().astype(np.int64)
            accepted_out[k] = ok_tile.cpu().numpy()
            tile_ok_px = ok_tile[ty_of][:, tx_of]
            best_px = best_k[ty_of][:, tx_of] * f
            ys = yy + best_px[..., 0]
            xs = xx + best_px[..., 1]
            inside = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
            ys, xs = ys.clamp(0, h - 1), xs.clamp(0, w - 1)
            aligned = nk[ys, xs]
            boxk = box3(nk)[ys, xs]
            margin = (ys >= 2) & (ys < h - 2) & (xs >= 2) & (xs < w - 2)
            zero = (best_px[..., 0] == 0) & (best_px[..., 1] == 0)
            z2 = (ref - boxk) ** 2 / (factor * kappa * (binvar(ref, cap9) * 9.0 / box_n + binvar(boxk, cap9)) + 1.0)
            weight = chain[1 if k > 0 else -1] & tile_ok_px & inside & (margin | zero) & (z2 <= PIXEL_Z ** 2)
            chain[1 if k > 0 else -1] = weight
            new_total += torch.where(weight, aligned, torch.zeros_like(aligned))
            new_pooled += weight
        total += new_total
        pooled += new_pooled
    return total.cpu().numpy(), pooled.cpu().numpy(), shifts_out, accepted_out


def describe(pool: Pooling) -> tuple[str, str]:
    """``(kind, sentence)`` of a pooling for the plan."""
    m = len(pool.offsets)
    assert pool.dtau is not None
    nb = pool.dtau / pool.window - 1.0
    mean_nb = float(nb.mean())
    full = float((nb >= m - 1e-6).mean())
    own = float((nb <= 1e-6).mean())
    moved = [np.abs(pool.shifts[k][pool.accepted[k]]).max(initial=0) for k in pool.offsets]
    smax = int(max(moved, default=0))
    span = (f"±{pool.radius} windows" if len(set(abs(k) for k in pool.offsets)) == pool.radius and m == 2 * pool.radius
            else f"{m} neighbouring windows (the capture's edge cuts the rest)")
    eff = f"Δτ_eff {float(pool.dtau.mean()):.0f} of {pool.window * (m + 1)} ticks on average"
    if full >= 0.9 and smax == 0:
        return "static", f"static: {span} pooled on {100 * full:.0f}% of photosites ({eff})"
    if own >= 0.75:
        return "fast motion", (f"fast motion: own window only on {100 * own:.0f}% of photosites (the neighbours do not match "
                               f"within their noise; {eff})")
    if mean_nb >= 0.75 * m:
        return "aligned", f"moving: {span} aligned (shifts up to {smax} px) and pooled on {100 * full:.0f}% of photosites ({eff})"
    return "mixed", (f"mixed motion: {mean_nb:.1f} of {m} neighbouring windows pooled on average, own window only on "
                     f"{100 * own:.0f}% of photosites (shifts up to {smax} px; {eff})")
