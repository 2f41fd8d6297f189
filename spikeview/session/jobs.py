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

from spikeview.session import core
from spikeview.recipe import Recipe

# ------------------------------------------------------------------------------------ previews


@dataclass(frozen=True)
class WindowRequest:
    """A job on the window around ``tick`` of ``source``: the session's parameters, the sequence's α, the ROI if one is set."""

    source: Any
    tick: int
    params: dict[str, Any]
    alpha: np.ndarray | None
    roi: tuple[int, int, int, int] | None = None


@dataclass(frozen=True)
class PreviewRequest(WindowRequest):
    """What the Stream, Rates and Degradation panels need for one window."""

    want_tfi: bool = True
    factor: int = 1  # display downsampling of the stream images
    x_override: np.ndarray | None = None  # the guided result for this window, if any (ROI-cropped)
    x_label: str = "TFP"
    recipe: Recipe | None = None  # the session's recipe (the degradation preview runs its forward model)


def frames_job(req: PreviewRequest, ctx: Any) -> core.StreamFrames:
    return core.stream_frames(req.source, req.tick, req.params, req.alpha, want_tfi=False, factor=req.factor)


def tfi_job(req: PreviewRequest, ctx: Any) -> tuple[int, np.ndarray, tuple[int, int]]:
    """``(tick, TFI image, full frame shape)`` for the Stream panel's TFI pane."""
    img = core.tfi_frame(req.source, req.tick, req.params, req.alpha, req.factor)
    return req.tick, img, (req.source.height, req.source.width)


def rates_job(req: PreviewRequest, mosaic: np.ndarray, ctx: Any) -> core.RatesResult:
    return core.site_rates(mosaic, req.source.cfa, int(req.params["window"]), req.roi, tick=req.tick)


def alpha_job(source: Any, recipe: Recipe, ctx: Any) -> tuple[np.ndarray | None, str | None, float | None, str | None, int | None]:
    """The sequence's gains α and white point from :func:`spikeview.pipeline.prepare_sequence`, with the
    sentence for a channel without spikes (no warning: warnings are process-global in threads), the line the CLI
    prints about the white balance (which, why, the gains; ``None`` without gains) and how far a dark capture's TFI
    searches at least (:attr:`spikeview.pipeline.SequenceState.tfi_reach`, ``None`` unless dark)."""
    from spikeview.pipeline import prepare_sequence, white_balance_line

    state = prepare_sequence(source, recipe, warn=False)
    return state.alpha, state.note, state.white, white_balance_line(state), state.tfi_reach


def sequence_state(source: Any, recipe: Recipe, alpha: np.ndarray | None, ctx: Any) -> Any:
    """The sequence-wide state the CLI would compute (:func:`spikeview.pipeline.prepare_sequence`:
    α and the white point), with the app's α when it has one; cached per worker for the source and
    the ``[classical]`` settings it depends on."""
    from spikeview.pipeline import prepare_sequence

    if alpha is not None and recipe.classical.colour_cast and recipe.classical.alpha is None:
        recipe = recipe.with_values({"classical.alpha": [float(v) for v in np.asarray(alpha, dtype=np.float64)]})
    key = (id(source), source.n_frames, tuple(sorted(recipe.classical.to_dict().items(), key=lambda kv: kv[0])).__repr__())
    cache = ctx.state.setdefault("sequence_state", {})
    if key not in cache:
        cache.clear()
        cache[key] = prepare_sequence(source, recipe)
    return cache[key]


@dataclass
class DegradationView:
    """A :class:`~spikeview.session.core.DegradationResult` with what it was computed from.

    ``plan`` is the window's scene plan and ``knobs`` :func:`spikeview.guided.knobs.knob_status` of it:
    the guided panel disables a control whose knob cannot act, with the reason as its tooltip.
    """

    result: core.DegradationResult
    x_label: str
    tick: int
    shape: tuple[int, int]
    plan: str = ""
    knobs: dict[str, str | None] = field(default_factory=dict)
    quantise: bool = True  # Q in the model (False: the "quantised" stage is C M X itself)
    #: what the observation pooled (:class:`spikeview.guided.temporal.Pooling`: Δτ_eff per photosite, the
    #: plan's temporal reason): the guided panel's pooling map
    pooling: Any = None
    #: the pooling map's uint8 image, made here in the worker (:func:`pooling_display`), or None
    pooling_image: np.ndarray | None = None
    #: the capture has a colour filter (mosaic and cast in the model; on a monochrome one η acts on nothing)
    colour: bool = True


