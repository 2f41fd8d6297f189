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
is far from Poisson, with the scale κ measured on the centre window, :func:`dispersion_curve`, by level;
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

import numba
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
#: in a tile's match, one value's squared difference counts at most this many times its noise variance (a hot or
#: blinking photosite alone cannot fail a tile of 64: it adds at most 16/64 = 0.25 to the normalised SSD)
CHI_CLIP = 16.0
#: a tile with fewer spikes per photosite in its own window than this stays at rest whenever zero shift matches
#: within :data:`REST_CHI` on average over its neighbours: at that light the search's velocity is mostly noise (a real dark capture at 0.31
#: spikes: a static scene's tiles otherwise moved on 13 %, blurring it)
DIM_COUNT = 1.0
#: a dim tile at rest (:data:`DIM_COUNT`) takes each neighbour whose raw match at zero shift is within this (at 1.5
#: one 64-value test of six failed by chance on 2–6 % of a dark static scene's tiles: low counts' tails are heavier
#: than χ²'s); the windows beyond ±radius (:data:`LOW_LIGHT_RADIUS`) are tested with it too
REST_CHI = 2.0
#: a tile is held at rest where zero shift matches (within :data:`TILE_CHI`) and the velocity found beats it by less
#: than this (normalised SSD, the mean over the neighbours): the best of the search's ~50 velocities beats rest by
#: 0.0–0.24 on a static regular capture's tiles (median 0.13), a 2 px-a-window pan's by 0.26–0.63 (median 0.46)
REST_MARGIN = 0.25
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
    #: windows pooled beyond ``radius`` at rest on static low-light tiles (:data:`LOW_LIGHT_RADIUS`), nearest first
    extended: tuple[int, ...] = ()
    #: ``(lo, hi)``: ``(H, W)`` int64 tick range each photosite pooled **at rest** (every window it took at zero
    #: shift, contiguous around its own); ``lo = hi = -1`` where it took a shifted window (:func:`interval_rates`)
    support: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    #: the frame's drift (photosites a window, y, x) that bounded the low-light extension (:func:`frame_drift`)
    drift: tuple[float, float] | None = None
    #: a dim frame's velocity (photosites a window, y, x; :func:`frame_velocity`) by which every neighbouring window
    #: was moved back before pooling (:class:`_Glide`); ``None``: read where it lies
    glide: tuple[float, float] | None = None
    #: the share of photosites whose rate came from the intervals between their spikes (set by the observation)
    interval_share: float = 0.0

    @property
    def active(self) -> bool:
        """Whether neighbours could be pooled at all (radius > 0 and neighbouring windows exist)."""
        return self.radius > 0 and bool(self.offsets)

    def crop(self, y0: int, y1: int, x0: int, x1: int) -> "Pooling":
        """The same pooling on the photosites ``[y0:y1, x0:x1]`` (tile maps kept whole)."""
        d = None if self.dtau is None else self.dtau[y0:y1, x0:x1]
        sup = None if self.support is None else tuple(x[y0:y1, x0:x1] for x in self.support)
        out = Pooling(self.radius, self.window, self.offsets, d, self.shifts, self.accepted, self.kind, self.reason,
                      self.extended, sup)
        out.drift, out.glide, out.interval_share = self.drift, self.glide, self.interval_share
        return out


#: run the torch alignment (:func:`_align_torch`) on the CPU too (tests hold the GPU path to the numpy one with it)
TORCH_ON_CPU = False


class _Arrays:
    """The pooling's per-photosite arrays: numpy (``device`` None), or torch tensors on ``device`` (:data:`TORCH_ON_CPU`:
    the CPU). ``put`` moves a numpy array there (dtypes kept), ``get`` brings one back."""

    def __init__(self, device: Any = None):
        self.torch = None
        if device is not None:
            import torch

            self.torch, self.device = torch, torch.device(device)

    def put(self, a: Any) -> Any:
        if self.torch is None or not isinstance(a, np.ndarray):
            return a
        return self.torch.from_numpy(np.ascontiguousarray(a)).to(self.device)

    def get(self, a: Any) -> Any:
        return a if isinstance(a, np.ndarray) else a.cpu().numpy()

    def full(self, shape: tuple[int, int], value: bool) -> Any:
        return self.put(np.full(shape, value))

    def zeros(self, shape: tuple[int, int], dtype: Any) -> Any:
        return self.put(np.zeros(shape, dtype=dtype))

    def add_where(self, total: Any, a: Any, cond: Any) -> None:
        """``total += a`` where ``cond``, in place."""
        if self.torch is None:
            np.add(total, a, out=total, where=cond)
        else:
            total += self.torch.where(cond, a, 0.0)


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


class _Glide:
    """A :class:`WindowCache` seen through a dim frame's measured velocity ``v`` (photosites a window): the window ``k``
    windows from the centre ``[a, a + window)`` is moved back by ``round(k v)`` (whole photosites; on a Bayer mosaic
    whole 2×2 cells, which keep the colour pattern), so the pooling sees a static scene. The photosites moved in from
    outside the frame read 0 and are left out (:meth:`valid`)."""

    def __init__(self, cache: "WindowCache", a: int, window: int, v: tuple[float, float], cfa: str | None):
        self.cache, self.a, self.window, self.v = cache, int(a), int(window), v
        self.step = 2 if cfa is not None else 1

    def shift(self, a: int) -> tuple[int, int]:
        k = (int(a) - self.a) / self.window
        return tuple(self.step * int(round(k * c / self.step)) for c in self.v)  # type: ignore[return-value]

    def counts(self, source: Any, a: int, b: int) -> np.ndarray:
        c = self.cache.counts(source, a, b)
        dy, dx = self.shift(a)
        if dy == 0 and dx == 0:
            return c
        out = np.zeros_like(c)
        h, w = c.shape
        # content at (y, x) of the centre window is at (y + dy, x + dx) of this one
        out[max(0, -dy):min(h, h - dy), max(0, -dx):min(w, w - dx)] = \
            c[max(0, dy):min(h, h + dy), max(0, dx):min(w, w + dx)]
        return out

    def valid(self, a: int, shape: tuple[int, int]) -> np.ndarray:
        """Where the moved window ``[a, …)`` holds data (photosites moved in from outside the frame do not)."""
        dy, dx = self.shift(a)
        m = np.zeros(shape, bool)
        h, w = shape
        m[max(0, -dy):min(h, h - dy), max(0, -dx):min(w, w - dx)] = True
        return m


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


#: levels of :func:`dispersion_curve` (quantile bins of the super-pixel level)
DISPERSION_BINS = 6


