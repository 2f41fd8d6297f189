"""The app's background jobs as plain functions (no Qt), run by :class:`spikeview.gui.workers.Worker`.

Each job takes a frozen request (a snapshot of the session: the source, the tick, a copy of the
parameters) and a context ``ctx`` with ``report(payload)``, ``check()``, ``cancelled`` (a
``threading.Event``) and ``state`` (a dict owned by the worker thread). Nothing here touches the
session or a widget, so the tests can call the jobs directly.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import Cancelled, ParameterError
from spikeview.gui import core

# ------------------------------------------------------------------------------------ previews


@dataclass(frozen=True)
class PreviewRequest:
    """What the Stream, Rates and Degradation panels need for one window."""

    source: Any
    tick: int
    params: dict[str, Any]
    alpha: np.ndarray | None
    roi: tuple[int, int, int, int] | None = None
    want_tfi: bool = True
    factor: int = 1  # display downsampling of the stream images
    x_override: np.ndarray | None = None  # the guided result for this window, if any (ROI-cropped)
    x_label: str = "TFP"


def frames_job(req: PreviewRequest, ctx: Any) -> core.StreamFrames:
    return core.stream_frames(req.source, req.tick, req.params, req.alpha, want_tfi=False, factor=req.factor)


def tfi_job(req: PreviewRequest, ctx: Any) -> tuple[int, np.ndarray, tuple[int, int]]:
    """``(tick, TFI image, full frame shape)`` for the Stream panel's TFI pane."""
    img = core.tfi_frame(req.source, req.tick, req.params, req.alpha, req.factor)
    return req.tick, img, (req.source.height, req.source.width)


def rates_job(req: PreviewRequest, mosaic: np.ndarray, ctx: Any) -> core.RatesResult:
    return core.site_rates(mosaic, req.source.cfa, int(req.params["window"]), req.roi, tick=req.tick)


def alpha_job(source: Any, window: int, ctx: Any) -> tuple[np.ndarray, str | None]:
    return core.sequence_alpha(source, window)


@dataclass
class DegradationView:
    """A :class:`~spikeview.gui.core.DegradationResult` with what it was computed from."""

    result: core.DegradationResult
    x_label: str
    tick: int
    shape: tuple[int, int]


def degradation_job(req: PreviewRequest, ctx: Any) -> DegradationView:
    """Current reconstruction X (guided result or classical TFP) pushed through M, C, Q vs. Y."""
    p = req.params
    src = req.source
    a, b = core.window_range(req.tick, int(p["window"]), src.n_frames)
    y = src.count(a, b).astype(np.float32) / np.float32(b - a)
    y, _ = core.crop_roi(y, req.roi)
    if req.x_override is not None and req.x_override.shape[:2] == y.shape:
        x, label = req.x_override, req.x_label
    else:
        x = core.reconstruct_classical(src, req.tick, "tfp", p, req.alpha if p["colour_cast"] else None)
        x, _ = core.crop_roi(x, req.roi)
        label = "TFP (classical)"
    alpha = req.alpha if (src.cfa is not None and p["colour_cast"]) else None
    res = core.degradation_chain(x, y, src.cfa, b - a, p["k"], p["eta"], alpha, int(p["levels"]),
                                 bool(p["show_pyramid"]), p)
    return DegradationView(res, label, req.tick, y.shape)


# ---------------------------------------------------------------------------------- guided


@dataclass(frozen=True)
class GuidedRequest:
    """One guided reconstruction of the window around ``tick`` (on the ROI when one is set)."""

    source: Any
    tick: int
    params: dict[str, Any]
    alpha: np.ndarray | None
    roi: tuple[int, int, int, int] | None
    ground_truth: Callable[[int], np.ndarray] | None = None
    run: int = 0


@dataclass
class GuidedUpdate:
    """Progress of a guided job: ``kind`` is ``"plan"`` (text) or ``"step"`` (preview + metrics)."""

    kind: str
    run: int
    step: int = 0
    total: int = 0
    preview: np.ndarray | None = None  # uint8 display image of the clean estimate x̂₀
    elapsed: float = 0.0
    psnr: float | None = None
    ssim: float | None = None
    text: str = ""