def window_plan(source: Any, recipe: Recipe, tick: int, state: Any, roi: Any, ctx: Any) -> Any:
    """:func:`spikeview.pipeline.plan_window` of the window, reusing the whole frame's pooled observation this worker
    built last (``ctx.state``) when it is the one these settings build: a knob change re-plans, it does not count and
    pool the 1000² frame again (seconds; the guided run and the degradation preview each keep their own)."""
    from spikeview.pipeline import plan_window

    key = (id(source), str(getattr(source.info, "path", "")), source.n_frames, id(getattr(source.info, "camera", None)))
    kept = ctx.state.get("whole_observation")
    wp = plan_window(source, recipe, tick, state=state, roi=roi, reuse=kept[1] if kept is not None and kept[0] == key else None)
    ctx.state["whole_observation"] = (key, wp.whole)
    return wp


def degradation_job(req: PreviewRequest, ctx: Any) -> DegradationView:
    """The forward model the guided sampler will run, stage by stage, on the current reconstruction X.

    X is the guided result of this window when there is one, else the classical TFP of the recipe
    (:func:`spikeview.pipeline.reconstruct_windows`). The stages come from the sampler's own data term
    (:meth:`spikeview.guided.sampler.GuidedSampler.data_term`: the plan's M, C, Q, noise weights and
    pyramid), so the preview shows exactly the model the sampler uses.
    """
    import torch

    from spikeview.guided.baseline import to_tensor
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.pipeline import guided_scale, reconstruct_windows

    recipe = req.recipe if req.recipe is not None else Recipe()
    src = req.source
    state = sequence_state(src, recipe, req.alpha, ctx)
    wp = window_plan(src, recipe, req.tick, state, req.roi, ctx)
    cfg, obs, plan = wp.params, wp.obs, wp.plan
    channels = 3 if plan.mosaic else 1
    if req.x_override is not None and req.x_override.shape[:2] == obs.shape and (req.x_override.ndim == 3) == (channels == 3):
        x, label = req.x_override, req.x_label
    else:
        tfp = recipe.with_values({"run.method": "tfp"})
        x = next(reconstruct_windows(src, [req.tick], tfp, state, roi=req.roi))
        if channels == 1 and x.ndim == 3:
            x = x.mean(axis=-1)
        label = "TFP (classical)"
    data = GuidedSampler.data_term(obs, plan, cfg)
    # X is in the outputs' linear units (Y·α/η); the data term works at the sampler's exposure, as in
    # pipeline.reconstruct_windows (without this, A X of a Bayer capture was ~2.7x brighter than Y)
    scale = np.float32(guided_scale(state))
    with torch.no_grad():
        st = data.stages(to_tensor(np.clip(x / scale, 0.0, 1.0)))
    res = core.stage_images(x, st, req.params, bool(req.params.get("show_pyramid")), scene_scale=float(scale))
    return DegradationView(res, label, req.tick, obs.shape, str(plan), wp.knobs, plan.quantise, plan.pooling,
                           pooling_display(plan.pooling), colour=bool(plan.mosaic))


def pooling_display(pool: Any) -> np.ndarray | None:
    """The guided panel's pooling-map image of ``pool`` (uint8), made in the worker, not on the GUI thread."""
    return core.pooling_display(pool)


# ---------------------------------------------------------------------------------- guided


@dataclass(frozen=True)
class GuidedRequest(WindowRequest):
    """One guided reconstruction of the window around ``tick`` (on the ROI when one is set)."""

    ground_truth: Callable[[int], np.ndarray] | None = None
    run: int = 0
    recipe: Recipe = field(default_factory=Recipe)


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
    knobs: dict[str, str | None] = field(default_factory=dict)
    pooling: Any = None  # "plan": the observation's Pooling (the guided panel's pooling map)
    pooling_image: np.ndarray | None = None  # "plan": its map image (uint8, made in the worker)
    tile_map: dict[str, Any] | None = None  # "plan": the per-tile plan (TileMap.as_dict()), None when tiles are off
    tiles: str = ""  # "plan": the plan's tiles line (the map's summary, or why tiles are off)


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
    #: the whole score against the aligned ground truth (:func:`score_frame`: PSNR, SSIM, one-gain PSNR, ΔE00),
    #: empty without a ground truth
    scores: dict[str, float] = field(default_factory=dict)
    #: the aligned ground truth the run was scored against, as a display image (uint8, ROI-sized), or None
    truth_preview: np.ndarray | None = None


