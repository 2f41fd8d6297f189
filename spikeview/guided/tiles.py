"""Per-tile plan and step-synchronous tiled sampling: leave out what each part of the frame does not need.

With ``guided.tile = T`` (pixels, 0 = off) a frame larger than ``T`` is cut into a grid of tiles of
about ``T × T`` (:func:`tile_spans`, even edges so every tile keeps the CFA phase). For each tile the
plan measures the noise σ of the corrected TFP estimate on that tile alone
(:func:`~spikeview.guided.observation.estimate_sigma`, the noise scale κ estimated on the tile: a
clean tile is found clean even where the frame's model would not say so) and decides (:func:`plan_tiles`):

* **skipped** — σ at or below ``noise_target``: no diffusion; the tile gets TFP (σ <= target/4) or
  one FFDNet pass, as a frame that needs no diffusion would;
* **short** — the noise the prior is told (``σ · sigma_scale``) is below half the frame's start
  level: the tile joins the frame's σ ladder at the first step whose level is at most
  :data:`JOIN_FACTOR` (3) times that noise and takes only the steps from there on;
* **full** — the whole ladder.

Sampling is **step-synchronous** (:func:`run_tiled`): one sample ``x`` of the whole frame and one σ
ladder (the untiled run's); at step ``i`` the pixels whose tile has joined (``join <= i``) are
*active*. The active area is cut into as few rectangles as the memory cap :data:`MAX_AREA` allows
(whole tile rows merged; a frame whose tiles are all full is one rectangle, i.e. the untiled run),
and each rectangle runs the HQS step (prior pass + data step) on its crop widened by
:func:`margin` pixels (more than FFDNet's receptive field plus the data step's 5×5 reach), keeping
the rectangle's interior. Every pixel therefore gets the number the whole-frame step would give it
(with ``levels = 0``, the default; a pyramid couples farther and is then approximate near
rectangle edges), and the re-noising, the start noise and the dihedral self-ensemble are drawn for
the whole frame from the run's seed, as untiled. Waiting pixels (a short tile before it joins) hold
their start ``Y₀ + σ_join·z``; the prior sees them at their own level through a per-pixel noise map.
Skipped tiles keep their fallback, cross-faded over :data:`BLEND` pixels into the diffused
neighbours (those pixels are sampled with the neighbour), so there is no seam at a skipped edge and
none between tiles at all: tiles exchange information every step, and the whole frame fills in
step by step (``callback`` gets the frame after every step). Memory follows :data:`MAX_AREA`, not
the frame.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spikeview.errors import Cancelled, ParameterError, check_cancelled, is_cancelled
from spikeview.guided.observation import Observation, worst_block_sigma

#: pixels a skipped tile's fallback is cross-faded over into its diffused neighbours
BLEND = 32
#: largest rectangle (photosites, margins not counted) one prior pass + data step runs on: bounds the
#: memory of a step (a 1000×1000 frame whose tiles all need the full ladder is one rectangle)
MAX_AREA = 1_100_000
#: a tile is "short" when the noise the prior is told is below this fraction of the start level
SHORT_FRACTION = 0.5
#: short tiles are kept only when the map leaves out more than this fraction of the prior work: below,
#: the rectangles' margins and data terms cost more than the steps saved (1000² natural scene, 35 of 64
#: tiles short, 91% of the work: 1.2× the CPU time of the whole frame)
PAY_WORK = 0.8
#: a short tile joins the frame's ladder at the first level at most this many times its own noise
#: (1000² natural scene, bright to dark: 3 → −0.03 dB / +0.0002 SSIM against the whole frame, 16 of 64
#: tiles short; 2.5 → −0.38 dB; 2 → −0.67 dB: a late start costs the data step its early iterations)
JOIN_FACTOR = 3.0
KINDS = ("skipped", "short", "full")


def margin(levels: int) -> int:
    """Context (even, pixels) around a rectangle: FFDNet's receptive field (15 layers at half
    resolution: 30 pixels, gray) + the data step's reach (5×5 local rate, 3×3 spread) + the
    pyramid's reach for ``levels > 0`` (approximate)."""
    return 36 + (0 if levels <= 0 else 2 ** (int(levels) + 3))