@dataclass
class GuidedResult:
    run: int
    tick: int
    image: np.ndarray  # float32 (H, W, 3) / (H, W) in [0, 1], ROI-sized
    preview: np.ndarray  # uint8
    origin: tuple[int, int]
    plan: str
    elapsed: float
    psnr: float | None = None
    ssim: float | None = None
    config: dict[str, Any] = field(default_factory=dict)


def guided_config(params: dict[str, Any]):
    """The :class:`spikeview.guided.GuidedConfig` of the session's parameters."""
    from spikeview.guided.config import GuidedConfig

    return GuidedConfig(guidance=params["guidance"], prior=params["prior"], model_path=params["model_path"] or None,
                        steps=int(params["steps"]), t_start=float(params["t_start"]), s=float(params["s"]),
                        k=float(params["k"]), levels=int(params["levels"]), eta=float(params["eta"]),
                        window=int(params["window"]), demosaic=_guided_demosaic(params["demosaic"]),
                        seed=int(params["seed"]), use_cast=None if params["colour_cast"] else False,
                        diffusion="always")


def _guided_demosaic(name: str) -> str:
    from spikeview.guided.config import DEMOSAICS

    return name if name in DEMOSAICS else "malvar2004"


def observation(source: Any, tick: int, params: dict[str, Any], alpha: np.ndarray | None,
                roi: tuple[int, int, int, int] | None):
    """The :class:`spikeview.guided.observation.Observation` of the window, cropped to ``roi``.

    The crop starts on even pixels so the CFA phase (``source.cfa``) stays the same.
    """
    from spikeview.guided.observation import Observation

    obs = Observation.from_source(source, int(tick), int(params["window"]), alpha=alpha if params["colour_cast"] else None,
                                  eta=float(params["eta"]))
    if roi is None:
        return obs, (0, 0)
    y, origin = core.crop_roi(obs.y, roi)
    if min(y.shape) < 8:
        raise ParameterError("The region of interest is too small for a guided reconstruction: draw one of at least 8x8 pixels.")
    return Observation(y, obs.cfa, obs.window, obs.alpha, obs.eta, obs.ticks, obs.center), origin


def guided_job(req: GuidedRequest, ctx: Any) -> GuidedResult:
    """Plan, then run the guided sampler, reporting the clean estimate (and metrics) every step."""
    from spikeview.guided.plan import make_plan

    p = req.params
    cfg = guided_config(p)
    obs, origin = observation(req.source, req.tick, p, req.alpha, req.roi)
    plan = make_plan(obs, cfg)
    ctx.report(GuidedUpdate("plan", req.run, total=cfg.steps, text=str(plan)))
    gt = None
    if req.ground_truth is not None:
        g = np.asarray(req.ground_truth(req.tick), dtype=np.float32)
        gt, _ = core.crop_roi(g, req.roi)
        if gt.shape[:2] == obs.y.shape:
            gt = core.align_ground_truth(gt, obs.y, obs.cfa, obs.alpha, obs.eta)
    t0 = time.perf_counter()
    last: dict[str, Any] = {}

    def callback(step: int, total: int, preview: np.ndarray) -> None:
        ctx.check()
        img = np.asarray(preview, dtype=np.float32)
        psnr = ssim = None
        if gt is not None and gt.shape == img.shape:
            psnr, ssim = core.psnr_ssim(img, gt)
        elapsed = time.perf_counter() - t0
        last.update(psnr=psnr, ssim=ssim)
        ctx.report(GuidedUpdate("step", req.run, step, total, core.show(img, p), elapsed, psnr, ssim))

    image = run_sampler(obs, cfg, callback, ctx)
    ctx.check()
    image = np.asarray(image, dtype=np.float32)
    psnr = ssim = None
    if gt is not None and gt.shape == image.shape:
        psnr, ssim = core.psnr_ssim(image, gt)
    return GuidedResult(req.run, req.tick, image, core.show(image, p), origin, str(plan),
                        time.perf_counter() - t0, psnr, ssim, cfg.to_dict())