def guided_job(req: GuidedRequest, ctx: Any) -> GuidedResult:
    """Plan, then run the guided reconstruction of one window through the pipeline, reporting the clean
    estimate (and metrics against the aligned ground truth) every step.

    Everything runs inside the job's :func:`~spikeview.errors.cancel_scope`: Cancel also stops the sequence's
    α and white point, the window's observation (the neighbours' counts and their alignment, seconds at
    1000×1000) and the plan, not only the sampler's steps."""
    from spikeview.errors import cancel_scope

    with cancel_scope(ctx.cancelled):
        return _guided_job(req, ctx)


def _guided_job(req: GuidedRequest, ctx: Any) -> GuidedResult:
    from spikeview import metrics
    from spikeview.cfa import crop_roi
    from spikeview.pipeline import reconstruct_windows

    p = req.params
    recipe = req.recipe.with_values({"run.method": "guided"})
    state = sequence_state(req.source, recipe, req.alpha, ctx)
    wp = window_plan(req.source, recipe, req.tick, state, req.roi, ctx)
    cfg, whole, obs, plan = wp.params, wp.whole, wp.obs, wp.plan  # the run reuses the whole observation (built once)
    origin = crop_roi(np.zeros((req.source.height, req.source.width), np.uint8), req.roi)[1][::-1] if req.roi else (0, 0)
    ctx.report(GuidedUpdate("plan", req.run, total=cfg.steps * cfg.chains, text=str(plan), knobs=wp.knobs,
                              pooling=plan.pooling, pooling_image=pooling_display(plan.pooling),
                              tile_map=None if plan.tile_map is None else plan.tile_map.as_dict(),
                              tiles=plan.reasons.get("tiles", "")))
    gt = aligned_truth(req.ground_truth, req.tick, req.roi, obs)
    t0 = time.perf_counter()

    # frames come back in linear-frame units; they are scored at the sampler's exposure, where the
    # ground truth is aligned to the exposed observation and both lie in [0, 1]
    to_exposed, gt = scoring_units(state, gt)

    def score(img: np.ndarray) -> tuple[float | None, float | None]:
        if gt is None or gt.shape != img.shape:
            return None, None
        return metrics.psnr_ssim(np.clip(img * to_exposed, 0.0, 1.0), gt, data_range=1.0)

    def callback(fi: int, n: int, step: int, total: int, preview: np.ndarray) -> None:
        ctx.check()
        img = np.asarray(preview, dtype=np.float32)
        psnr, ssim = score(img)
        ctx.report(GuidedUpdate("step", req.run, step, total, core.show(img, p), time.perf_counter() - t0, psnr, ssim))

    sampler = ctx.state.get("sampler")
    if sampler is None:
        from spikeview.guided.sampler import GuidedSampler

        sampler = ctx.state["sampler"] = GuidedSampler(cfg)
    image = next(reconstruct_windows(req.source, [req.tick], recipe, state, roi=req.roi,
                                     callback=callback, cancel=ctx.cancelled, sampler=sampler, first_observation=whole))
    ctx.check()
    image = np.asarray(image, dtype=np.float32)
    psnr, ssim = score(image)
    elapsed = time.perf_counter() - t0
    scores = score_frame(image, gt, to_exposed)
    truth = None if gt is None else core.show(gt / to_exposed, p)
    return GuidedResult(req.run, req.tick, image, core.show(image, p), origin, str(plan),
                        elapsed, psnr, ssim, recipe.to_dict(), scores, truth)