def dispersion_curve(raw: np.ndarray, cap: float, keep: float = 0.9, bins: int = DISPERSION_BINS) -> tuple[np.ndarray, np.ndarray]:
    """κ as a function of the level: ``(levels, kappas)``, float64, for :func:`_countvar` (linear between the levels).

    A dark photosite of an integrate-and-fire sensor fires far less regularly than a bright one (its
    count is closer to Poisson): one κ for the frame, measured mostly on the bright majority, made a
    static scene's dark tiles fail the match test (a static 256² camera scene pooled 75 % of its
    photosites). Per 2×2 block of ``raw`` the finest diagonal Haar detail ``HH = (a − b − c + d)/2`` has the counts'
    variance and is nearly blind to smooth content; the blocks are split into ``bins`` quantile bins of their level
    ``m``, each with its own ``κ = Σ HH² / Σ m (1 − m/cap)``, leaving out the ``1 − keep`` of blocks with the largest
    ratio (edges) and corrected for that trimming as in :func:`spikeview.guided.observation.haar_noise_variance`
    (at least 64 blocks a bin).
    """
    from spikeview.classical.noise import trim_factor as _trim_factor

    h2, w2 = (raw.shape[0] // 2) * 2, (raw.shape[1] // 2) * 2
    if h2 < 2 or w2 < 2:
        return np.array([0.0]), np.array([1.0])
    p = raw[:h2, :w2].astype(np.float64)
    a, b, c, d = p[0::2, 0::2], p[0::2, 1::2], p[1::2, 0::2], p[1::2, 1::2]
    hh2 = (((a - b - c + d) / 2.0) ** 2).ravel()
    m = (a + b + c + d).ravel() / 4.0
    v = _binvar(m, cap)
    nb = int(max(1, min(bins, m.size // 64)))
    order = np.argsort(m, kind="stable")
    levels, kappas = [], []
    for part in np.array_split(order, nb):
        hp, vp = hh2[part], v[part]
        ratio = hp / (vp + 1.0)
        kept = ratio <= np.quantile(ratio, keep)
        k = 1.0 if float(vp[kept].sum()) <= 0 else float(hp[kept].sum() / vp[kept].sum() / (_trim_factor(keep) / keep))
        levels.append(float(np.mean(m[part])))
        kappas.append(float(np.clip(k, 0.05, 4.0)))
    return np.asarray(levels), np.asarray(kappas)


def _countvar(g: Any, cap: float, curve: tuple[np.ndarray, np.ndarray], scale: float = 1.0) -> Any:
    """Variance ``κ(g·scale) · g (1 − g/cap)`` of counts ``g`` (``scale`` maps ``g`` to the curve's super-pixel
    units), float32: κ interpolated linearly in float64 between the curve's levels (constant beyond them).
    A torch tensor ``g`` stays on its device (:func:`_interp_torch`: numpy's interpolation)."""
    if not isinstance(g, np.ndarray) and hasattr(g, "double"):
        g64 = g.double()
        return (_interp_torch(g64 * scale, curve[0], curve[1]) * _binvar_torch(g64, cap)).float()
    kap = np.interp(np.asarray(g, dtype=np.float64) * scale, curve[0], curve[1])
    return (kap * _binvar(np.asarray(g, dtype=np.float64), cap)).astype(np.float32)


def _binvar_torch(g: Any, cap: float) -> Any:
    """:func:`_binvar` of a torch tensor."""
    return (g * (1.0 - g / cap)).clamp_min(0.0)


def _interp_torch(x: Any, xp: np.ndarray, fp: np.ndarray) -> Any:
    """``np.interp(x, xp, fp)`` for a float64 torch tensor ``x`` (on its device): the same slope and offset per interval,
    ``fp[0]``/``fp[-1]`` beyond the ends."""
    import torch

    xp_t = torch.as_tensor(np.asarray(xp, dtype=np.float64), device=x.device)
    fp_t = torch.as_tensor(np.asarray(fp, dtype=np.float64), device=x.device)
    if xp_t.numel() == 1:
        return torch.full_like(x, float(fp_t[0]))
    j = (torch.searchsorted(xp_t, x.contiguous(), right=True) - 1).clamp(0, xp_t.numel() - 2)
    x0, x1, y0, y1 = xp_t[j], xp_t[j + 1], fp_t[j], fp_t[j + 1]
    dx = x1 - x0
    slope = torch.where(dx > 0, (y1 - y0) / torch.where(dx > 0, dx, torch.ones_like(dx)), torch.zeros_like(dx))
    out = slope * (x - x0) + y0
    out = torch.where(x == x1, y1, out)
    return torch.where(x <= xp_t[0], fp_t[0], torch.where(x >= xp_t[-1], fp_t[-1], out))


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
    noise-only SSD ``Σ noise·(v₀ + v_k)`` (``v0``: the variance of ``g0``, ``vk``: of the padded ``gk``, both
    from :func:`_countvar`, κ included; without them :func:`_binvar`, and ``noise`` carries κ).
    Each call checks the job's Cancel (the motion search and the match test are hundreds of calls: seconds at 1000×1000)."""
    from spikeview.errors import check_cancelled

    check_cancelled("while aligning the neighbouring windows")
    h, w = g0.shape
    s = gk[pad + dy:pad + dy + h, pad + dx:pad + dx + w]
    d = g0 - s
    v0 = _binvar(g0, cap) if v0 is None else v0
    vs = _binvar(s, cap) if vk is None else vk[pad + dy:pad + dy + h, pad + dx:pad + dx + w]
    v = v0 + vs
    # one value counts at most CHI_CLIP times its noise: a single defective photosite (hot, blinking) no longer
    # fails its whole tile (a real dark capture kept 16×16 blocks of raw noise there)
    return _tile_sum(np.minimum(d * d, CHI_CLIP * noise * v + 1e-6), tile) / (noise * _tile_sum(v, tile) + 1e-6)


def _velocity_grid(radius: int, max_speed: float) -> list[tuple[float, float]]:
    """Candidate velocities ``(vy, vx)`` (guide pixels per window), ``vy`` outer, on a grid of step ``1/radius``."""
    step = 1.0 / max(1, radius)
    n = int(np.floor(max_speed / step + 1e-9))
    return [(i * step, j * step) for i in range(-n, n + 1) for j in range(-n, n + 1)]


def estimate_motion(g0: np.ndarray, guides: dict[int, np.ndarray], tile: int, curve: tuple[np.ndarray, np.ndarray],
                    kernel_energy: float, radius: int, max_speed: float = MAX_SPEED, cap: float = np.inf,
                    factors: dict[int, float] | None = None) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict]:
    """Per tile, one constant velocity ``v`` (guide pixels per window) for all neighbours, by exhaustive search.

    Candidates: ``v`` on a grid of step ``1/radius`` within ``±max_speed`` guide pixels per window;
    the neighbour ``k`` windows away is read at the integer shift ``round(k·v)``. The cost of ``v`` is
    the mean over neighbours of the tile's SSD over its noise-only SSD (:func:`_tile_chi`, the variances
    from the level-dependent κ of ``curve`` times ``kernel_energy``: the guides are smoothed; times ``factors[k]``,
    the measured scale of neighbour ``k``'s differences, :func:`_noise_scale`), plus
    :data:`SHIFT_PENALTY` per guide pixel per window of speed, plus the noise-scaled cost of moving at all
    (:func:`_move_cost`), so that a static or flat tile keeps ``v = 0`` unless motion explains the data clearly better.

    Returns:
        ``(shifts, chi, frame)``: per offset ``k``, ``(ty, tx, 2)`` int ``(dy, dx)`` in guide pixels (content
        at ``(y, x)`` of the centre window is at ``(y + dy, x + dx)`` of window ``k``) and the ``(ty, tx)``
        normalised SSD of that shift; ``frame``: velocity → the whole frame's mean cost (without the penalty).
    """
    ks = sorted(guides)
    grid = _velocity_grid(radius, max_speed)
    pad = int(np.ceil(max_speed * max(abs(k) for k in ks))) + 1
    padded = {k: np.pad(guides[k], pad, mode="edge") for k in ks}
    vpad = {k: _countvar(padded[k], cap, curve) for k in ks}  # elementwise, so slicing it equals v of the slice
    memo: dict[tuple[int, int, int], np.ndarray] = {}
    v0 = _countvar(g0, cap, curve)

    def chi(k: int, dy: int, dx: int) -> np.ndarray:
        key = (k, dy, dx)
        if key not in memo:
            factor = factors[k] if factors is not None else ADJACENT_DISPERSION if abs(k) == 1 else 1.0
            memo[key] = _tile_chi(g0, padded[k], pad, dy, dx, tile, factor * kernel_energy, cap, v0, vpad[k])
        return memo[key]

    best_cost = best_v = None
    frame: dict[tuple[float, float], float] = {}  # the whole frame's mean cost of each velocity (_global_motion)
    for vy, vx in grid:
        cost = sum(chi(k, int(round(k * vy)), int(round(k * vx))) for k in ks) / len(ks)
        frame[(vy, vx)] = float(cost.mean())
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
    return shifts, chis, frame


def match_quality(raw0: np.ndarray, rawk: np.ndarray, shifts: np.ndarray, tile: int, noise: float, cap: float,
                  curve: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Per tile, the SSD of the unsmoothed super-pixel counts at the tile's shift over its noise-only SSD.

    The search ran on smoothed guides (robust, but a tile then has only ~5 independent values); the
    acceptance uses the raw counts, whose 64 independent values per tile make the test both sharper
    and less often wrong on a static tile. ``curve``: κ by level (:func:`dispersion_curve`; ``noise`` is
    then the factor of adjacent windows only); without it ``noise`` carries one κ.
    """
    pad = int(np.abs(shifts).max(initial=0)) + 1
    padded = np.pad(rawk, pad, mode="edge")
    if curve is None:
        v0, vk = _binvar(raw0, cap), _binvar(padded, cap)
    else:
        v0, vk = _countvar(raw0, cap, curve), _countvar(padded, cap, curve)
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


def _box_same_colour(c: Any, cfa: str | None) -> Any:
    """3×3 sums over photosites of the same colour (within each Bayer plane); a torch tensor stays on its device
    (:func:`_box_torch`)."""
    from scipy.ndimage import uniform_filter

    if not isinstance(c, np.ndarray) and hasattr(c, "double"):
        if cfa is None:
            return _box_torch(c)
        out = c.new_empty(c.shape)
        for i in (0, 1):
            for j in (0, 1):
                out[i::2, j::2] = _box_torch(c[i::2, j::2])
        return out
    if cfa is None:
        return uniform_filter(c, size=3, mode="nearest") * 9.0
    out = np.empty_like(c)
    for i in (0, 1):
        for j in (0, 1):
            out[i::2, j::2] = uniform_filter(c[i::2, j::2], size=3, mode="nearest") * 9.0
    return out


def _lone(rejected: Any, accepted: Any, cfa: str | None) -> Any:
    """Photosites of ``rejected`` whose same-colour neighbours (the 8 around it within its Bayer plane, those inside
    the frame) are all in ``accepted`` but at most one (a pair of false alarms): numpy or torch boolean arrays alike
    (integer counts, so both give the same)."""
    def plane(r: Any, a: Any) -> Any:
        h, w = r.shape
        if isinstance(a, np.ndarray):
            ap, ones = np.pad(a.astype(np.int16), 1), np.pad(np.ones((h, w), np.int16), 1)
        else:
            import torch

            pad = torch.nn.functional.pad
            ap = pad(a.to(torch.int16)[None], (1, 1, 1, 1))[0]
            ones = pad(torch.ones((1, h, w), dtype=torch.int16, device=a.device), (1, 1, 1, 1))[0]
        n_acc = n_all = 0
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                if dy != 1 or dx != 1:
                    n_acc = n_acc + ap[dy:dy + h, dx:dx + w]
                    n_all = n_all + ones[dy:dy + h, dx:dx + w]
        return r & (n_acc >= n_all - 1) & (n_acc >= 1)  # a photosite with no accepted neighbour is not rescued

    if cfa is None:
        return plane(rejected, accepted)
    out = rejected & False
    for i in (0, 1):
        for j in (0, 1):
            out[i::2, j::2] = plane(rejected[i::2, j::2], accepted[i::2, j::2])
    return out


def _box_torch(c: Any) -> Any:
    """``uniform_filter(c, 3, mode="nearest") * 9`` of a float32 torch tensor, as scipy rounds it: a 3-tap mean along
    the rows, then the columns, each summed in float64 and stored as float32."""
    import torch

    def mean3(x: Any, dim: int) -> Any:
        n = x.shape[dim]
        p = torch.cat((x.narrow(dim, 0, 1), x, x.narrow(dim, n - 1, 1)), dim).double()
        return ((p.narrow(dim, 0, n) + p.narrow(dim, 1, n) + p.narrow(dim, 2, n)) / 3.0).float()

    return mean3(mean3(c.float(), 0), 1) * 9.0


#: bounds of the measured scale of a neighbour's differences over the model's (:func:`_noise_scale`)
NOISE_SCALE_RANGE = (1.0, 2.0)
#: fewest tiles from which :func:`_noise_scale` measures (fewer: the model's factor as it is)
NOISE_SCALE_TILES = 16


def _noise_scale(chi_at_rest: np.ndarray, model: float, tile_g: int) -> float:
    """The noise factor of one neighbour's differences: ``model`` (1, or :data:`ADJACENT_DISPERSION`) unless the
    tiles say otherwise. ``chi_at_rest``: the tiles' SSD at zero shift over the model's noise without the factor.
    On static tiles it follows χ²ₙ/n (n = the tile's super-pixels); its lower quartile over the tiles, divided by
    that of χ²ₙ/n, measures the factor (moving tiles only raise the upper quantiles), within :data:`NOISE_SCALE_RANGE`
    of ``model``."""
    from scipy.special import chdtri

    if chi_at_rest.size < NOISE_SCALE_TILES:
        return float(model)
    n = tile_g * tile_g
    measured = float(np.quantile(chi_at_rest, 0.25)) / (float(chdtri(n, 0.75)) / n)
    lo, hi = NOISE_SCALE_RANGE
    return float(np.clip(measured, lo * model, hi * model))


#: low light: a static tile pools windows beyond ``temporal_radius`` (at rest, each window tested as the nearer
#: ones) until its pooled count reaches :data:`LOW_LIGHT_COUNT` spikes per photosite, up to this many windows on
#: each side (±16 windows of 10 ticks = 33 windows, 16.5 ms at 20 kHz)
LOW_LIGHT_RADIUS = 16
#: the mean of one side's extension windows must match the core (the centre and the ±radius windows) within this
#: (normalised SSD of the tile's super-pixels): slow motion no single window shows accumulates past it
SIDE_CHI = 1.5
#: spikes per photosite a static tile's pooled count should reach before the pooling stops growing (10 spikes:
#: a relative noise of ~0.3/√10 ≈ 0.1 at the dispersion of a dark real pixel, κ ≈ 0.5–0.7)
LOW_LIGHT_COUNT = 10.0


# ---------------------------------------------------------------------------------------- pooling
def pool_counts(source: Any, a: int, b: int, radius: int, cfa: str | None,
                cache: WindowCache | None = None, device: Any = None) -> tuple[np.ndarray, Pooling]:
    """Pooled counts of the window ``[a, b)`` with its aligned neighbours (see the module docstring).

    ``device``: where the motion search runs (``guided.device``; ``None``/CPU: numpy, as always). On a CUDA
    device the velocity search and the match test run in torch there (:func:`_search_torch`: the same
    rules, sums in float64); the decisions per photosite are this function's, on the CPU.

    Returns:
        ``(counts, pooling)``: ``(H, W)`` float32 pooled spike counts (``counts / pooling.dtau`` is
        the pooled TFP) and what was pooled.
    """
    from scipy.ndimage import gaussian_filter

    from spikeview.errors import check_cancelled

    # room for every window a frame may pool (the low-light extension's, whose drift test reads the far ones first)
    cache = cache if cache is not None else WindowCache(2 * max(int(radius), LOW_LIGHT_RADIUS) + 3)
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
    # a dim frame that moves as a whole (a pan, a drifting mount) is aligned by its measured velocity before anything
    # else: no tile shows a pan of a photosite a window above its noise at 0.03 spikes per tick, so the windows were
    # pooled at rest and the scene smeared along the pan (±16 windows: 33 photosites at a photosite a window)
    reads: Any = cache
    glide = None
    glide_depth = LOW_LIGHT_RADIUS
    if float(n0.mean()) * (2 * radius + 1) < LOW_LIGHT_COUNT:
        # a slow drift (≤ GLIDE_REST photosites over ±radius windows) pools at rest, its support bounded by the drift
        # (_extend_at_rest): the real dark capture (0.32-0.46 photosites a window, a spinning rotor) lost detail
        # (0.694 -> 0.675 against its long exposure, NIQE 10.0 -> 11.5) when its far windows glided, where simulated
        # slow pans gained 2-3 dB; what no tile sees, a rotor's blades, a far window may hold moved
        spectra: dict = {}  # the ±8 and ±16 estimates share the group sums they both read
        v = frame_velocity(source, a, b, cache, cfa, GLIDE_SPAN, spectra)
        speed = 0.0 if v is None else float(np.hypot(*v))
        whole = frame_velocity(source, a, b, cache, cfa, spectra=spectra) if speed * radius > GLIDE_REST else None
        # the velocity over the whole span must tell the same motion (a change of speed, not another direction)
        change = np.inf if v is None or whole is None else float(np.hypot(whole[0] - v[0], whole[1] - v[1]))
        if v is not None and change <= GLIDE_AGREE * speed:
            glide_depth = int(min(LOW_LIGHT_RADIUS, max(GLIDE_SPAN, np.floor(DRIFT_LIMIT / max(change, 1e-9)))))
            # a steady motion: the whole span's estimate (twice the pairs) aligns the far windows more precisely
            glide = whole if change * LOW_LIGHT_RADIUS <= 2 * DRIFT_LIMIT else v
            reads = _Glide(cache, a, window, glide, cfa)
    f = 2  # guide pixels are 2×2 super-pixels: shifts keep the CFA phase, and the search costs a quarter
    tile_g = max(1, TILE // f)
    raw0 = _guide_raw(n0, cfa)
    cap = 4.0 * window  # a super-pixel holds at most 4 photosites × window spikes
    curve = dispersion_curve(raw0, cap)
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
    counts = {k: reads.counts(source, a + k * window, b + k * window) for k in offsets}
    raws = {k: _guide_raw(counts[k], cfa) for k in offsets}
    guides = {k: gaussian_filter(raws[k], SMOOTH, mode="reflect") for k in offsets}
    # the noise of a window-to-window difference, measured: the model's variance (κ by level, measured on the
    # centre window's finest spatial detail; adjacent windows anti-correlate) times a scale per neighbour, fitted
    # on the lower quartile of the tiles' match at rest (a real dark capture's windows two apart differ 1.28×
    # more than the spatial detail says; a quarter of the tiles at rest is enough to measure it)
    zero_g = np.zeros((-(-raw0.shape[0] // tile_g), -(-raw0.shape[1] // tile_g), 2), np.int64)
    chi0 = {k: match_quality(raw0, raws[k], zero_g, tile_g, 1.0, cap, curve) for k in offsets}
    factors = {k: _noise_scale(chi0[k], ADJACENT_DISPERSION if abs(k) == 1 else 1.0, tile_g) for k in offsets}
    on_device = getattr(device, "type", "cpu") != "cpu" or TORCH_ON_CPU  # a resolved torch.device (Observation.from_source)
    if on_device:
        motion, chis, frame = _search_torch(raw0, g0, raws, guides, window, radius, curve, kernel_energy, factors,
                                            device if device is not None else "cpu")
    else:
        motion, _, frame = estimate_motion(g0, guides, tile_g, curve, kernel_energy, radius, MAX_SPEED / f, cap, factors)
        chis = {k: match_quality(raw0, raws[k], motion[k], tile_g, factors[k], cap, curve) for k in offsets}
    # at rest: where the search found no motion, and on a dim tile (DIM_COUNT) wherever the raw counts' mean match
    # at zero shift is within REST_CHI (a real capture's darkest tiles, 0.2 spikes a window, match at rest at 1.5–2.1
    # against every neighbour alike: the model's variance is low there, nothing moves); a dim tile at rest takes each neighbour whose match is within REST_CHI
    chi0 = {k: chi0[k] / factors[k] for k in offsets}
    rest_cost = np.mean([chi0[k] for k in offsets], axis=0)
    dim = _tile_sum(raw0, tile_g) / (4.0 * tile_g * tile_g) < DIM_COUNT  # spikes per photosite in the own window
    searched = np.logical_and.reduce([np.all(motion[k] == 0, axis=-1) for k in offsets])
    pan = _global_motion(frame, zero_g.shape[0] * zero_g.shape[1], len(offsets), tile_g)
    # a panning frame's dim tiles keep their own search (held at rest, a pan's dim tiles were blurred)
    # and any tile whose zero shift passes the tile test and matches within REST_MARGIN of the velocity found: the
    # search's best of ~50 velocities beats rest by about that on a static tile by chance, and more so on a real
    # sensor's bright pixels, which fire almost regularly (a photosite's adjacent windows anticorrelate: 2, 3, 2, 3 …
    # spikes). A static regular capture had a third of its tiles 'aligned' by up to 4 px and pooled ±3 on 87 %
    best_cost = np.mean([chis[k] for k in offsets], axis=0)
    held = (rest_cost <= TILE_CHI) & (rest_cost - best_cost < REST_MARGIN)
    at_rest = (searched | ((rest_cost <= REST_CHI) & dim) | held) if pan is None else searched
    for k in offsets:
        motion[k] = np.where(at_rest[..., None], 0, motion[k])
        chis[k] = np.where(at_rest, chi0[k], chis[k])
    cap9 = 9.0 * window  # a 3×3 same-colour sum holds at most 9 × window spikes per window
    lv = 4.0 / 9.0  # a 3×3 same-colour sum's level in the curve's super-pixel (2×2) units
    # the per-photosite decisions: numpy, or torch on the alignment's device (there the host's cores, not the GPU, set
    # a clip's pace: benchmarks/gpu_profile.py); the same operations, the same float32/float64 sums
    xp = _Arrays((device if device is not None else "cpu") if on_device else None)
    total, pooled = xp.put(total), xp.put(pooled)

    def reference() -> tuple[Any, Any]:
        """What was pooled so far as a 3×3 same-colour sum per window, and that mean's variance (once per step: both
        sides of a distance are tested against the same reference)."""
        box_n = _box_same_colour(1.0 + pooled, cfa)
        ref = 9.0 * _box_same_colour(total, cfa) / box_n
        return ref, _countvar(ref, cap9, curve, lv) * 9.0 / box_n

    def pixel_ok(refs: tuple[Any, Any], nk_aligned_box: Any, factor: float) -> Any:
        """The per-photosite test: the 3×3 same-colour sum of the aligned neighbour against the pooled reference."""
        ref, ref_var = refs
        var = ref_var + _countvar(nk_aligned_box, cap9, curve, lv)
        return (ref - nk_aligned_box) ** 2 / (factor * var + 1.0) <= PIXEL_Z ** 2

    # nearest windows first; a photosite takes window k only if it took every window between k and the
    # centre (motion grows with the distance), and window k is compared with what was pooled so far
    # (the centre and the accepted nearer windows: a less noisy reference than the centre alone)
    chain = {-1: xp.full((h, w), True), 1: xp.full((h, w), True)}
    # how many windows each photosite took on each side (contiguous: the chain), and whether all at zero shift
    sides = {-1: xp.zeros((h, w), np.int64), 1: xp.zeros((h, w), np.int64)}
    still = xp.full((h, w), True)
    ty_px, tx_px = xp.put(ty_of), xp.put(tx_of)
    rows, cols = xp.put(np.arange(h)[:, None]), xp.put(np.arange(w)[None, :])
    for d in sorted({abs(k) for k in offsets}):
        oks = {}
        refs = reference()
        for k in (-d, d):  # both sides against the same reference (what the nearer windows pooled)
            if k not in counts:
                continue
            check_cancelled("while pooling the neighbouring windows")  # each window's pooling: ~0.1 s at 1000×1000
            nk = xp.put(counts[k])
            # tiles of the guide are tiles of TILE photosites (an odd last row/column of a Bayer frame
            # has no super-pixel: it takes its neighbour tile's match)
            best, chi = _fit_tiles(motion[k], th, tw), _fit_tiles(chis[k], th, tw)
            rest = _fit_tiles(at_rest & dim, th, tw)
            ok_tile = (chi <= np.where(rest, REST_CHI, TILE_CHI)) & (np.abs(best * f).max(axis=-1) <= MAX_SHIFT)
            shifts[k] = best * f
            accepted[k] = ok_tile
            # every photosite reads the neighbour at its tile's shift (the 3×3 same-colour sums shift with it)
            tile_ok_px = xp.put(ok_tile)[ty_px][:, tx_px]
            side = 1 if k > 0 else -1
            if not best.any():  # every tile at rest (a static scene, the common case): no gather, nothing moved
                candidate = chain[side] & tile_ok_px
                ok = pixel_ok(refs, _box_same_colour(nk, cfa), factors[k])
                aligned = nk
            else:
                best_px = xp.put(best * f)[ty_px][:, tx_px]
                ys, xs = rows + best_px[..., 0], cols + best_px[..., 1]
                inside = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
                ys, xs = ys.clip(0, h - 1), xs.clip(0, w - 1)
                aligned = nk[ys, xs]
                boxk = _box_same_colour(nk, cfa)[ys, xs]
                # a shifted 3×3 sum that reaches past the frame's border (edge-extended there) is not the sum
                # the centre window's photosite sees: such photosites are left out unless the shift is zero
                margin = (ys >= 2) & (ys < h - 2) & (xs >= 2) & (xs < w - 2)
                zero = (best_px[..., 0] == 0) & (best_px[..., 1] == 0)
                candidate = chain[side] & tile_ok_px & inside & (margin | zero)
                ok = pixel_ok(refs, boxk, factors[k])
            if glide is not None:  # photosites the glide moved in from outside the frame hold no data
                candidate = candidate & xp.put(reads.valid(a + k * window, (h, w)))
            weight = candidate & ok
            # a lone photosite (or pair) failing the test among same-colour neighbours that passed it (their 3×3 sums
            # hold its count) is the test's false alarm, not motion, which moves a patch: it pools with them. Without
            # this, a regular (noise-free) integrate-and-fire capture's dark photosites whose ±1 windows swung from
            # an empty 3×3 sum to a full one kept their own 10-tick window: isolated black or white dots
            missed = candidate & ~ok
            if missed.any():  # most windows reject no photosite: nothing to rescue
                weight = weight | _lone(missed, weight, cfa)
            if best.any():
                still &= ~weight | zero
            chain[side] = weight
            sides[side] += weight
            oks[k] = (weight, aligned)
        for k, (weight, aligned) in oks.items():
            xp.add_where(total, aligned, weight)
            pooled += weight
    total, pooled, still = xp.get(total), xp.get(pooled), xp.get(still)
    chain = {k: xp.get(v) for k, v in chain.items()}
    sides = {k: xp.get(v) for k, v in sides.items()}
    # low light: static tiles go on pooling at rest beyond ±radius while their pooled count is low
    far = max(abs(k) for k in offsets)
    ext: tuple[int, ...] = ()
    drift: list = []  # the frame's drift that bounded the extension (photosites a window)
    if pan is None:  # a panning frame does not grow its support at rest
        ext = _extend_at_rest(source, a, b, cfa, reads, total, pooled, chain, at_rest, curve, cap, tile_g, reference, pixel_ok,
                              far, radius, accepted, max(factors[k] for k in offsets if abs(k) == far), sides, drift,
                              valid=reads.valid if glide is not None else None, limit=glide_depth)
    if glide is not None:
        # a photosite's own history (interval_rates) saw the scene move under it: it is read over the windows in which
        # the glide moved the scene by a photosite at most (the real dark capture, 0.32 a window: ±3, as at rest; at a
        # photosite a window, ±1)
        near = int(np.floor(GLIDE_HISTORY / float(np.hypot(*glide)) + 1e-9))
        for side in (-1, 1):
            sides[side] = np.minimum(sides[side], near)
    for k in ext:
        shifts[k] = np.zeros((th, tw, 2), np.int64)
    lo = np.where(still, a - window * sides[-1], -1)
    hi = np.where(still, b + window * sides[1], -1)
    pool = Pooling(radius, window, offsets, (window * (1.0 + pooled)).astype(np.float32), shifts, accepted, extended=ext,
                   support=(lo, hi))
    if drift:
        pool.drift = drift[0]
    pool.glide = glide
    pool.kind, pool.reason = describe(pool)
    if pan is not None:
        v = _pan_measured(counts, cfa)
        vy, vx = v if v is not None else (f * pan[0], f * pan[1])
        pool.reason += (f"; the frame pans ({'' if v is not None else 'about '}{vy:+.2f}, {vx:+.2f} photosites a window, "
                        "y, x): its dim tiles are not held at rest and the support does not grow")
    return total, pool


#: the interval estimate (:func:`interval_rates`) needs this many spikes of a photosite in its support
INTERVAL_MIN_SPIKES = 2


def interval_rates(source: Any, support: tuple[np.ndarray, np.ndarray], cfa: str | None = None,
                   count_rates: np.ndarray | None = None, min_ticks: int = 0) -> np.ndarray:
    """The rate of each photosite from the **intervals** between its spikes over the ticks it pooled at rest:
    ``(n − 1) / (t_n − t_1)`` for its first and last spike ``t_1 < t_n`` in ``[lo, hi)`` (``support``,
    :attr:`Pooling.support`), ``NaN`` where it took a shifted window, pooled fewer than ``min_ticks`` ticks (a
    photosite whose neighbouring windows did not all match is near motion: its rate changes within the support, and
    with one or two intervals the estimate is TFI's own noise; on a sequence with rotating fans they cost 0.8 dB) or
    holds fewer than :data:`INTERVAL_MIN_SPIKES` spikes there.

    Why: a pixel integrates light and fires when its charge crosses the threshold, so on a static scene its spikes are
    nearly evenly spaced (real pixels fire with 0.1–0.5× the variance of binomial counts, DOMAIN.md). A count over
    the support loses up to one spike to the phase at each end (±1 of 6 spikes is 17 % at 0.03 spikes per tick); the
    spacing of the spikes inside it does not (a tick of 160 is 0.6 %). This is TFI's information (one interval) taken
    over every interval of the support: the interval rate of issue 25's deliverable 1.

    ``(n − 1) / (t_n − t_1)`` is exact for a pixel that fires evenly, but reads high for one that fires at random
    (Poisson-like: by about one spike in the support), and is noisier than the count there: when the photosites'
    intervals vary (:data:`INTERVAL_MAX_CV2`) every value is ``NaN`` and the counts stay. With ``count_rates`` (the pooled counts over the support, which
    are unbiased either way) the estimate is calibrated per level (:data:`INTERVAL_LEVELS` quantile bins of the
    same-colour 3×3 mean rate): in each, its mean is scaled to the counts' mean. So the level of each part of the
    frame is the counts', and only the pixel-to-pixel noise is the intervals'."""
    lo, hi = support
    ok = (lo >= 0) & (hi - lo >= min_ticks)
    out = np.full(lo.shape, np.nan, np.float32)
    if not ok.any():
        return out
    t0, t1 = int(lo[ok].min()), int(hi[ok].max())
    spikes = np.ascontiguousarray(source.read(t0, t1), dtype=np.uint8)
    lo_r = np.where(ok, lo - t0, 0).astype(np.int64)
    hi_r = np.where(ok, hi - t0, 0).astype(np.int64)
    n, first, last, s1, s2 = _interval_stats(spikes, lo_r, hi_r)
    many = n >= 4  # three intervals or more: their spread says how evenly the photosites fire
    if many.sum() >= 16:
        mean = s1[many] / (n[many] - 1)
        cv2 = (s2[many] / (n[many] - 1) - mean * mean) / (mean * mean)
        if float(np.median(cv2)) > INTERVAL_MAX_CV2:
            return out  # photosites that fire at random: the counts are the better estimate
    good = ok & (n >= INTERVAL_MIN_SPIKES) & (last > first)
    out[good] = ((n[good] - 1) / (last[good] - first[good])).astype(np.float32)
    if count_rates is not None:
        _calibrate_levels(out, np.asarray(count_rates, np.float32), cfa)
    return out


@numba.njit(cache=True, nogil=True)
def _interval_stats(spikes: np.ndarray, lo: np.ndarray, hi: np.ndarray):  # pragma: no cover - compiled
    """One pass over ``spikes`` ``(T, H, W)`` (time outermost, so the reads are sequential): per photosite, within
    ``[lo, hi)``, the spike count, the first and last spike's tick, and the sum and sum of squares of the intervals."""
    tt, h, w = spikes.shape
    n = np.zeros((h, w), np.int64)
    first = np.full((h, w), -1, np.int64)
    last = np.full((h, w), -1, np.int64)
    s1 = np.zeros((h, w), np.float64)
    s2 = np.zeros((h, w), np.float64)
    for t in range(tt):
        for i in range(h):
            for j in range(w):
                if spikes[t, i, j] != 0 and lo[i, j] <= t and t < hi[i, j]:
                    if n[i, j] == 0:
                        first[i, j] = t
                    else:
                        d = t - last[i, j]
                        s1[i, j] += d
                        s2[i, j] += d * d
                    last[i, j] = t
                    n[i, j] += 1
    return n, first, last, s1, s2


#: the interval rate is used while the photosites' intervals vary this little: the median over photosites with three
#: intervals or more of their squared coefficient of variation (an integrate-and-fire pixel: ~0.001, the real dark
#: capture and the simulator alike; random, Bernoulli firing: ~0.7, where the counts are the better estimate)
INTERVAL_MAX_CV2 = 0.25


#: quantile bins of the local rate in which :func:`interval_rates` matches the counts' mean
INTERVAL_LEVELS = 8


def _calibrate_levels(est: np.ndarray, counts: np.ndarray, cfa: str | None) -> None:
    """Scale ``est`` (in place, where finite) so that its mean equals ``counts``' in each level bin (the same-colour
    3×3 mean of ``counts``: a level that does not follow one pixel's own noise)."""
    ok = np.isfinite(est)
    if ok.sum() < 16:
        return
    level = _box_same_colour(counts.astype(np.float32), cfa) / 9.0
    edges = np.unique(np.quantile(level[ok], np.linspace(0.0, 1.0, INTERVAL_LEVELS + 1)))
    if edges.size < 2:
        return
    which = np.clip(np.searchsorted(edges, level, side="right") - 1, 0, edges.size - 2)
    for i in range(edges.size - 1):
        sel = ok & (which == i)
        se = float(est[sel].sum())
        if se > 0:
            est[sel] *= float(counts[sel].sum()) / se


#: a frame pans when its best velocity matches better than the opposite one by this many standard deviations of
#: that comparison (:func:`_global_motion`)
PAN_Z = 4.0


def _global_motion(frame: dict[tuple[float, float], float], tiles: int, neighbours: int,
                   tile_g: int) -> tuple[float, float] | None:
    """The frame's common velocity (guide pixels per window) when it pans, else ``None``.

    ``frame``: the search's cost of each velocity (smoothed guides) averaged over the frame's ``tiles`` tiles and its
    ``neighbours`` windows. Its best velocity
    ``v`` other than zero is tested against ``−v``: a static scene matches both alike, a pan matches ``v`` clearly
    better (:data:`PAN_Z` standard deviations of the difference, ``sqrt(4 / (n_eff · tiles · neighbours))`` relative,
    ``n_eff`` = a smoothed tile's independent values ≈ 5). Zero itself is not compared: an integrate-and-fire photosite's
    counts in two windows correlate with each other, not with a neighbour's, so at low light any shift matches a
    static scene ~10 % better than none (the velocity search's spurious motion in the dark). In low light no tile
    alone shows a pan of a photosite a window above its noise; the whole frame does, and its dim tiles are then not
    held at rest (nor pooled over a growing support: a blur). The velocity is only as fine as the search's grid."""
    moving = {v: c for v, c in frame.items() if v != (0.0, 0.0)}
    if not moving:
        return None
    vy, vx = min(moving, key=moving.get)
    back = frame.get((-vy, -vx))
    if back is None:
        return None
    n_eff = max(1.0, tile_g * tile_g / (4.0 * np.pi * SMOOTH ** 2))  # a smoothed tile's independent values
    margin = PAN_Z * float(np.sqrt(4.0 / (n_eff * max(1, tiles) * max(1, neighbours))))
    return (vy, vx) if moving[(vy, vx)] < back * (1.0 - margin) else None


#: the low-light extension stops where the frame's measured drift (:func:`frame_drift`) has moved the scene by more
#: than this many photosites since the centre window (a drift no tile's test sees at that light blurs the pool)
DRIFT_LIMIT = 0.5
#: a drift estimate is trusted when the correlation peak stands this far above its surroundings (in standard
#: deviations of the band-passed correlation surface away from it; a static simulated scene at 0.02-0.05 spikes per
#: tick peaks at 16, the real dark capture's drift at 6.7, a 0.2-photosite-a-window pan at 3.9)
DRIFT_PEAK = 3.0


def _band_fft(x: np.ndarray, sigma: float = 1.0) -> np.ndarray:
    """The 2-D FFT of ``x`` band-passed (Gaussians of ``sigma`` and ``4 sigma``: the scene's large areas make a broad
    peak that hides a shift of a few photosites) under a Hann window (:func:`frame_drift`, :func:`frame_velocity`)."""
    from scipy.ndimage import gaussian_filter

    x = np.asarray(x, np.float64)
    a = gaussian_filter(x, sigma) - gaussian_filter(x, 4 * sigma)
    return np.fft.fft2(a * np.outer(np.hanning(a.shape[0]), np.hanning(a.shape[1])))


def _correlation_peak(xc: np.ndarray, r: int, centre: tuple[int, int] = (0, 0)) -> tuple[float, float, float] | None:
    """``(dy, dx, z)``: the sub-pixel peak of the cross-correlation ``xc`` (unshifted FFT layout) within ``±r`` pixels
    of the shift ``centre`` (a parabola through the peak and its neighbours, each axis) and its height in standard
    deviations of the surface away from it; ``None`` on the search's border or below :data:`DRIFT_PEAK`."""
    h, w = xc.shape
    xc = np.fft.fftshift(xc)
    cy, cx = h // 2 + int(centre[0]), w // 2 + int(centre[1])
    if 2 * r + 1 > min(h, w):
        return None
    # the correlation is circular: rows and columns past the surface's edge wrap (a 16-px frame's ±8 search)
    sub = xc[np.ix_((cy + np.arange(-r, r + 1)) % h, (cx + np.arange(-r, r + 1)) % w)]
    iy, ix = np.unravel_index(int(np.argmax(sub)), sub.shape)
    if iy in (0, 2 * r) or ix in (0, 2 * r):
        return None
    far = np.ones_like(sub, bool)
    far[max(0, iy - 3):iy + 4, max(0, ix - 3):ix + 4] = False
    spread = float(sub[far].std())
    z = (sub[iy, ix] - sub[far].mean()) / spread if spread > 0 else 0.0
    if z < DRIFT_PEAK:
        return None

    def vertex(m: float, c: float, p: float) -> float:
        d = m - 2 * c + p
        return 0.0 if d >= 0 else 0.5 * (m - p) / d

    dy = centre[0] + iy - r + vertex(sub[iy - 1, ix], sub[iy, ix], sub[iy + 1, ix])
    dx = centre[1] + ix - r + vertex(sub[iy, ix - 1], sub[iy, ix], sub[iy, ix + 1])
    return float(dy), float(dx), float(z)


def frame_drift(first: np.ndarray, second: np.ndarray, sigma: float = 1.0) -> tuple[float, float] | None:
    """The sub-pixel shift ``(dy, dx)`` that moves ``first`` onto ``second`` (two sums of counts of one frame, in the
    same units), from the peak of their cross-correlation after a Gaussian of ``sigma`` (a parabola through the peak
    and its neighbours, each axis); ``None`` when the peak is not clear (:data:`DRIFT_PEAK`): a flat or too dark
    frame. The whole frame is one measurement, so a drift of a third of a photosite a window that no 16-px tile
    shows above its noise at 0.03 spikes per tick is measured to a few hundredths."""
    h, w = np.shape(first)
    if min(h, w) < 16 or not (np.std(first) > 0 and np.std(second) > 0):
        return None
    xc = np.fft.ifft2(np.conj(_band_fft(first, sigma)) * _band_fft(second, sigma)).real
    peak = _correlation_peak(xc, 8)  # shifts beyond ±8 photosites are not a drift (the search handles motion)
    return None if peak is None else peak[:2]


#: :func:`frame_velocity` compares sums of this many consecutive windows ...
GLIDE_GROUP = 2
#: ... this many windows apart: farther than an integrate-and-fire photosite's period at low light (a dim photosite's
#: counts in windows a few ticks apart anticorrelate, through its phase, and make a trough at zero shift that hid a
#: static scene's peak), near enough that a pan of a photosite a window stays within the search
GLIDE_LAG = 6
#: ... searching shifts up to this many photosites (4 photosites a window at the lag above; the drift view's pixels are
#: 2×2 cells on a Bayer mosaic, photosites in monochrome: a monochrome pan of 3 photosites a window was missed)
GLIDE_REACH = 24
#: ... on the frame's central crop of at most this many pixels a side (the drift of the whole frame is one number)
GLIDE_CROP = 384
#: the glide's velocity is measured on the windows within this many of the centre (the velocity there); where the
#: whole ±:data:`LOW_LIGHT_RADIUS` span gives another, the motion changes speed (the real dark capture's drift grows
#: from 0.28 to 0.57 photosites a window over its 200 ticks) and the glided support stops where the two would part by
#: :data:`DRIFT_LIMIT`
GLIDE_SPAN = 8
#: a glided photosite's rate is read from the intervals between its own spikes (:func:`interval_rates`) over the
#: windows in which the scene moved this many photosites at most under it
GLIDE_HISTORY = 1.0
#: a dim frame glides when its velocity moves the scene by more than this many photosites over ±radius windows
#: (pooled at rest, they would smear it by more than a photosite each way)
GLIDE_REST = 1.5
#: ... and when the velocity over the whole ±LOW_LIGHT_RADIUS span is within this fraction of the local one
GLIDE_AGREE = 0.5


def frame_velocity(source: Any, a: int, b: int, cache: "WindowCache", cfa: str | None,
                   span: int = LOW_LIGHT_RADIUS, spectra: dict | None = None) -> tuple[float, float] | None:
    """The whole frame's velocity ``(vy, vx)`` in photosites per window around the window ``[a, b)``, or ``None``.

    Measured on the windows within ±``span`` of it that lie in the capture: the cross-correlations of
    every pair of :data:`GLIDE_GROUP`-window sums :data:`GLIDE_LAG` windows apart are added (one surface from the
    whole span: a dim frame's single pair is noise), and the peak within ±:data:`GLIDE_REACH` photosites, divided by
    the lag, is the velocity. Unlike comparing the two far sides of the span (:func:`_extension_drift`), no sum is
    blurred by the motion it measures: at a photosite a window, two 13-window sums are each smeared by 13
    photosites, and the sensor's fixed pattern (which does not move) then made a pan read as static."""
    window = int(b - a)
    n = int(source.n_frames)
    ks = [k for k in range(-int(span), int(span) + 1) if a + k * window >= 0 and b + k * window <= n]

    def pairs(lag: int) -> list[int]:
        return [k for k in ks if k + GLIDE_GROUP - 1 in ks and k + lag in ks and k + lag + GLIDE_GROUP - 1 in ks]

    starts = pairs(GLIDE_LAG)
    if not starts:
        return None
    view, unit = _drift_view(cfa)
    # the group sums' spectra, by the group's first window: ``spectra`` shares them between calls about one window
    ffts: dict[int, np.ndarray] = spectra if spectra is not None else {}

    def spectrum(k: int) -> np.ndarray:
        if k not in ffts:
            x = view(sum(cache.counts(source, a + j * window, b + j * window).astype(np.float64)
                         for j in range(k, k + GLIDE_GROUP)))
            h, w = x.shape
            ch, cw = min(h, GLIDE_CROP), min(w, GLIDE_CROP)
            ffts[k] = _band_fft(x[(h - ch) // 2:(h - ch) // 2 + ch, (w - cw) // 2:(w - cw) // 2 + cw])
        return ffts[k]

    first = spectrum(starts[0])
    reach = int(np.ceil(GLIDE_REACH / unit))  # in the view's pixels
    if min(first.shape) < 4 * reach:
        return None
    xc = sum(np.fft.ifft2(np.conj(spectrum(k)) * spectrum(k + GLIDE_LAG)).real for k in starts)
    peak = _correlation_peak(xc, reach)
    if peak is None:
        return None
    vy, vx = peak[0] / GLIDE_LAG, peak[1] / GLIDE_LAG
    # refined at twice the lag, around where that puts the peak: a sub-pixel error of the first estimate grows with
    # the windows a support reaches (1.04 for 1.00 misaligned the farthest windows by a photosite), and the fixed
    # pattern's peak at zero, which pulls a slow pan's estimate toward rest, lies twice as far from it
    # and it must be found there, within a pixel of the lag's estimate: a static scene whose photosites fire regularly
    # (a noise-free simulator) has counts that anticorrelate at some lags, and its surface then peaks off zero by chance
    far = pairs(2 * GLIDE_LAG)
    if not far:
        return None
    xc = sum(np.fft.ifft2(np.conj(spectrum(k)) * spectrum(k + 2 * GLIDE_LAG)).real for k in far)
    fine = _correlation_peak(xc, 6, (int(round(2 * GLIDE_LAG * vy)), int(round(2 * GLIDE_LAG * vx))))
    if fine is None:
        return None
    fy, fx = fine[0] / (2 * GLIDE_LAG), fine[1] / (2 * GLIDE_LAG)
    if max(abs(fy - vy), abs(fx - vx)) > 1.0 / GLIDE_LAG:
        return None
    return unit * fy, unit * fx


def _drift_view(cfa: str | None) -> tuple[Any, float]:
    """How :func:`frame_drift` sees a window's counts, and the photosites one of its pixels spans: a Bayer mosaic as
    2×2 super-pixels (its colour pattern would correlate with itself at even shifts), a monochrome frame as is."""
    return ((lambda x: _guide_raw(x, cfa)), 2.0) if cfa is not None else ((lambda x: x), 1.0)


def _pan_measured(counts: dict[int, np.ndarray], cfa: str | None) -> tuple[float, float] | None:
    """A panning frame's velocity in photosites per window for the plan: the whole frame's shift
    (:func:`frame_drift`) between the farthest pair of neighbouring windows ``±k`` whose shift it can measure (nearer
    pairs for a faster pan), divided by ``2k``; ``None`` when no pair gives one (the search's grid velocity is said)."""
    view, unit = _drift_view(cfa)
    for k in sorted((k for k in counts if k > 0 and -k in counts), reverse=True):
        d = frame_drift(view(counts[-k].astype(np.float64)), view(counts[k].astype(np.float64)))
        if d is not None:
            return unit * d[0] / (2 * k), unit * d[1] / (2 * k)
    return None


def _extension_drift(source: Any, a: int, b: int, cache: WindowCache, core: np.ndarray, reached: int,
                     cfa: str | None = None) -> tuple[float, float] | None:
    """The frame's drift in photosites per window over the windows the extension may pool: the sum of the far
    windows on one side against the other (or against the core when one side lies outside the capture), divided by
    their distance in windows; ``None`` when it cannot be measured."""
    window = b - a
    n = int(source.n_frames)
    sides = {s: [k for k in range(s * (reached + 1), s * (LOW_LIGHT_RADIUS + 1), s)
                 if a + k * window >= 0 and b + k * window <= n] for s in (-1, 1)}
    view, unit = _drift_view(cfa)
    core = view(core)
    sums = {s: (view(sum(cache.counts(source, a + k * window, b + k * window).astype(np.float64) for k in ks)),
                float(np.mean(ks))) for s, ks in sides.items() if ks}
    if -1 in sums and 1 in sums:
        (left, kl), (right, kr) = sums[-1], sums[1]
        scale = len(sides[-1]) / len(sides[1])
        d = frame_drift(left, right * scale)
        span = kr - kl
    elif sums:
        s, (far, kf) = next(iter(sums.items()))
        d = frame_drift(core, far) if s > 0 else frame_drift(far, core)
        span = abs(kf)
    else:
        return None
    if d is None or span <= 0:
        return None
    return unit * d[0] / span, unit * d[1] / span


def _extend_at_rest(source: Any, a: int, b: int, cfa: str | None, cache: WindowCache, total: np.ndarray,
                    pooled: np.ndarray, chain: dict[int, np.ndarray], at_rest: np.ndarray,
                    curve: tuple[np.ndarray, np.ndarray], cap: float, tile_g: int, reference: Any, pixel_ok: Any, reached: int,
                    radius: int, accepted: dict[int, np.ndarray], factor: float,
                    sides: dict[int, np.ndarray] | None = None, drift_out: list | None = None,
                    valid: Any = None, limit: int = LOW_LIGHT_RADIUS) -> tuple[int, ...]:
    """Pool windows ``reached + 1 …`` at zero shift on static tiles whose pooled count is below
    :data:`LOW_LIGHT_COUNT` per photosite (in place on ``total``, ``pooled``, ``chain``), up to
    :data:`LOW_LIGHT_RADIUS` windows a side. A tile takes window ``k`` when it was at rest and matched every
    nearer window, and its raw counts match what it pooled so far (:data:`TILE_CHI`); a photosite, when it
    took every nearer window on that side and passes the 3×3 test (``accepted[k]``: the tiles that took some of
    window ``k``; ``factor``: the measured noise scale of the farthest ±radius neighbour). Returns the offsets pooled from."""
    from spikeview.errors import check_cancelled

    window = b - a
    h, w = total.shape
    th, tw = -(-h // TILE), -(-w // TILE)
    ty_of, tx_of = np.arange(h) // TILE, np.arange(w) // TILE
    rest_px = _fit_tiles(at_rest, th, tw)[ty_of][:, tx_of]
    out: list[int] = []
    if reached < radius:  # the capture's edge already cut the ±radius windows: nothing beyond them either
        return ()
    # the core (the centre and what the ±radius stage pooled), frozen: each side's extension, as a whole, is compared
    # with it too, so slow motion that no single window shows above its noise is caught as it accumulates
    core_t, core_n = _guide_raw(total, cfa), _guide_raw(1.0 + pooled, cfa)
    core = 4.0 * core_t / np.maximum(core_n, 1.0)
    core_var = _countvar(core, cap, curve) * 4.0 / np.maximum(core_n, 1.0)
    side_t = {-1: np.zeros_like(total), 1: np.zeros_like(total)}
    side_n = {-1: np.zeros_like(total), 1: np.zeros_like(total)}
    deepest = min(LOW_LIGHT_RADIUS, int(limit))  # a glided frame's support ends where its speed is not known (GLIDE_SPAN)
    for d in range(reached + 1, LOW_LIGHT_RADIUS + 1):
        need_tile = _tile_sum(total, TILE) < LOW_LIGHT_COUNT * _tile_sum(np.ones_like(total), TILE)
        need = need_tile[ty_of][:, tx_of] & rest_px
        ks = [k for k in (-d, d) if a + k * window >= 0 and b + k * window <= int(source.n_frames)]
        if not ks or not (need & (chain[-1] | chain[1])).any():
            break
        if d == reached + 1:
            # a slow drift of the whole frame that no tile shows at this light, measured on the whole frame, bounds
            # the support: beyond DRIFT_LIMIT photosites of drift since the centre, pooling at rest is a blur (the real
            # dark capture drifts 0.36 photosites a window: ±9 windows at rest smeared its rotor blades)
            v = _extension_drift(source, a, b, cache, total, reached, cfa)
            if v is not None and float(np.hypot(*v)) * LOW_LIGHT_RADIUS > DRIFT_LIMIT:
                deepest = min(deepest, int(np.floor(DRIFT_LIMIT / float(np.hypot(*v)) + 1e-9)))
                if drift_out is not None:
                    drift_out.append(v)
        if d > deepest:
            break
        oks = {}
        refs = reference()  # both sides against what was pooled so far
        pt, pn = _guide_raw(total, cfa), _guide_raw(1.0 + pooled, cfa)
        ref = 4.0 * pt / np.maximum(pn, 1.0)
        ref_var = _countvar(ref, cap, curve) * 4.0 / np.maximum(pn, 1.0)
        for k in ks:
            side = 1 if k > 0 else -1
            cand = need & chain[side]
            if not cand.any():
                continue
            check_cancelled("while pooling the neighbouring windows")
            nk = cache.counts(source, a + k * window, b + k * window)
            # the tile test against what was pooled so far (a mean per window: its variance shrinks with the windows)
            rk = _guide_raw(nk, cfa)
            var = ref_var + _countvar(rk, cap, curve)
            dd = ref - rk
            chi = _tile_sum(dd * dd, tile_g) / (factor * _tile_sum(var, tile_g) + 1e-6)
            # the side as a whole (its accepted windows and this one, where the photosite is a candidate) against the core
            st_, sn_ = _guide_raw(side_t[side] + np.where(cand, nk, 0.0), cfa), _guide_raw(side_n[side] + cand, cfa)
            has = sn_ > 0
            sm = 4.0 * st_ / np.maximum(sn_, 1.0)
            dv = np.where(has, core - sm, 0.0)
            vv = np.where(has, core_var + _countvar(sm, cap, curve) * 4.0 / np.maximum(sn_, 1.0), 0.0)
            chi_side = _tile_sum(dv * dv, tile_g) / (factor * _tile_sum(vv, tile_g) + 1e-6)
            ok_tile = _fit_tiles((chi <= REST_CHI) & (chi_side <= SIDE_CHI), th, tw)[ty_of][:, tx_of]
            ok = pixel_ok(refs, _box_same_colour(nk, cfa), factor)
            if valid is not None:  # a glided window (:class:`_Glide`): what it moved in from outside holds no data
                cand = cand & valid(a + k * window, (h, w))
            weight = cand & ok_tile & ok
            missed = cand & ok_tile & ~ok
            if missed.any():
                weight = weight | _lone(missed, weight, cfa)  # the test's false alarm (pool_counts)
            chain[side] = weight
            if weight.any():
                oks[k] = (weight, nk)
                accepted[k] = _tile_sum(weight.astype(np.float32), TILE) > 0
                side_t[side] += np.where(weight, nk, 0.0).astype(np.float32)
                side_n[side] += weight
                if sides is not None:
                    sides[side] += weight
        for k, (weight, nk) in oks.items():
            total += np.where(weight, nk, 0.0).astype(np.float32)
            pooled += weight
            out.append(k)
        if not oks:
            break
    return tuple(out)


def _search_torch(raw0: np.ndarray, g0: np.ndarray, raws: dict[int, np.ndarray], guides: dict[int, np.ndarray],
                  window: int, radius: int, curve: tuple[np.ndarray, np.ndarray], kernel_energy: float,
                  factors: dict[int, float], device: Any) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict]:
    """:func:`estimate_motion` and :func:`match_quality` in torch on ``device`` (a GPU; tests run it on the CPU).

    The per-tile normalised SSD of every candidate shift of every neighbour at once (float64 tile sums; the
    variances are :func:`_countvar`'s, computed on the CPU), the velocity search with its speed penalty (the
    first minimum in the same grid order), then the match test on the unsmoothed counts at the chosen shifts.
    Returns ``(shifts, chis, frame)`` as numpy, as the numpy pair does.
    """
    import torch
    import torch.nn.functional as F

    from spikeview.errors import check_cancelled

    dev = torch.device(device)
    f = 2
    tile = max(1, TILE // f)
    cap = 4.0 * window
    ks = sorted(guides)
    grid = _velocity_grid(radius, MAX_SPEED / f)

    def up(x: np.ndarray) -> Any:
        return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32)).to(dev, non_blocking=True)

    def tile_sums(x: Any) -> Any:  # (S, h, w) float32 -> (S, th, tw) float64 sums over tile × tile blocks
        s_, h_, w_ = x.shape
        th_, tw_ = -(-h_ // tile), -(-w_ // tile)
        x = F.pad(x, (0, tw_ * tile - w_, 0, th_ * tile - h_)).double()
        return x.view(s_, th_, tile, tw_, tile).sum(dim=(2, 4))

    def chi_all(ref: np.ndarray, other: np.ndarray, shifts: list[tuple[int, int]], noise: float) -> Any:
        """(S, th, tw) normalised SSD of ``ref`` against the edge-padded ``other`` at each shift."""
        pad = max(max(abs(dy), abs(dx)) for dy, dx in shifts) + 1
        o_pad = np.pad(other, pad, mode="edge")
        padded, vpad = up(o_pad), up(_countvar(o_pad, cap, curve))
        ref_t, v0 = up(ref), up(_countvar(ref, cap, curve))
        h_, w_ = ref.shape
        out = []
        for i in range(0, len(shifts), 32):  # bounded memory: 32 shifted copies at a time
            check_cancelled("while aligning the neighbouring windows")
            part = shifts[i:i + 32]
            sl = torch.stack([padded[pad + dy:pad + dy + h_, pad + dx:pad + dx + w_] for dy, dx in part])
            vs = torch.stack([vpad[pad + dy:pad + dy + h_, pad + dx:pad + dx + w_] for dy, dx in part])
            d = ref_t[None] - sl
            v = v0[None] + vs
            out.append(tile_sums(torch.minimum(d * d, CHI_CLIP * noise * v + 1e-6)) / (noise * tile_sums(v) + 1e-6))
        return torch.cat(out)

    cost = None
    cand: dict[int, list[tuple[int, int]]] = {}
    for k in ks:
        sh = [(int(round(k * vy)), int(round(k * vx))) for vy, vx in grid]
        uniq = sorted(set(sh))
        cand[k] = uniq
        pos = {s_: i for i, s_ in enumerate(uniq)}
        index = torch.tensor([pos[s_] for s_ in sh], device=dev)
        term = chi_all(g0, guides[k], uniq, factors[k] * kernel_energy)[index]  # (V, th, tw)
        cost = term if cost is None else cost + term
    assert cost is not None
    pen = torch.tensor([SHIFT_PENALTY * float(np.hypot(vy, vx)) for vy, vx in grid], dtype=torch.float64, device=dev)
    cost = cost / len(ks) + pen[:, None, None]
    frame_t = (cost - pen[:, None, None]).mean(dim=(1, 2)).cpu().numpy()
    frame = {v: float(c) for v, c in zip(grid, frame_t)}
    best = torch.argmin(cost, dim=0)  # the first minimum, as the numpy search's strict "<" keeps
    vel = torch.tensor(grid, dtype=torch.float64, device=dev)[best]  # (th, tw, 2)
    motion: dict[int, np.ndarray] = {}
    chis: dict[int, np.ndarray] = {}
    for k in ks:
        sh = torch.round(k * vel).long()  # np.rint, half to even, as torch.round
        lut = {s_: i for i, s_ in enumerate(cand[k])}
        sel = torch.tensor([lut[(dy, dx)] for dy, dx in sh.view(-1, 2).tolist()], device=dev).view(sh.shape[:2])
        raw_chi = chi_all(raw0, raws[k], cand[k], factors[k])
        motion[k] = sh.cpu().numpy().astype(np.int64)
        chis[k] = torch.gather(raw_chi, 0, sel[None]).squeeze(0).cpu().numpy()
    return motion, chis, frame


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
    # tiles that took a neighbour at a shift, of those that took one at all (a few edge tiles of a static scene may)
    took = [pool.accepted[k] for k in pool.offsets]
    shifted = [pool.accepted[k] & (np.abs(pool.shifts[k]).max(axis=-1) > 0) for k in pool.offsets]
    moving = float(np.sum([s_.sum() for s_ in shifted])) / max(1.0, float(np.sum([t.sum() for t in took])))
    span = (f"±{pool.radius} windows" if len(set(abs(k) for k in pool.offsets)) == pool.radius and m == 2 * pool.radius
            else f"{m} neighbouring windows (the capture's edge cuts the rest)")
    eff = f"Δτ_eff {float(pool.dtau.mean()):.0f} of {pool.window * (m + 1)} ticks on average"
    if pool.extended:
        far = max(abs(k) for k in pool.extended)
        more = float((nb > m + 1e-6).mean())
        eff = (f"Δτ_eff {float(pool.dtau.mean()):.0f} ticks on average, up to {float(pool.dtau.max()):.0f}: low light, "
               f"{100 * more:.0f}% of photosites (static tiles under {LOW_LIGHT_COUNT:g} spikes) went on "
               f"{'with the glide' if pool.glide is not None else 'at rest'} "
               f"to ±{far} windows, the bound is ±{LOW_LIGHT_RADIUS}")
    if pool.drift is not None:
        v = float(np.hypot(*pool.drift))
        depth = max(pool.radius, int(np.floor(DRIFT_LIMIT / v + 1e-9)) if v > 0 else LOW_LIGHT_RADIUS)
        why = (f"the ±{pool.radius} windows already span {v * pool.radius:.1f} photosites of it each way"
               if depth <= pool.radius else f"beyond, the scene has moved more than {DRIFT_LIMIT:g} photosite")
        eff += (f"; the whole frame drifts {v:.2f} photosites a window ({pool.drift[0]:+.2f}, {pool.drift[1]:+.2f}, y, x), "
                f"so the support stops at ±{depth} windows ({why})")
    some = "" if full >= 0.995 else f", at least one neighbour on {100 * (1.0 - own):.0f}%"
    if pool.glide is not None:
        gy, gx = pool.glide
        return "aligned", (f"moving: the whole frame glides {float(np.hypot(gy, gx)):.2f} photosites a window ({gy:+.2f}, "
                           f"{gx:+.2f}, y, x; measured on the whole frame over up to ±{LOW_LIGHT_RADIUS} windows), so every neighbouring window was moved "
                           f"back by it before pooling; then {span} pooled on {100 * full:.0f}% of photosites{some} ({eff})")
    if full >= 0.9 and moving <= 0.05:
        still = "" if smax == 0 else f"; {100 * moving:.0f}% of the tiles aligned, shifts up to {smax} px"
        return "static", f"static: {span} pooled on {100 * full:.0f}% of photosites{some} ({eff}{still})"
    if own >= 0.75:
        return "fast motion", (f"fast motion: own window only on {100 * own:.0f}% of photosites (the neighbours do not match "
                               f"within their noise; {eff})")
    if min(mean_nb, m) >= 0.75 * m:
        return "aligned", f"moving: {span} aligned (shifts up to {smax} px) and pooled on {100 * full:.0f}% of photosites{some} ({eff})"
    return "mixed", (f"mixed motion: {min(mean_nb, m):.1f} of {m} neighbouring windows pooled on average, own window only on "
                     f"{100 * own:.0f}% of photosites (shifts up to {smax} px; {eff})")
