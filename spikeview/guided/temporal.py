"""Motion-aware temporal support: borrow the photons of neighbouring windows where the motion allows.

The output frame stays the instant at its window's centre, but the guided reconstruction may draw on
the spikes of the ``radius`` windows of ``window`` ticks on each side (``guided.temporal_radius``;
0 = the paper's single window). It is a burst-merging problem (METHOD.md "Video"): align each
neighbour to the centre window, then merge with per-photosite weights that fall back to the centre
window where the match fails.

**Align.** Each window's counts are summed over 2×2 super-pixels (Bayer: one super-pixel per CFA
period, so every shift keeps the CFA phase; monochrome: full resolution) and smoothed by a Gaussian
(σ = :data:`SMOOTH` guide pixels). For every :data:`TILE`-pixel tile the neighbour ``k`` windows
away is matched to the centre window by exhaustive integer block matching within ``±(1 + 2|k|)``
guide pixels (capped at :data:`MAX_SEARCH`): the cost is the tile's sum of squared differences plus
a small penalty per pixel of displacement (:data:`SHIFT_PENALTY` of the noise-only SSD), so that
flat and static tiles keep a zero shift rather than one chosen by the noise.

**Decide.** A tile's best match is accepted when its SSD is within :data:`TILE_CHI` times what the
noise alone gives (``E[SSD] = Σ κ·Σk²·(g₀ + g_k)``: Poisson-like counts whose variance/mean ratio
``κ`` is measured on the centre window, :func:`count_dispersion`). Inside an accepted tile every
photosite is checked again: the 3×3 sums of same-colour photosites of the centre and the aligned
neighbour must agree within :data:`PIXEL_Z` standard deviations (occlusions, an edge the tile's
shift does not fit, something fast inside a slow tile). Weights are 0 or 1: a photosite either
takes a neighbour's whole window or none of it.

**What the data term sees.** The pooled observation is ``y = N / Δτ_eff`` with ``N`` the pooled
count and ``Δτ_eff = window · (1 + pooled neighbours)`` per photosite
(:attr:`~spikeview.guided.observation.Observation.dtau`), so the binomial noise model, the noise
weights and the quantiser Q (step ``1/Δτ_eff``, :class:`PooledQuantise`) stay exact for every photosite.

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
#: a tile's match is accepted when its SSD is at most this many times the noise-only SSD
TILE_CHI = 2.0
#: per-photosite test: 3×3 same-colour sums must agree within this many standard deviations
PIXEL_Z = 2.5
#: largest radius accepted by the config
MAX_RADIUS = 8


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

    def neighbours(self) -> np.ndarray | None:
        """``(H, W)`` float32 number of neighbouring windows pooled per photosite (the pooling map), or None."""
        if self.dtau is None:
            return None
        return (self.dtau / float(self.window) - 1.0).astype(np.float32)

    def crop(self, y0: int, y1: int, x0: int, x1: int) -> "Pooling":
        """The same pooling on the photosites ``[y0:y1, x0:x1]`` (tile maps kept whole)."""
        d = None if self.dtau is None else self.dtau[y0:y1, x0:x1]
        return Pooling(self.radius, self.window, self.offsets, d, self.shifts, self.accepted, self.kind, self.reason)


# --------------------------------------------------------------------------------- window reads
class WindowCache:
    """Counts of recently read windows (a sequence's consecutive frames share most neighbours)."""

    def __init__(self, size: int = 24):
        self.size = int(size)
        self._d: OrderedDict[tuple[int, int, int], np.ndarray] = OrderedDict()

    def counts(self, source: Any, a: int, b: int) -> np.ndarray:
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
def _guide_raw(counts: np.ndarray, cfa: str | None) -> np.ndarray:
    """Counts summed over 2×2 super-pixels (Bayer) or as they are (monochrome), float32."""
    c = counts.astype(np.float32, copy=False)
    if cfa is None:
        return c
    h2, w2 = (c.shape[0] // 2) * 2, (c.shape[1] // 2) * 2
    return c[0:h2:2, 0:w2:2] + c[1:h2:2, 0:w2:2] + c[0:h2:2, 1:w2:2] + c[1:h2:2, 1:w2:2]


def count_dispersion(raw: np.ndarray, keep: float = 0.9) -> float:
    """Variance/mean ratio κ of counts, in [0.05, 4].

    Per 2×2 block the finest diagonal Haar detail ``HH = (a − b − c + d)/2`` has the counts' variance
    (``κ ×`` their mean) and is nearly blind to smooth content; ``κ = Σ HH² / Σ mean`` over the
    blocks, leaving out the ``1 − keep`` of blocks with the largest ``HH² / (mean + 1)`` (edges), and
    corrected for the trimming as in :func:`spikeview.guided.observation.haar_noise_variance`. A ratio
    per block, so a bright region does not set the noise of a dark one.
    """
    from spikeview.guided.observation import _trim_factor

    h2, w2 = (raw.shape[0] // 2) * 2, (raw.shape[1] // 2) * 2
    if h2 < 2 or w2 < 2:
        return 1.0
    p = raw[:h2, :w2].astype(np.float64)
    a, b, c, d = p[0::2, 0::2], p[0::2, 1::2], p[1::2, 0::2], p[1::2, 1::2]
    hh2 = (((a - b - c + d) / 2.0) ** 2).ravel()
    m = ((a + b + c + d) / 4.0).ravel()
    ratio = hh2 / (m + 1.0)
    kept = ratio <= np.quantile(ratio, keep)
    if float(m[kept].sum()) <= 0:
        return 1.0
    return float(np.clip(hh2[kept].sum() / m[kept].sum() / (_trim_factor(keep) / keep), 0.05, 4.0))


def _tile_sum(x: np.ndarray, t: int) -> np.ndarray:
    h, w = x.shape
    th, tw = -(-h // t), -(-w // t)
    p = np.zeros((th * t, tw * t), dtype=np.float64)
    p[:h, :w] = x
    return p.reshape(th, t, tw, t).sum(axis=(1, 3))


def _shifted(img: np.ndarray, dy: int, dx: int, fill: float = np.nan) -> np.ndarray:
    """``out[y, x] = img[y + dy, x + dx]`` (``fill`` outside)."""
    h, w = img.shape
    out = np.full(img.shape, fill, dtype=img.dtype)
    ys, ye = max(0, -dy), min(h, h - dy)
    xs, xe = max(0, -dx), min(w, w - dx)
    if ys < ye and xs < xe:
        out[ys:ye, xs:xe] = img[ys + dy:ye + dy, xs + dx:xe + dx]
    return out


def _tile_chi(g0: np.ndarray, gk: np.ndarray, pad: int, dy: int, dx: int, tile: int, noise: float) -> np.ndarray:
    """Per tile: SSD between ``g0`` and the edge-padded ``gk`` read at ``(y + dy, x + dx)``, over the
    noise-only SSD ``Σ noise·(g₀ + g_k)``."""
    h, w = g0.shape
    s = gk[pad + dy:pad + dy + h, pad + dx:pad + dx + w]
    return _tile_sum((g0 - s) ** 2, tile) / (_tile_sum(noise * (g0 + s), tile) + 1e-6)


def estimate_motion(g0: np.ndarray, guides: dict[int, np.ndarray], tile: int, kappa: float,
                    kernel_energy: float, radius: int, max_speed: float = MAX_SPEED) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
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
    memo: dict[tuple[int, int, int], np.ndarray] = {}

    def chi(k: int, dy: int, dx: int) -> np.ndarray:
        key = (k, dy, dx)
        if key not in memo:
            factor = ADJACENT_DISPERSION if abs(k) == 1 else 1.0
            memo[key] = _tile_chi(g0, padded[k], pad, dy, dx, tile, factor * kappa * kernel_energy)
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
                cache: WindowCache | None = None) -> tuple[np.ndarray, Pooling]:
    """Pooled counts of the window ``[a, b)`` with its aligned neighbours (see the module docstring).

    Returns:
        ``(counts, pooling)``: ``(H, W)`` float32 pooled spike counts (``counts / pooling.dtau`` is
        the pooled TFP) and what was pooled.
    """
    from scipy.ndimage import gaussian_filter

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
    f = 1 if cfa is None else 2
    tile_g = max(1, TILE // f)
    raw0 = _guide_raw(n0, cfa)
    kappa = count_dispersion(raw0)
    # variance of a Gaussian-smoothed white-noise image: Σ k² = 1 / (4πσ²) (σ >= ~0.7)
    kernel_energy = 1.0 / (4.0 * np.pi * SMOOTH ** 2)
    g0 = gaussian_filter(raw0, SMOOTH, mode="reflect")
    box0 = _box_same_colour(n0, cfa)
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
    motion, chis = estimate_motion(g0, guides, tile_g, kappa, kernel_energy, radius, MAX_SPEED / f)
    for k in offsets:
        nk = counts[k]
        # tiles of the guide are tiles of TILE photosites (an odd last row/column of a Bayer frame
        # has no super-pixel: it takes its neighbour tile's match)
        best, chi = _fit_tiles(motion[k], th, tw), _fit_tiles(chis[k], th, tw)
        factor = ADJACENT_DISPERSION if abs(k) == 1 else 1.0
        ok_tile = chi <= TILE_CHI
        shifts[k] = best * f
        accepted[k] = ok_tile
        weight = np.zeros((h, w), dtype=bool)
        aligned = np.zeros((h, w), dtype=np.float32)
        tile_ok_px = ok_tile[ty_of][:, tx_of]
        best_px = best[ty_of][:, tx_of]
        for dy, dx in {tuple(v) for v in best[ok_tile].reshape(-1, 2).tolist()}:
            sel = tile_ok_px & (best_px[..., 0] == dy) & (best_px[..., 1] == dx)
            s = _shifted(nk, f * dy, f * dx)
            inside = ~np.isnan(s)
            s0 = np.where(inside, s, 0.0).astype(np.float32)
            boxk = _box_same_colour(s0, cfa)
            # the 3×3 sums near the frame border read zeros outside: the test rejects them
            z2 = (box0 - boxk) ** 2 / (factor * kappa * (box0 + boxk) + 1.0)
            good = sel & inside & (z2 <= PIXEL_Z ** 2)
            weight |= good
            aligned = np.where(good, s0, aligned)
        total += np.where(weight, aligned, 0.0).astype(np.float32)
        pooled += weight
    dtau = (window * (1.0 + pooled)).astype(np.float32)
    pool = Pooling(radius, window, offsets, dtau, shifts, accepted)
    pool.kind, pool.reason = describe(pool)
    return total, pool


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


# ------------------------------------------------------------------------------------ quantiser
def pooled_quantise(dtau: Any, k: float) -> Any:
    """Q with a per-photosite step ``1/Δτ_eff`` (``dtau``: ``(1, 1, H, W)`` tensor of ticks)."""
    import torch
    from torch import nn

    from spikeview.ops.quantise import _check_k

    class PooledQuantise(nn.Module):
        """Soft quantisation to multiples of ``1/Δτ_eff`` per photosite (the formula of :func:`spikeview.ops.quantise.soft_quantise`)."""

        def __init__(self, n: torch.Tensor, kk: float):
            super().__init__()
            self.register_buffer("n", n.to(torch.float32))
            self.k = _check_k(kk)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            n = self.n.to(x.dtype)
            step = 1.0 / n
            with torch.no_grad():
                cell = torch.minimum(torch.floor(x * n).clamp_min(0), n - 1)
            lower = cell * step
            mid = lower + 0.5 * step
            phi = 0.5 * (torch.tanh(self.k * (x - mid)) + 1.0)
            return lower + step * phi

        def extra_repr(self) -> str:
            return f"window=per-photosite Δτ_eff, k={self.k}"

    return PooledQuantise(torch.as_tensor(dtau), k)