def scoring_units(state: Any, gt: np.ndarray | None) -> tuple[np.float32, np.ndarray | None]:
    """The factor from linear frames to the units they are scored in, and the aligned ground truth ``gt`` in them:
    the sampler's exposure (the sequence's white at :data:`~spikeview.guided.observation.EXPOSURE_LEVEL`). A capture
    the sampler sees without a colour cast (monochrome) is exposed as its rates; it is scored with the sequence's
    exposure white brought to that level alike, not the display's White control (in spikes per tick with a data range
    of 1, a Spike-Zoo clip, white 0.6, scored 4.4 dB above its exported frames)."""
    from spikeview.guided.observation import EXPOSURE_LEVEL
    from spikeview.pipeline import guided_scale

    to_exposed = 1.0 / guided_scale(state)
    if state.alpha is None:  # the sequence's exposure white, as guided_scale takes it (not the display's White control)
        white = float(state.sampler_white) if state.sampler_white is not None else 1.0
        k = EXPOSURE_LEVEL / white if np.isfinite(white) and white > 0 else 1.0
        to_exposed *= k
        gt = None if gt is None else np.clip(gt * np.float32(k), 0.0, 1.0).astype(np.float32)
    return np.float32(to_exposed), gt


def aligned_truth(ground_truth: Callable[[int], Any] | None, tick: int, roi: tuple[int, int, int, int] | None,
                  obs: Any) -> np.ndarray | None:
    """The ground truth of the window at ``tick`` (ROI-cropped) in the observation's colour normalisation at the
    sampler's exposure (:func:`spikeview.metrics.align_ground_truth`), float32 in [0, 1]; ``None`` without one, or
    when its size is not the observation's."""
    from spikeview import metrics
    from spikeview.cfa import crop_roi

    g = ground_truth(tick) if ground_truth is not None else None  # None: no frame stored near this tick
    if g is None:
        return None
    g = np.asarray(g, dtype=np.float32)
    gt = crop_roi(g, roi)[0] if roi is not None else g
    return metrics.align_ground_truth(gt, obs.y, obs.cfa, obs.alpha, obs.eta) if gt.shape[:2] == obs.y.shape else None


def score_frame(image: np.ndarray, gt: np.ndarray | None, to_exposed: float) -> dict[str, float]:
    """PSNR and SSIM (data range 1) of a linear frame ``image`` against the aligned ground truth ``gt`` at the
    sampler's exposure (``image · to_exposed``, clipped to [0, 1]: how the guided runs are scored), and the colour
    scores of :func:`spikeview.metrics.colour_scores` (``psnr_1gain``: one gain for all channels; ``delta_e00`` for
    colour frames only).
    Empty without a ground truth or when the sizes differ."""
    from spikeview import metrics

    if gt is None or gt.shape != image.shape:
        return {}
    x = np.clip(np.asarray(image, dtype=np.float32) * np.float32(to_exposed), 0.0, 1.0)
    psnr, ssim = metrics.psnr_ssim(x, gt, data_range=1.0)
    colour = metrics.colour_scores(x, gt)
    out = {"psnr": psnr, "ssim": ssim, "psnr_1gain": colour["psnr_1gain"]}
    if x.ndim == 3:  # a monochrome frame has no colour error to report (colour_scores gives it 0)
        out["delta_e00"] = colour["delta_e00"]
    return out


# ---------------------------------------------------------------------------------- comparison


@dataclass(frozen=True)
class CompareRequest(WindowRequest):
    """Score classical reconstructions of the window around ``tick`` (on the ROI) against the ground truth."""

    ground_truth: Callable[[int], np.ndarray] | None = None
    recipe: Recipe = field(default_factory=Recipe)
    methods: tuple[str, ...] = ("tfp", "tfi")


@dataclass
class CompareView:
    """What the app's comparison shows for one window: the aligned ground truth and each classical method's
    frame (uint8 display images, ROI-sized, top-left at ``origin`` = (x, y)) and their scores (:func:`score_frame`)."""

    tick: int
    origin: tuple[int, int]
    truth: np.ndarray | None
    images: dict[str, np.ndarray]
    scores: dict[str, dict[str, float]]
    roi: tuple[int, int, int, int] | None = None