@dataclass
class Tile:
    """One tile: photosites ``[y0:y1, x0:x1]`` and what it gets."""

    y0: int
    y1: int
    x0: int
    x1: int
    kind: str
    sigma: float
    steps: int = 0
    t_start: float = 0.0
    fallback: str = ""
    #: first step of the frame's ladder this tile takes (``steps`` = ladder length − join)
    join: int = 0
    #: per-channel σ of the tile's TFP estimate (fractions of 1)
    sigma_c: tuple[float, ...] = ()

    @property
    def area(self) -> int:
        return (self.y1 - self.y0) * (self.x1 - self.x0)


@dataclass
class TileMap:
    """The per-tile plan of one frame."""

    shape: tuple[int, int]
    size: int
    rows: int
    cols: int
    tiles: list[Tile] = field(default_factory=list)
    #: the frame's ladder length (steps of a full tile)
    ladder: int = 0
    #: why the map differs from the tiles' own noise (short tiles made full when they would not pay)
    note: str = ""
    #: prior work of the map as planned, before short tiles were made full
    work_if_short: float = 1.0

    def counts(self) -> dict[str, int]:
        return {k: sum(t.kind == k for t in self.tiles) for k in KINDS}

    def work(self) -> float:
        """Prior work (pixel-steps, margins not counted) relative to the whole frame's full ladder."""
        total = self.shape[0] * self.shape[1] * max(self.ladder, 1)
        return sum(t.area * t.steps for t in self.tiles if t.kind != "skipped") / total

    def summary(self) -> str:
        """``"1000×1000 (width × height) in 64 tiles of 125 px: 21 skipped (noise below target), 30 short, 13 full; prior work 41%"``."""
        c = self.counts()
        return (f"{self.shape[1]}×{self.shape[0]} in {len(self.tiles)} tiles of {self.size} px: {c['skipped']} skipped "
                f"(noise below target), {c['short']} short, {c['full']} full; "
                f"{100 * self.work():.0f}% of the whole frame's prior work" + (f" ({self.note})" if self.note else ""))

    def grid(self) -> np.ndarray:
        """``(rows, cols)`` int8 map of tile kinds (0 skipped, 1 short, 2 full), row-major (for an overlay)."""
        return np.array([KINDS.index(t.kind) for t in self.tiles], dtype=np.int8).reshape(self.rows, self.cols)

    def steps(self) -> int:
        return sum(t.steps for t in self.tiles)

    def pays(self) -> bool:
        """Whether sampling by tiles changes anything: a tile is skipped or short. Otherwise the whole
        frame at once gives the same pixels, sooner and in less memory (the strip-wise prior already
        bounds its feature volume: 2000×2000 in 1795 MB whole, 2075 MB cut into rectangles)."""
        return any(t.kind != "full" for t in self.tiles)

    def as_dict(self) -> dict[str, Any]:
        """The map for an output's metadata: summary, counts and every tile's box, kind and steps."""
        return {"summary": self.summary(), "shape": list(self.shape), "size": self.size, "rows": self.rows, "cols": self.cols,
                "counts": self.counts(), "work": round(self.work(), 4),
                "tiles": [[t.y0, t.y1, t.x0, t.x1, t.kind, t.steps] for t in self.tiles]}