def run_sampler(obs: Any, cfg: Any, callback: Callable[[int, int, np.ndarray], None], ctx: Any) -> np.ndarray:
    """Run the guided sampler for ``cfg.prior``, kept in ``ctx.state`` (the worker owns it).

    ``"ffdnet"``: :class:`spikeview.guided.sampler.GuidedSampler` (pixel-space prior, loaded once);
    ``"sd"``: :class:`spikeview.guided.latent.LatentGuidedSampler` (weights from ``cfg.model_path``,
    loaded on the first run and kept while the path stays the same). ``callback(step, total,
    preview)`` gets the float clean estimate after every step; both samplers check ``ctx.cancelled``
    before every step and raise :class:`~spikeview.errors.Cancelled`.
    """
    if cfg.prior == "sd":
        from spikeview.guided.latent import LatentGuidedSampler

        sampler = ctx.state.get("latent_sampler")
        if sampler is None:
            sampler = ctx.state["latent_sampler"] = LatentGuidedSampler()
    else:
        from spikeview.guided.sampler import GuidedSampler

        sampler = ctx.state.get("sampler")
        if sampler is None:
            sampler = ctx.state["sampler"] = GuidedSampler(cfg)
    return sampler.run(obs, cfg, callback=callback, cancel=ctx.cancelled)


# ---------------------------------------------------------------------------------- export


@dataclass(frozen=True)
class ExportRequest:
    """Write the reconstruction of ``ticks`` to ``out`` (format from its suffix)."""

    source: Any
    source_name: str
    ticks: tuple[int, ...]
    method: str  # "tfp", "tfi" or "guided"
    params: dict[str, Any]
    alpha: np.ndarray | None
    out: Path
    roi: tuple[int, int, int, int] | None = None
    preset: dict[str, Any] = field(default_factory=dict)


def export_ticks(params: dict[str, Any], mode: str, tick: int, marked: tuple[int, int]) -> tuple[int, ...]:
    """Centre ticks to export: the current one, or one per window Δτ across the marked range."""
    if mode == "frame":
        return (int(tick),)
    lo, hi = marked
    step = max(1, int(params["window"]))
    return tuple(range(int(lo), int(hi) + 1, step)) or (int(lo),)


def export_job(req: ExportRequest, ctx: Any) -> list[Path]:
    """Reconstruct and write every frame; progress ``(done, total)``; Cancel keeps finished frames."""
    from spikeview.export import ExportConfig, ExportMetadata, open_exporter

    p = req.params
    n = len(req.ticks)
    cfg = ExportConfig(fps=float(p["export_fps"]), black=float(p["black"]), white=max(float(p["white"]), float(p["black"]) + 1e-3),
                       transfer=p["transfer"], gamma=float(p["gamma"]))
    step = int(p["window"]) if n > 1 else None
    a, b = core.window_range(req.ticks[0], int(p["window"]), req.source.n_frames)
    meta = ExportMetadata(source=req.source_name, method=req.method, tick_rate=float(req.source.tick_rate),
                          window=(a, b), centre_tick=int(req.ticks[0]), step_ticks=step, params=req.preset)

    def frame(t: int) -> np.ndarray:
        if req.method == "guided":
            sub = _Ctx(ctx)
            res = guided_job(GuidedRequest(req.source, t, p, req.alpha, req.roi), sub)
            return res.image
        img = core.reconstruct_classical(req.source, t, req.method, p, req.alpha if p["colour_cast"] else None)
        return core.crop_roi(img, req.roi)[0] if req.roi is not None else img

    ctx.report((0, n))
    first = frame(req.ticks[0])
    ex = open_exporter(req.out, n, first.shape, cfg, meta, cancel=ctx.cancelled.is_set,
                       progress=lambda done, total: ctx.report((done, total)))
    with ex:
        ex.write(first)
        for t in req.ticks[1:]:
            ctx.check()
            ex.write(frame(t))
        return ex.close()


class _Ctx:
    """A context for a nested job: same cancel flag and state, progress swallowed."""

    def __init__(self, outer: Any):
        self.cancelled, self.state = outer.cancelled, outer.state

    def report(self, payload: Any) -> None:
        pass

    def check(self) -> None:
        if self.cancelled.is_set():
            raise Cancelled("cancelled")
