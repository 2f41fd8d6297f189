"""Per-tile plan and tiled sampling: leave out what each part of the frame does not need.

With ``guided.tile = T`` (pixels, 0 = off) a frame larger than ``T`` is split into tiles of about
``T × T`` that overlap by :data:`OVERLAP` pixels (more than FFDNet's receptive field, 24 pixels at
full resolution, so every kept pixel sees the same neighbourhood as in the whole frame). For each
tile the plan measures the noise σ of the corrected TFP estimate on that tile alone
(:func:`~spikeview.guided.plan.estimate_sigma`) and decides:

* **skipped** — σ at or below ``noise_target``: no diffusion, the tile gets the frame's fallback
  (TFP where σ <= target/4, else one FFDNet pass);
* **short** — the noise the prior is told (``σ · sigma_scale``) is below ``t_start / 2``: the tile
  starts at ``2 σ · sigma_scale`` instead of ``t_start`` and takes only the steps of the frame's
  geometric schedule below that level;
* **full** — the whole schedule.

Tiles are blended with linear ramps across the overlap (weights 1 inside, falling to 0 at a tile
edge that lies inside the frame), and every tile's start noise is cut from one noise field drawn
for the whole frame with the run's seed, so a tiled run of a uniform scene matches the whole-frame
run away from the frame's borders (``tests/test_guided_tiles.py``). Memory follows the tile, not
the frame.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spikeview.errors import Cancelled, is_cancelled
from spikeview.guided.observation import Observation

#: overlap between neighbouring tiles (pixels; even, so crops keep the CFA phase)
OVERLAP = 48
#: pixels at a tile's inner edge that get no weight in the blend (they see the tile's zero padding)
HALO = 16
#: a tile is "short" when the noise the prior is told is below this fraction of t_start
SHORT_FRACTION = 0.5
KINDS = ("skipped", "short", "full")


@dataclass
class Tile:
    """One tile: photosites ``[y0:y1, x0:x1]`` (overlap included) and what it gets."""

    y0: int
    y1: int
    x0: int
    x1: int
    kind: str
    sigma: float
    steps: int = 0
    t_start: float = 0.0
    fallback: str = ""


@dataclass
class TileMap:
    """The per-tile plan of one frame."""

    shape: tuple[int, int]
    size: int
    rows: int
    cols: int
    tiles: list[Tile] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        return {k: sum(t.kind == k for t in self.tiles) for k in KINDS}

    def summary(self) -> str:
        """``"1000×1000 in 16 tiles: 3 skipped (noise below target), 5 short, 8 full"``."""
        c = self.counts()
        return (f"{self.shape[0]}×{self.shape[1]} in {len(self.tiles)} tiles of {self.size} px: {c['skipped']} skipped "
                f"(noise below target), {c['short']} short, {c['full']} full")

    def grid(self) -> np.ndarray:
        """``(rows, cols)`` int8 map of tile kinds (0 skipped, 1 short, 2 full), row-major (for an overlay)."""
        return np.array([KINDS.index(t.kind) for t in self.tiles], dtype=np.int8).reshape(self.rows, self.cols)

    def steps(self) -> int:
        return sum(t.steps for t in self.tiles)


def tile_spans(n: int, size: int, overlap: int = OVERLAP) -> list[tuple[int, int]]:
    """``[(start, stop)]`` of as few tiles of at most ``size`` as cover ``[0, n)`` overlapping by about
    ``overlap`` (even starts: a crop keeps the CFA phase)."""
    if n <= size:
        return [(0, n)]
    count = math.ceil((n - overlap) / (size - overlap))
    length = min(n, math.ceil((n + (count - 1) * overlap) / count) + 1)
    starts = sorted({int(round(i * (n - length) / (count - 1))) & ~1 for i in range(count)})
    return [(a, n if i == len(starts) - 1 else min(n, a + length)) for i, a in enumerate(starts)]


def plan_tiles(obs: Any, plan: Any, p: Any, size: int | None = None) -> TileMap:
    """The per-tile decisions for ``obs`` under the frame's ``plan`` and settings ``p`` (see the module docstring)."""
    from spikeview.guided.observation import estimate_sigma

    size = int(size or p.tile)
    h, w = obs.shape
    ys, xs = tile_spans(h, size), tile_spans(w, size)
    tm = TileMap((h, w), size, len(ys), len(xs))
    full_steps = int(p.steps)
    hi, lo = max(float(p.t_start), float(p.sigma_end)), float(p.sigma_end)
    for y0, y1 in ys:
        for x0, x1 in xs:
            s = float(np.max(estimate_sigma(obs.crop(y0, y1, x0, x1), plan.mosaic, plan.cast)))
            t = Tile(y0, y1, x0, x1, "full", s)
            told = s * float(p.sigma_scale)
            if not plan.diffusion or (s <= p.noise_target and p.diffusion == "auto"):
                t.kind = "skipped"
                t.fallback = plan.fallback if not plan.diffusion else ("tfp" if s <= p.noise_target / 4 else "baseline")
            elif told < SHORT_FRACTION * hi and hi > lo:
                t.kind = "short"
                t.t_start = max(2.0 * told, lo)
                frac = math.log(t.t_start / lo) / math.log(hi / lo) if t.t_start > lo else 0.0
                t.steps = max(1, min(full_steps, math.ceil(full_steps * frac)))
            else:
                t.t_start, t.steps = hi, full_steps
            tm.tiles.append(t)
    return tm