def tile_spans(n: int, size: int, overlap: int = 0) -> list[tuple[int, int]]:
    """``[(start, stop)]`` of as few tiles of about ``size`` as cover ``[0, n)`` (even edges: a crop
    keeps the CFA phase). ``overlap`` > 0 makes neighbours share about that many pixels."""
    if n <= size:
        return [(0, n)]
    if overlap <= 0:
        count = math.ceil(n / size)
        edges = [0] + [int(round(i * n / count)) & ~1 for i in range(1, count)] + [n]
        return [(a, b) for a, b in zip(edges, edges[1:], strict=False) if b > a]
    count = math.ceil((n - overlap) / (size - overlap))
    length = min(n, math.ceil((n + (count - 1) * overlap) / count) + 1)
    starts = sorted({int(round(i * (n - length) / (count - 1))) & ~1 for i in range(count)})
    return [(a, n if i == len(starts) - 1 else min(n, a + length)) for i, a in enumerate(starts)]


def frame_ladder(plan: Any, p: Any, channels: int, sigma_max: float) -> tuple[Any, np.ndarray, np.ndarray]:
    """``(schedule, sigma_obs (C,), sigma_add (C,))``: the untiled run's σ ladder (``schedule.sigmas``,
    ``(steps + 1, C)``) and start noise (as :meth:`GuidedSampler._sample` computes them)."""
    from spikeview.guided.schedule import ve_ladder

    sigma_obs = np.asarray(plan.sigma, dtype=np.float64) * p.sigma_scale
    if sigma_obs.size != channels:
        sigma_obs = np.full(channels, float(np.sqrt(np.mean(sigma_obs ** 2))))
    t_s = p.t_start
    sigma_add = np.sqrt(np.maximum(t_s ** 2 - sigma_obs ** 2, 0.0)) if p.top_up else np.full(channels, t_s)
    return ve_ladder(sigma_obs, sigma_add, sigma_max, p.sigma_end, p.steps), sigma_obs, sigma_add


def plan_tiles(obs: Any, plan: Any, p: Any, size: int | None = None,
               variance: tuple[np.ndarray, np.ndarray] | None = None) -> TileMap:
    """The per-tile decisions for ``obs`` under the frame's ``plan`` and settings ``p`` (see the module docstring).

    ``variance``: the frame's :func:`~spikeview.guided.observation.start_variance` map and gains when the
    caller has them (:func:`~spikeview.guided.plan.make_plan` does), else computed here.
    """
    from spikeview.guided.config import SIGMA_MAX
    from spikeview.guided.observation import start_variance

    size = int(size or p.tile)
    h, w = obs.shape
    ys, xs = tile_spans(h, size), tile_spans(w, size)
    channels = 3 if plan.mosaic else 1
    sched, _, _ = frame_ladder(plan, p, channels, SIGMA_MAX)
    n = int(p.steps)
    levels = sched.sigmas[:n].max(axis=1)  # the level of each step (largest over channels)
    tm = TileMap((h, w), size, len(ys), len(xs), ladder=n)
    var, gain = variance if variance is not None else start_variance(obs, plan.mosaic, plan.cast)
    kappa = np.asarray(obs.noise_scale(), dtype=np.float64)  # the frame's noise scale: tiles rescale by their own
    if var.shape[0] == 1 and kappa.size != 1:
        kappa = None
    for y0, y1 in ys:
        for x0, x1 in xs:
            # estimate_sigma of the tile alone: the frame's demosaicked variance rescaled by the tile's own
            # noise scale κ (the variance is linear in κ per channel), averaged over the tile
            ratio = obs.crop(y0, y1, x0, x1).noise_scale() / kappa if kappa is not None else np.ones(1)
            if ratio.size != var.shape[0]:
                ratio = np.full(var.shape[0], float(np.mean(ratio)))
            sc = np.sqrt(ratio * var[:, y0:y1, x0:x1].reshape(var.shape[0], -1).mean(axis=1, dtype=np.float64)) * gain
            s = float(sc.max())
            t = Tile(y0, y1, x0, x1, "full", s, sigma_c=tuple(sc.tolist()))
            # a tile joins the sampler at the σ of its noisiest block (a block that pooled less is not left with raw
            # noise by a tile mean that its quiet neighbours lower), and is skipped as the plan judges the frame
            worst = max(s, worst_block_sigma(var[:, y0:y1, x0:x1] * np.asarray(ratio).reshape(-1, 1, 1), gain))
            told = worst * float(p.sigma_scale)
            judged = worst * float(getattr(plan, "exposure", 1.0))
            if not plan.diffusion or (judged <= p.noise_target and p.diffusion == "auto"):
                t.kind = "skipped"
                t.fallback = plan.fallback if not plan.diffusion else ("tfp" if judged <= p.noise_target / 4 else "baseline")
                t.join = n
            else:
                below = np.flatnonzero(levels <= JOIN_FACTOR * told)
                j = int(below[0]) if below.size else n - 1
                if told < SHORT_FRACTION * levels[0] and j > 0:
                    t.kind, t.join = "short", j
                t.steps, t.t_start = n - t.join, float(levels[t.join])
            tm.tiles.append(t)
    tm.work_if_short = tm.work()
    if tm.work() > PAY_WORK:  # too little left out to pay for the tiles' margins: short tiles take the whole ladder
        for t in tm.tiles:
            if t.kind == "short":
                t.kind, t.join, t.steps, t.t_start = "full", 0, n, float(levels[0])
        tm.note = f"short tiles would leave out only {100 * (1 - tm.work_if_short):.0f}% of the prior work: all full"
    return tm