def compare_job(req: CompareRequest, ctx: Any) -> CompareView:
    """Reconstruct the window with each of ``req.methods`` through the pipeline (the CLI's frames) and score
    them as the guided runs are scored (same observation, same aligned ground truth, same exposure)."""
    from spikeview.cfa import crop_roi
    from spikeview.errors import cancel_scope
    from spikeview.pipeline import plan_window, reconstruct_windows

    with cancel_scope(ctx.cancelled):
        base = req.recipe.with_values({"run.method": "guided"})
        state = sequence_state(req.source, base, req.alpha, ctx)
        origin = crop_roi(np.zeros((req.source.height, req.source.width), np.uint8), req.roi)[1][::-1] if req.roi else (0, 0)
        gt = None
        if req.ground_truth is not None:
            wp = plan_window(req.source, base, req.tick, state=state, roi=req.roi)
            gt = aligned_truth(req.ground_truth, req.tick, req.roi, wp.obs)
        to_exposed, gt = scoring_units(state, gt)
        images: dict[str, np.ndarray] = {}
        scores: dict[str, dict[str, float]] = {}
        for m in req.methods:
            ctx.check()
            recipe = req.recipe.with_values({"run.method": m})
            img = np.asarray(next(reconstruct_windows(req.source, [req.tick], recipe, state, roi=req.roi)), dtype=np.float32)
            images[m] = core.show(img, req.params)
            scores[m] = score_frame(img, gt, to_exposed)
        truth = None if gt is None else core.show(gt / np.float32(to_exposed), req.params)
        return CompareView(req.tick, (int(origin[0]), int(origin[1])), truth, images, scores, req.roi)


# ---------------------------------------------------------------------------------- export


@dataclass(frozen=True)
class ExportRequest:
    """Write the recipe's reconstruction of ``ticks`` to ``out`` (format from its suffix)."""

    source: Any
    source_name: str
    ticks: tuple[int, ...]
    recipe: Recipe
    alpha: np.ndarray | None
    out: Path
    roi: tuple[int, int, int, int] | None = None
    overwrite: bool = False
    #: ``.zarr`` outputs: ``None`` in-process, ``"local:N"`` or a Dask scheduler address
    cluster: str | None = None


def export_ticks(recipe: Recipe, n_frames: int) -> tuple[int, ...]:
    """Centre ticks of the recipe's ``[run]`` (the CLI's rule, :func:`spikeview.pipeline.window_centres`)."""
    from spikeview.pipeline import window_centres

    return tuple(window_centres(recipe, n_frames)[0])


def export_job(req: ExportRequest, ctx: Any) -> list[Path]:
    """Reconstruct and write every frame with :func:`spikeview.pipeline.write_sequence` (the CLI's
    function: α once, the sequence path with reuse and warm start as configured); progress
    ``(done, total)``; Cancel keeps finished frames."""
    from spikeview.pipeline import WriteOptions, window_centres, write_sequence

    if req.out.suffix.lower() == ".zarr":
        return store_job(req, ctx)
    n = len(req.ticks)
    ctx.report((0, n))
    sampler = ctx.state.get("sampler")
    if sampler is None and req.recipe.run.method == "guided":
        from spikeview.guided.sampler import GuidedSampler

        sampler = ctx.state["sampler"] = GuidedSampler(req.recipe.guided)
    step = window_centres(req.recipe, req.source.n_frames)[1]
    state = sequence_state(req.source, req.recipe, req.alpha, ctx)
    return write_sequence(req.source, req.recipe, list(req.ticks), req.out,
                          WriteOptions(state=state, roi=req.roi, step=step, cancel=ctx.cancelled, sampler=sampler,
                                       overwrite=req.overwrite, progress=lambda done, total: ctx.report((done, total)),
                                       source_name=req.source_name))


def store_job(req: ExportRequest, ctx: Any) -> list[Path]:
    """The marked range into a Zarr store, in chunks, in-process or on Dask (``req.cluster``): the CLI's
    :func:`spikeview.cluster.reconstruct.reconstruct_to_store`. Workers read the capture from its file;
    progress ``(windows done, total)``; Cancel stops after the running chunks (finished ones are kept and
    ``spikeview reconstruct … --resume`` completes the store)."""
    from spikeview.errors import ParameterError

    path = getattr(req.source.info, "path", None)
    if path is None:
        raise ParameterError("A Zarr export reads the capture from its file, and this capture has none: "
                             "save it (File menu) or open a capture file, then export again.")
    from spikeview.cluster.reconstruct import reconstruct_to_store

    ctx.report((0, len(req.ticks)))
    reconstruct_to_store(path, req.recipe, req.out, cluster=req.cluster, overwrite=req.overwrite,
                         progress=lambda done, total: ctx.report((done, total)), cancel=ctx.cancelled.is_set)
    return [req.out]