def _ramp(n: int, lo_inside: bool, hi_inside: bool, overlap: int) -> np.ndarray:
    """1-D blend weights of a tile of length ``n``: at an edge inside the frame, 0 over :data:`HALO`
    pixels, then a linear ramp up to 1 over the rest of the overlap."""
    r = np.ones(n, dtype=np.float32)
    k = min(overlap, n // 2)
    if k > 0:
        halo = min(HALO, k // 2)
        ramp = np.clip((np.arange(k, dtype=np.float32) + 0.5 - halo) / (k - halo), 0.0, 1.0)
        if lo_inside:
            r[:k] = np.minimum(r[:k], ramp)
        if hi_inside:
            r[n - k:] = np.minimum(r[n - k:], ramp[::-1])
    return r


@dataclass
class _FrameNoise(Observation):
    """A tile's observation that keeps the frame's noise scale κ (estimated on many more photosites),
    so the data weights of every tile are those of the whole frame."""

    kappa: np.ndarray | None = None

    @classmethod
    def of(cls, obs: Observation, kappa: np.ndarray) -> _FrameNoise:
        return cls(**{f.name: getattr(obs, f.name) for f in dataclasses.fields(obs)}, kappa=kappa)

    def noise_scale(self) -> np.ndarray:
        return self.kappa if self.kappa is not None else super().noise_scale()


def _canvas(acc: np.ndarray, wsum: np.ndarray, t: Any, preview: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """The frame so far with tile ``t``'s running ``preview`` blended in at weight ``wt`` (a copy)."""
    a, s = acc.copy(), wsum.copy()
    a[t.y0:t.y1, t.x0:t.x1] += preview * (wt[..., None] if preview.ndim == 3 else wt)
    s[t.y0:t.y1, t.x0:t.x1] += wt
    s = np.where(s > 0, s, 1.0)
    return a / (s[..., None] if a.ndim == 3 else s)


def run_tiled(sampler: Any, obs: Any, p: Any, plan: Any, callback: Any = None, cancel: Any = None) -> np.ndarray:
    """Reconstruct ``obs`` tile by tile (``plan.tile_map``) and blend; ``callback(step, total, canvas)``
    gets the whole frame filled in so far after every step (finished tiles blended, the running
    tile's current estimate over them, zeros where no tile has run yet: the app shows the frame
    filling in). The cancel flag is checked before every tile, and inside a tile by the sampler."""
    import torch

    from spikeview.guided.baseline import baseline, start_estimate
    from spikeview.ops.pyramid import max_levels

    tm = plan.tile_map if getattr(plan, "tile_map", None) is not None else plan_tiles(obs, plan, p)
    h, w = obs.shape
    channels = 3 if plan.mosaic else 1
    shape = (h, w, 3) if channels == 3 else (h, w)
    acc = np.zeros(shape, dtype=np.float32)
    wsum = np.zeros((h, w), dtype=np.float32)
    # one start-noise field for the whole frame, cut per tile: the same noise as an untiled run
    noise = torch.randn((1, channels, h, w), generator=torch.Generator().manual_seed(int(p.seed)))
    total = max(1, sum(max(t.steps, 1) for t in tm.tiles))
    done = 0
    sub_p = p.replace(tile=0)
    kappa = obs.noise_scale()
    for k, t in enumerate(tm.tiles):
        if is_cancelled(cancel):
            raise Cancelled(f"guided reconstruction cancelled before tile {k + 1} of {len(tm.tiles)}")
        sub = _FrameNoise.of(obs.crop(t.y0, t.y1, t.x0, t.x1), kappa)
        wy = _ramp(t.y1 - t.y0, t.y0 > 0, t.y1 < h, OVERLAP)
        wx = _ramp(t.x1 - t.x0, t.x0 > 0, t.x1 < w, OVERLAP)
        wt = wy[:, None] * wx[None, :]
        if t.kind == "skipped":
            if t.fallback == "tfp":
                out = start_estimate(sub, plan.mosaic, plan.cast, p.demosaic)
            else:
                denoiser = sampler.prior_for(channels, p)
                out = baseline(sub, denoiser, sigma_scale=p.sigma_scale, use_mosaic=plan.mosaic, use_cast=plan.cast,
                               demosaic=p.demosaic)
            offset = done
            done += 1
        else:
            # the frame's decisions (M, C, Q, demosaic, precision) and noise (more samples) on every tile
            sub_plan = dataclasses.replace(plan, diffusion=True, reuse=False, changed=None, tile_map=None,
                                           levels=min(plan.levels, max_levels(*sub.shape)),
                                           sigma=np.minimum(plan.sigma, t.sigma) if t.kind == "short" else plan.sigma)
            cfg = sub_p.replace(steps=t.steps, t_start=t.t_start)
            offset = done

            def cb(step, _total, preview, _o=offset, _t=t, _wt=wt):
                if callback is not None:
                    callback(_o + step, total, _canvas(acc, wsum, _t, np.asarray(preview, dtype=np.float32), _wt))

            out = sampler.run(sub, cfg, cb if callback is not None else None, cancel, plan=sub_plan,
                              noise=noise[..., t.y0:t.y1, t.x0:t.x1])
            done += t.steps
        acc[t.y0:t.y1, t.x0:t.x1] += out * (wt[..., None] if out.ndim == 3 else wt)
        wsum[t.y0:t.y1, t.x0:t.x1] += wt
        if callback is not None:
            filled = np.where(wsum > 0, wsum, 1.0)
            callback(done, total, acc / (filled[..., None] if acc.ndim == 3 else filled))
    return acc / (wsum[..., None] if acc.ndim == 3 else wsum)