def _split(c0: int, c1: int, rows: int, cuts: list[int], max_area: int) -> list[tuple[int, int]]:
    """The column run ``[c0, c1)`` cut at tile edges ``cuts`` into pieces of at most ``max_area`` (a run
    narrower than two tiles, or within the cap, stays whole)."""
    if rows * (c1 - c0) <= max_area:
        return [(c0, c1)]
    out, a = [], c0
    inner = [c for c in cuts if c0 < c < c1]
    for i, c in enumerate(inner):
        nxt = inner[i + 1] if i + 1 < len(inner) else c1
        if rows * (nxt - a) > max_area:
            out.append((a, c))
            a = c
    out.append((a, c1))
    return out


def _rectangles(active: np.ndarray, bands: list[tuple[int, int]], max_area: int,
                cuts: list[int] | None = None) -> list[tuple[int, int, int, int]]:
    """Rectangles ``(y0, y1, x0, x1)`` covering the active pixels: per band of tile rows the runs of
    active columns (rows trimmed to the active ones; a run over ``max_area`` cut at the tile columns
    ``cuts``), merged down the frame while their columns match and the area stays within
    ``max_area``; edges made even (the CFA phase, FFDNet's 2×2 cells)."""
    h, w = active.shape
    rects: list[list[int]] = []
    for r0, r1 in bands:
        a = active[r0:r1]
        cols = a.any(axis=0)
        if not cols.any():
            continue
        d = np.diff(np.concatenate([[0], cols.astype(np.int8), [0]]))
        runs = [piece for c0, c1 in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)
                for piece in _split(int(c0), int(c1), r1 - r0, cuts or [], max_area)]
        for c0, c1 in runs:
            rows = np.flatnonzero(a[:, c0:c1].any(axis=1))
            y0, y1 = r0 + int(rows[0]), r0 + int(rows[-1]) + 1
            for m in rects:
                if m[2] == c0 and m[3] == c1 and m[1] == y0 and (y1 - m[0]) * (c1 - c0) <= max_area:
                    m[1] = y1
                    break
            else:
                rects.append([y0, y1, int(c0), int(c1)])
    return [(y0 & ~1, min(h, y1 + (y1 & 1)), x0 & ~1, min(w, x1 + (x1 & 1))) for y0, y1, x0, x1 in rects]


@dataclass
class _FrameNoise(Observation):
    """A crop's observation that keeps the frame's noise scale κ (estimated on many more photosites),
    so the data weights of every crop are those of the whole frame."""

    kappa: np.ndarray | None = None

    @classmethod
    def of(cls, obs: Observation, kappa: np.ndarray) -> _FrameNoise:
        return cls(**{f.name: getattr(obs, f.name) for f in dataclasses.fields(obs)}, kappa=kappa)

    def noise_scale(self) -> np.ndarray:
        return self.kappa if self.kappa is not None else super().noise_scale()


class _MapPrior:
    """A prior told a per-pixel noise map (pixels still waiting for their tile sit at their own level)."""

    def __init__(self, prior: Any, smap: Any):
        self.prior, self.smap = prior, smap
        self.channels = getattr(prior, "channels", None)
        self.sigma_max = getattr(prior, "sigma_max", math.inf)

    def denoise(self, x: Any, sigma: Any) -> Any:
        return self.prior.denoise(x, self.smap)


def _weights(tm: TileMap) -> tuple[np.ndarray, np.ndarray]:
    """``(join, wdiff)`` per pixel: the first step at which a pixel is sampled (ladder length = never)
    and the weight of the diffused estimate in the output (1 in diffused tiles, a ramp over
    :data:`BLEND` pixels into skipped ones, 0 beyond)."""
    h, w = tm.shape
    n = tm.ladder
    join = np.full((h, w), n, dtype=np.int32)
    wdiff = np.zeros((h, w), dtype=np.float32)
    for t in tm.tiles:
        if t.kind == "skipped":
            continue
        y0, y1, x0, x1 = max(0, t.y0 - BLEND), min(h, t.y1 + BLEND), max(0, t.x0 - BLEND), min(w, t.x1 + BLEND)
        ry = 1.0 - np.clip(np.maximum(t.y0 - np.arange(y0, y1), np.arange(y0, y1) - (t.y1 - 1)), 0, None) / BLEND
        rx = 1.0 - np.clip(np.maximum(t.x0 - np.arange(x0, x1), np.arange(x0, x1) - (t.x1 - 1)), 0, None) / BLEND
        ramp = (ry[:, None] * rx[None, :]).astype(np.float32)
        np.maximum(wdiff[y0:y1, x0:x1], ramp, out=wdiff[y0:y1, x0:x1])
        join[y0:y1, x0:x1] = np.where(ramp > 0, np.minimum(join[y0:y1, x0:x1], t.join), join[y0:y1, x0:x1])
    for t in tm.tiles:  # a diffused tile's own pixels: its own join and full weight
        if t.kind != "skipped":
            join[t.y0:t.y1, t.x0:t.x1] = t.join
            wdiff[t.y0:t.y1, t.x0:t.x1] = 1.0
    return join, wdiff


def run_tiled(sampler: Any, obs: Any, p: Any, plan: Any, callback: Any = None, cancel: Any = None,
              max_area: int | None = None) -> np.ndarray:
    """Reconstruct ``obs`` step-synchronously over ``plan.tile_map`` (see the module docstring).

    ``callback(step, total, frame)`` gets the whole frame after every step (diffused pixels' x̂₀,
    waiting pixels' start estimate, skipped tiles' fallback). The cancel flag is checked before
    every step and between rectangles (and inside every prior pass by the sampler's cancel scope).
    ``max_area`` overrides :data:`MAX_AREA` (tests use it to cut a small frame into many rectangles).
    """
    import torch

    from spikeview.guided import precision as prec
    from spikeview.guided.baseline import baseline, start_estimate, to_image, to_tensor
    from spikeview.guided.guidance import HQSGuidance, _dihedral
    from spikeview.ops.pyramid import max_levels

    tm = plan.tile_map if getattr(plan, "tile_map", None) is not None else plan_tiles(obs, plan, p)
    h, w = obs.shape
    channels = 3 if plan.mosaic else 1
    prior = sampler.prior_for(channels, p)
    from spikeview.guided.device import module_device, randn

    dev = module_device(prior)  # the whole step-synchronous run lives where the prior runs (guided.device)
    sampler.info.device = str(dev)

    def on(t: Any) -> Any:  # a host tensor (masks, maps) on the run's device
        return t.to(dev, non_blocking=True)

    rule = sampler._guidance if sampler._guidance is not None else sampler.guidance_for(p, prior, obs.shape)
    if not isinstance(rule, HQSGuidance):
        raise TypeError("step-synchronous tiles need HQS guidance (the plan turns tiles off for DPS)")
    step_rule = HQSGuidance(rule.lam, rule.data_steps, renoise=False, s=rule.s)
    n = int(p.steps)
    sched, sigma_obs, sigma_add = frame_ladder(plan, p, channels, getattr(prior, "sigma_max", math.inf))
    sigmas = sched.sigmas
    tm.ladder = n
    join, wdiff = _weights(tm)
    kappa = obs.noise_scale()
    mg = margin(plan.levels)
    max_area = int(max_area or MAX_AREA)
    bands = tile_spans(h, tm.size)
    cuts = [a for a, _ in tile_spans(w, tm.size)]

    def crop(y0: int, y1: int, x0: int, x1: int) -> tuple[int, int, int, int]:
        return max(0, y0 - mg), min(h, y1 + mg), max(0, x0 - mg), min(w, x1 + mg)

    # the start estimate of the whole frame (as untiled), and every skipped tile's fallback
    start = on(to_tensor(start_estimate(obs, plan.mosaic, plan.cast, p.demosaic)))
    fallback = start.clone() if any(t.kind == "skipped" and t.fallback == "baseline" for t in tm.tiles) else start
    for t in tm.tiles:
        if t.kind == "skipped" and t.fallback == "baseline":
            check_cancelled("before a skipped tile's one-pass estimate")
            cy0, cy1, cx0, cx1 = crop(t.y0, t.y1, t.x0, t.x1)
            sub = _FrameNoise.of(obs.crop(cy0, cy1, cx0, cx1), kappa)
            one = on(to_tensor(baseline(sub, prior, sigma_scale=p.sigma_scale, use_mosaic=plan.mosaic, use_cast=plan.cast,
                                        demosaic=p.demosaic, sigma_map=True)))
            fallback[..., t.y0:t.y1, t.x0:t.x1] = one[..., t.y0 - cy0:t.y1 - cy0, t.x0 - cx0:t.x1 - cx0]

    # per-pixel start noise: full tiles exactly as untiled; a short tile (and a skipped tile's cross-fade
    # band) tops its own noise up to the level of the step it joins at (tile by tile: no frame-sized temporaries)
    lad = torch.as_tensor(sigmas[:n], dtype=torch.float32, device=dev)  # (n, C)
    add = torch.as_tensor(sigma_add, dtype=torch.float32, device=dev).view(1, -1, 1, 1).expand(1, channels, h, w).clone()
    for t in tm.tiles:
        jr = join[t.y0:t.y1, t.x0:t.x1]
        if t.kind == "full" and not (jr > 0).any():
            continue
        own = np.asarray(t.sigma_c, dtype=np.float64) * p.sigma_scale
        own = own if own.size == channels else np.full(channels, float(np.sqrt(np.mean(own ** 2))))
        own = torch.as_tensor(np.minimum(sigma_obs, own) if t.kind != "full" else sigma_obs, dtype=torch.float32, device=dev)
        level = lad[on(torch.from_numpy(np.minimum(jr, n - 1).astype(np.int64)))].permute(2, 0, 1)[None]
        top = torch.sqrt(torch.clamp(level ** 2 - own.view(1, -1, 1, 1) ** 2, min=0.0))
        region = add[..., t.y0:t.y1, t.x0:t.x1]
        region.copy_(torch.where(on(torch.from_numpy(jr == 0))[None, None], region, top))
    skipped_only = on(torch.from_numpy(join >= n))[None, None]
    wd = on(torch.from_numpy(wdiff))[None, None]
    precision = plan.precision or prec.resolve_precision(p.precision, device=dev)[0]
    sampler.info.precision = precision
    layer_prec = prec.step_precisions(precision, sigmas[:n].min(axis=1))
    gen = torch.Generator().manual_seed(int(p.seed))
    total = n * p.chains
    data_cache: dict[tuple[int, int, int, int], Any] = {}  # this step's rectangles' data terms (kept while they last)

    def data_for(box: tuple[int, int, int, int], cache: dict) -> Any:
        if box not in cache:
            cache[box] = data_cache.get(box)
            if cache[box] is None:
                sub = _FrameNoise.of(obs.crop(*box), kappa)
                sub_plan = dataclasses.replace(plan, levels=min(plan.levels, max_levels(*sub.shape)), tile_map=None)
                cache[box] = sampler.data_term(sub, sub_plan, p, dev)
        return cache[box]

    def blend(x0: Any) -> Any:
        return torch.where(skipped_only, fallback, wd * x0 + (1.0 - wd) * fallback)

    acc = torch.zeros_like(start)
    for chain in range(p.chains):
        # drawn from the CPU generator on any device: the noise a CPU run draws
        x = randn(start.shape, gen, start.dtype, dev) if bool((add > 0).any()) else torch.zeros_like(start)
        x.mul_(add).add_(start)  # start + add·z, as the untiled run draws it
        x = torch.where(skipped_only, fallback, x, out=x)
        x0_full = torch.where(skipped_only, fallback, start)
        for i in range(n):
            done = chain * n + i
            if is_cancelled(cancel):
                raise Cancelled(f"guided reconstruction cancelled at step {done + 1} of {total}")
            act = join <= i
            if act.any():
                sigma = torch.as_tensor(sigmas[i], dtype=start.dtype, device=dev).view(1, -1, 1, 1)
                transform = ((i + 3 * chain) % 8) if p.self_ensemble else None
                prior_i = prec.at_precision(prior, layer_prec[i])
                new = x0_full  # written in place: the rectangles read x, never x̂₀
                used: dict = {}
                for ry0, ry1, rx0, rx1 in _rectangles(act, bands, max_area, cuts):
                    check_cancelled(f"at step {done + 1} of {total}")
                    box = crop(ry0, ry1, rx0, rx1)
                    cy0, cy1, cx0, cx1 = box
                    jc = join[cy0:cy1, cx0:cx1]
                    pr = prior_i
                    if (jc > i).any():  # waiting or skipped pixels in the context: a per-pixel noise map
                        smap = lad[on(torch.from_numpy(np.clip(np.maximum(jc, i), 0, n - 1).astype(np.int64)))]
                        smap = smap.permute(2, 0, 1)[None].to(start.dtype)
                        pr = _MapPrior(prior_i, _dihedral(smap, transform) if transform else smap)
                    _, x0c = step_rule.step(pr, None, data_for(box, used), x[..., cy0:cy1, cx0:cx1], i, sigma, zeta=p.zeta,
                                            generator=None, transform=transform)
                    keep = on(torch.from_numpy(act[ry0:ry1, rx0:rx1]))[None, None]
                    inner = x0c[..., ry0 - cy0:ry1 - cy0, rx0 - cx0:rx1 - cx0]
                    new[..., ry0:ry1, rx0:rx1] = torch.where(keep, inner, new[..., ry0:ry1, rx0:rx1])
                data_cache = used
                if not bool(torch.isfinite(new).all()):
                    raise ParameterError(f"the guided sample diverged (non-finite values at step {done + 1} of {total}, "
                                         f"tiled, guidance = hqs); raise lam (now {p.lam:g}) or use fewer data_steps, "
                                         "or use method tfp for this stream.")
                mask = on(torch.from_numpy(act))[None, None]
                if rule.renoise:
                    prev = sched.step(new, i, x, zeta=p.zeta, generator=gen).prev_sample
                else:
                    prev = new
                torch.where(mask, prev, x, out=x)
                del prev
            sampler.info.steps = done + 1
            if callback is not None:
                callback(done + 1, total, to_image(blend((acc + x0_full) / (chain + 1))))
        acc = acc + x0_full
    return to_image(blend(acc / p.chains))

