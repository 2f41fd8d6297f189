"""One pipeline for every front end: a recipe and a source in, frames (and files) out.

The CLI's ``reconstruct``, the app's reconstruct and export, the benchmark and the batch path all
call these functions::

    state = prepare_sequence(source, recipe)               # sequence-wide: colour cast α (once)
    for frame in reconstruct_windows(source, centers, recipe, state):
        ...
    write_sequence(source, recipe, centers, out)           # the same, straight into an exporter

* :func:`prepare_sequence` resolves what must not change from frame to frame (the gray-world gains α)
  once per sequence; :func:`recipe_for_state` records it in the recipe, so a saved preset re-runs to
  the same pixels.
* :func:`reconstruct_windows` runs the recipe's method (``tfp``/``tfi``: :mod:`spikeview.classical`;
  ``guided``: :func:`spikeview.guided.video.reconstruct_sequence`, with its plan, reuse and warm start
  as configured) on every centre tick, optionally on a region of interest.
* :func:`window_centres` turns ``[run] at / range`` into centre ticks.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import ParameterError
from spikeview.recipe import Recipe
from spikeview.transfer import WHITE_HOW

#: guided reuse / warm-start chains restart every this many windows of a range (see reconstruct_windows)
KEYFRAME = 16

#: ``callback(frame_index, n_frames, step, n_steps, preview)`` (guided: every sampler step; classical: every frame)
Callback = Callable[[int, int, int, int, np.ndarray], Any]


@dataclass
class SequenceState:
    """What a whole sequence shares, computed once before the first frame.

    Attributes:
        alpha: ``(3,)`` float64 gray-world gains, or ``None`` (monochrome stream, colour cast off).
        white: the sequence's white point in the units of its frames: ``Y·α/η`` with gains α,
            the plain rate ``Y`` without (monochrome)
            (:func:`spikeview.classical.colour_cast.estimate_white`: 99.9th percentile of the
            corrected rates); the guided sampler sees the exposure that puts it at
            :data:`spikeview.guided.observation.EXPOSURE_LEVEL`. ``None``: not estimated.
    """

    alpha: np.ndarray | None = None
    white: float | None = None
    #: the sentence when a channel had no spikes and its gain was filled in (the app shows it)
    note: str | None = None
    #: which white balance gave α and why (:func:`spikeview.classical.colour_cast.sequence_white_balance`)
    white_balance: str | None = None
    #: how the white point was found, for the white-point line (:func:`white_point_line`)
    white_how: str = WHITE_HOW
    #: the white the guided sampler's exposure is set from (:func:`sampler_params`, :func:`guided_scale`): the
    #: percentile over the reconstruction's own windows; ``None``: :attr:`white`. It differs from ``white`` only on a
    #: dark capture, whose display white is measured over longer windows: the sampler was tuned on the exposure of
    #: the window-length estimate (measured the other way, exposing a dark Bayer frame at its display white, a 1-px-a-
    #: window pan at 0.03 spikes per tick lost 1.9 dB and half its detail)
    exposure_white: float | None = None
    #: the gains α are gray-world's or the camera profile's (chosen, asked for or recorded): the guided frame keeps that
    #: balance (:mod:`spikeview.guided.balance`, :func:`sampler_params`)
    keep_balance: bool = False
    #: on a dark capture, the TFI half window its darker parts' intervals need (:func:`tfi_reach`); ``None`` otherwise.
    #: TFI searches at least this far (:func:`tfi_half_window`)
    tfi_reach: int | None = None

    @property
    def sampler_white(self) -> float | None:
        """:attr:`exposure_white`, else :attr:`white`."""
        return self.white if self.exposure_white is None else self.exposure_white

    def attrs(self) -> dict[str, Any]:
        """Plain values for metadata (Zarr attributes, logs)."""
        return {"alpha": None if self.alpha is None else [float(v) for v in self.alpha], "white": self.white,
                "exposure_white": self.exposure_white, "keep_balance": self.keep_balance}


def window_centres(recipe: Recipe, n_frames: int) -> tuple[list[int], int]:
    """Centre ticks of ``[run] at`` / ``range`` (default: the middle of the stream) and the tick step.

    Raises:
        ParameterError: a tick outside ``[0, n_frames)`` (the message names the flag).
    """
    run = recipe.run
    span = recipe.span()
    if run.at is not None:
        if not 0 <= run.at < n_frames:
            raise ParameterError(f"--at {run.at} is outside the stream, which holds ticks [0, {n_frames}).")
        return [run.at], span
    if run.range is not None:
        a, b, step = parse_range(run.range, default_step=span)
        if a < 0 or a >= n_frames:
            raise ParameterError(f"--range {run.range}: start {a} is outside the stream, which holds ticks [0, {n_frames}).")
        return list(range(a, min(b, n_frames), step)), step
    return [n_frames // 2], span


def parse_range(text: str, default_step: int) -> tuple[int, int, int]:
    """Parse ``A:B[:STEP]`` (ticks) into ``(a, b, step)``; ``B`` is exclusive."""
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        a, b = int(parts[0]), int(parts[1])
        step = int(parts[2]) if len(parts) == 3 and parts[2] else default_step
    except ValueError:
        raise ParameterError(f"--range {text!r} is not A:B or A:B:STEP in ticks (e.g. 0:2000:20).") from None
    if step < 1 or b <= a:
        raise ParameterError(f"--range {text!r} needs B > A and STEP >= 1 (e.g. 0:2000:20).")
    return a, b, step


def prepare_sequence(source: Any, recipe: Recipe, *, warn: bool = True) -> SequenceState:
    """The sequence-wide state: α from ``[classical] alpha`` or one gray-world estimate of the stream, and
    the white point. A channel without spikes gets the others' mean gain: a
    :class:`~spikeview.classical.colour_cast.ColourCastWarning` says so (``warn=False``: only
    :attr:`SequenceState.note`, for the app's worker threads, where warnings are unreliable)."""
    from spikeview.classical.colour_cast import WHITE_LOW_COUNT, ecosystem_white, estimate_white, sequence_white_balance

    c = recipe.classical
    detail: dict = {}
    a, note, why = sequence_white_balance(source, c, warn=warn, detail=detail)
    # the exposure, once per sequence, on the windows the frames are made of
    span: dict = {}
    window = min(c.window, source.n_frames)
    estimate = estimate_white(source, a, window=window, max_windows=c.alpha_max_windows, eta=c.eta, detail=span)
    white, how = ecosystem_white(estimate, source, a)
    longer = span["ticks"] > window  # a dark capture: the display white came from longer windows
    if longer and white == estimate:
        how += (f" over {span['ticks']}-tick windows (a {window}-tick window holds under {WHITE_LOW_COUNT:g} spikes at "
                "the white: its count levels, not the scene, would set the percentile)")
    if span.get("no_spikes"):
        how = ("the capture has no spikes in the windows sampled, so every frame is black whatever the white point: "
               "a covered lens, or not the file meant?")
    return SequenceState(a, white, note, why, how, span["window_white"] if longer else None,
                         keep_balance=detail["keep_balance"], tfi_reach=tfi_reach(source) if longer else None)


def tfi_reach(source: Any) -> int:
    """The TFI half window of a dark capture: far enough that a photosite with no spike in the search reads the
    capture's darkest floor (:func:`spikeview.classical.defects.darkest_floor`: its black, or its dark rate), not a level
    above it: ``1 / (2·floor)`` ticks, within the setting's bounds (up to 512).

    A search too short caps the darker photosites' intervals at 2·half_window: they all show 1/(2·half_window), one flat
    level, tinted by the gains. With the ±32-tick default a dark chelsea at 0.03 spikes a tick (floor 0.005) came out a
    uniform lilac; the real `uhsr.npz`, whose floor (0.016 spikes a tick) is that level, keeps its ±32 (a longer search
    there only trades the floor for single-interval noise: detail 0.698 → 0.621 against its long exposure at ±187)."""
    from spikeview.classical.config import ClassicalConfig
    from spikeview.classical.defects import find_defects
    from spikeview.config import param_fields

    hi = dict(param_fields(ClassicalConfig))["tfi_half_window"].hi
    floor = float(find_defects(source).floor)
    return int(hi if floor <= 1.0 / (2 * hi) else min(hi, np.ceil(1.0 / (2.0 * floor))))


def tfi_half_window(configured: int, state: SequenceState | None) -> int:
    """How far TFI searches: the setting (``classical.tfi_half_window``), or further on a dark capture
    (:attr:`SequenceState.tfi_reach`). The CLI says so; the app's TFI pane shows it in its title."""
    reach = None if state is None else state.tfi_reach
    return int(configured) if reach is None else max(int(configured), int(reach))


def recipe_for_state(recipe: Recipe, state: SequenceState, source: Any = None) -> Recipe:
    """``recipe`` with the sequence's α, white point, for the guided method the prior's precision (``auto``
    resolved for this CPU or GPU) and, given the ``source``, its display curve (``export.transfer = auto`` resolved:
    :func:`spikeview.transfer.resolve_transfer`) recorded (a saved preset then reproduces the frames exactly)."""
    values: dict[str, Any] = {}
    if source is not None and recipe.export.transfer == "auto":
        from spikeview.transfer import resolve_transfer

        values["export.transfer"] = resolve_transfer("auto", source.info)[0]
    if state.alpha is not None and recipe.classical.alpha is None:
        values["classical.alpha"] = [float(v) for v in state.alpha]
    out = recipe.with_values(values) if values else recipe
    if state.white is not None and recipe.export.white is None:  # recorded as found (no slider range applies)
        out = dataclasses.replace(out, export=out.export.replace(white=float(state.white)))
    if out.run.method == "guided" and out.guided.precision == "auto":  # the prior's arithmetic, as this CPU resolves it
        from spikeview.guided.precision import resolve_precision

        from spikeview.guided.device import resolve_device

        out = out.with_values({"guided.precision": resolve_precision("auto", device=resolve_device(out.guided.device))[0]})
    return out


def guided_scale(state: SequenceState) -> float:
    """Factor from the sampler's exposed frames to linear-frame units (``white / EXPOSURE_LEVEL``).

    1 without a white point, and without gains α (monochrome, or the colour cast off): the exposure
    reaches the sampler through its colour cast C (:func:`sampler_params`), so without C the sampler
    sees the plain rates ``Y`` and its frames are already in the units of the classical frames
    (``Y``, the white point's units then too, :func:`~spikeview.classical.colour_cast.estimate_white`).
    """
    if state.sampler_white is None or state.alpha is None:
        return 1.0
    from spikeview.guided.observation import EXPOSURE_LEVEL

    return float(state.sampler_white) / EXPOSURE_LEVEL


def output_white(recipe: Recipe, state: SequenceState) -> float:
    """The white point the outputs use: ``[export] white`` when set, else the sequence's estimate (else 1)."""
    return recipe.export.white_or(state.white)


def white_point_line(recipe: Recipe, state: SequenceState, how: str) -> str:
    """The one line every output prints about its exposure (plain runs, ``.zarr`` stores and their
    export): the white point (:func:`output_white`), its unit and ``how`` it was chosen."""
    unit = "spikes per tick" if state.alpha is None else "Y·α/η, rates corrected for the colour cast"
    return (f"white point {output_white(recipe, state):.4g} ({unit}; {how}): EXR keeps values above it, "
            "npy/PNG/MP4 map it to full scale.")


def white_balance_line(state: SequenceState) -> str | None:
    """The one line a run prints about its colour cast: which white balance and why, and the gains (relative to G);
    ``None`` without gains (monochrome, colour cast off)."""
    if state.alpha is None:
        return None
    a = np.asarray(state.alpha, dtype=np.float64)
    rel = a / a[1] if a[1] > 0 else a
    return f"{state.white_balance or 'white balance'}; gains R {rel[0]:.3g}, G 1, B {rel[2]:.3g} (relative to G)."


def exposure_mapping(recipe: Recipe, state: SequenceState, out: str | Path) -> tuple[Any, Callable[[np.ndarray], np.ndarray]]:
    """The exporter settings and the frame mapping of an output (the one exposure rule of every writer).

    Every frame is divided by the white point (:func:`output_white`): EXR keeps the result
    scene-linear (above 1 where the scene is brighter than the white point), npy is clipped to
    [0, 1], PNG and MP4 map ``black``..``white`` to the display range (clipped) and apply the curve.
    """
    white = output_white(recipe, state)
    cfg = recipe.export.replace(white=1.0, black=min(recipe.export.black / white, 0.999))
    clip = Path(str(out)).suffix.lower() == ".npy"
    inv = np.float32(1.0 / white)

    def mapping(frame: np.ndarray) -> np.ndarray:
        x = np.asarray(frame, dtype=np.float32) * inv
        return np.clip(x, 0.0, 1.0) if clip else x

    return cfg, mapping


def sampler_params(recipe: Recipe, state: SequenceState) -> Any:
    """The :class:`~spikeview.guided.GuidedConfig` the sampler runs on this sequence: η set so that the
    sequence's white point sits at :data:`spikeview.guided.observation.EXPOSURE_LEVEL` (the prior and
    the data term see the exposed image, never clipped); ``recipe.guided`` without a white point or
    without gains α (no C to carry the exposure: see :func:`guided_scale`). ``balance`` is the state's
    :attr:`SequenceState.keep_balance` (:mod:`spikeview.guided.balance`)."""
    if state.sampler_white is None or state.alpha is None:
        return recipe.guided
    from spikeview.guided.observation import exposed_eta

    return recipe.guided.replace(eta=exposed_eta(recipe.classical.eta, state.sampler_white),
                                 balance=bool(state.keep_balance))


@dataclass
class WindowPlan:
    """One guided window as every front end plans it (:func:`plan_window`).

    Attributes:
        state: the sequence's state (α, white point).
        params: the :class:`~spikeview.guided.GuidedConfig` the sampler runs (:func:`sampler_params`: η at the
            sequence's exposure).
        whole: the whole frame's observation (counts, pooling); ``reconstruct_windows(..., first_observation=whole)``
            reuses it instead of counting and aligning again.
        obs: the observation the sampler runs on (``whole`` cropped to the region of interest).
        plan: the window's plan (printed by the CLI, shown by the app).
        knobs: :func:`spikeview.guided.knobs.knob_status` of the plan: why a knob cannot act here (None where it can).
    """

    state: SequenceState
    params: Any
    whole: Any
    obs: Any
    plan: Any
    knobs: dict[str, str | None]


def plan_window(source: Any, recipe: Recipe, at: int, *, state: SequenceState | None = None,
                roi: tuple[int, int, int, int] | None = None, precision: str | None = None,
                reuse: Any = None) -> WindowPlan:
    """The one place a front end turns a capture, its recipe and a centre tick (and a region of interest) into the
    guided window's observation, plan, knob status and sampler settings (:class:`WindowPlan`).

    The CLI (its printed plan and notes), the app's preview and guided jobs and the benchmark call it; the guided
    sequence itself plans each window with :func:`spikeview.guided.window.observe_window`, which this wraps.
    ``precision`` overrides ``guided.precision`` in the plan's settings (the CLI shows ``auto`` as given while the
    recipe records what it resolved to). ``reuse``: an earlier :attr:`WindowPlan.whole` of this source, used when it
    is the observation these settings build (:func:`spikeview.guided.window.observe_window`).
    """
    from spikeview.guided.knobs import knob_status
    from spikeview.guided.window import observe_window

    state = state if state is not None else prepare_sequence(source, recipe)
    params = sampler_params(recipe, state)
    if precision is not None:
        params = params.replace(precision=precision)
    w = observe_window(source, at, params, state.alpha, roi=roi, reuse=reuse)
    return WindowPlan(state, params, w.whole, w.obs, w.plan, knob_status(params, w.plan))


def reconstruct_windows(source: Any, centers: Iterable[int], recipe: Recipe, state: SequenceState | None = None, *,
                        roi: tuple[int, int, int, int] | None = None, callback: Callback | None = None,
                        cancel: Any = None, sampler: Any = None, infos: list | None = None,
                        first_observation: Any = None) -> Iterator[np.ndarray]:
    """The recipe's frames at each centre tick (see the module docstring).

    Args:
        source: the spike stream.
        centers: centre ticks, in output order.
        recipe: the settings (``recipe.run.method`` picks the method).
        state: the sequence's state (default: :func:`prepare_sequence`).
        roi: ``(x, y, w, h)`` region of interest (frames are cropped; guided samples only the region).
        callback: progress (see :data:`Callback`).
        cancel: ``threading.Event``-like or callable, checked before every frame/step
            (:class:`~spikeview.errors.Cancelled`).
        sampler: a :class:`~spikeview.guided.sampler.GuidedSampler` to reuse (keeps the prior loaded).
        infos: guided only: the run info of every frame is appended.
        first_observation: guided only: the first centre's :class:`~spikeview.guided.observation.Observation` if
            the caller built it already (for its plan); used only when it matches (see
            :func:`spikeview.guided.video.reconstruct_sequence`).

    Yields:
        float32 frames ``(H, W, 3)`` (``(H, W)`` for monochrome): TFP/TFI in [0, 1] unless
        ``classical.clip`` is off; guided in [0, 1].
    """
    state = state if state is not None else prepare_sequence(source, recipe)
    centers = list(centers)
    n = len(centers)
    if recipe.run.method == "guided":
        from spikeview.guided.video import reconstruct_sequence

        params = sampler_params(recipe, state)
        # the sampler works at the exposure that puts the white point at EXPOSURE_LEVEL; its frames go
        # back to the linear-frame units Y·α/η of the classical methods
        scale = np.float32(guided_scale(state))
        # reuse / warm-start chains restart at every KEYFRAME-th window: a window's result then never
        # depends on how a long range is split into chunks (spikeview.cluster), only on its keyframe
        for g0 in range(0, n, KEYFRAME):
            cb = None
            if callback is not None:
                def cb(fi: int, _n: int, step: int, total: int, preview: np.ndarray, _g0: int = g0) -> None:
                    callback(fi + _g0, n, step, total, preview * scale)
            for frame in reconstruct_sequence(source, centers[g0:g0 + KEYFRAME], params, alpha=state.alpha, callback=cb,
                                              cancel=cancel, sampler=sampler, infos=infos, roi=roi, resolve=False,
                                              first=first_observation if g0 == 0 else None):
                yield frame * scale
        return
    from spikeview.classical.reconstruct import reconstruct_frames
    from spikeview.cfa import crop_roi
    from spikeview.errors import Cancelled, is_cancelled

    cfg = recipe.classical.replace(method=recipe.run.method)
    if cfg.method == "tfi":
        cfg = cfg.replace(tfi_half_window=tfi_half_window(cfg.tfi_half_window, state))
    for i, frame in enumerate(reconstruct_frames(source, centers, cfg, alpha=state.alpha)):
        if is_cancelled(cancel):
            raise Cancelled(f"reconstruction cancelled at frame {i + 1} of {n}")
        out = crop_roi(frame, roi)[0] if roi is not None else frame
        if callback is not None:
            callback(i, n, 1, 1, out)
        yield out


class _FirstOnly(list):
    """A list that keeps only the first item appended (the first frame's run info, not one per frame)."""

    def append(self, item: Any) -> None:
        if not self:
            super().append(item)


@dataclass
class WriteOptions:
    """How :func:`write_sequence` runs and writes (everything but what it writes: source, recipe, centres, output).

    Attributes:
        state: the sequence's state (default: :func:`prepare_sequence`).
        roi: ``(x, y, w, h)`` region of interest.
        step: ticks between centres (recorded in the metadata).
        callback: progress per sampler step / frame (see :data:`Callback`); ``cancel``: checked before every step.
        sampler: a guided sampler to reuse (its prior loaded); ``first_observation``: the first window's observation
            when the caller built it already (:func:`reconstruct_windows`).
        progress: ``progress(done, total)`` of the exporter.
        overwrite: replace an existing output; never the source or one of ``inputs``.
        source_name: the source's name in the metadata (default: its path).
        inputs: files the run reads besides the source (never replaced); ``extra_outputs``: files written beside
            the output (e.g. its preset), checked with it before any work.
        announce: gets one sentence about a large output's size first.
    """

    state: SequenceState | None = None
    roi: tuple[int, int, int, int] | None = None
    step: int | None = None
    callback: Callback | None = None
    cancel: Any = None
    sampler: Any = None
    progress: Callable[[int, int], Any] | None = None
    overwrite: bool = False
    source_name: str | None = None
    inputs: Sequence[Any] = ()
    extra_outputs: Sequence[Any] = ()
    announce: Callable[[str], Any] | None = None
    first_observation: Any = None


def write_sequence(source: Any, recipe: Recipe, centers: Sequence[int], out: str | Path,
                   options: WriteOptions | None = None) -> list[Path]:
    """Reconstruct ``centers`` and write them to ``out`` (format from its suffix), with the recipe in the metadata.

    Nothing existing is replaced without ``options.overwrite``, and never the source or one of ``options.inputs``
    (checked for ``out`` and ``options.extra_outputs``, e.g. the preset written beside it, before any work).

    Returns:
        The files written (one for MP4/npy, one per frame for EXR/PNG patterns).
    """
    from spikeview.classical.windows import window_range
    from spikeview.export import ExportMetadata, open_exporter

    o = options if options is not None else WriteOptions()
    state = o.state if o.state is not None else prepare_sequence(source, recipe)
    recipe = recipe_for_state(recipe, state, source)
    span = recipe.span()
    centers = list(centers)
    first = window_range(centers[0], span, source.n_frames)
    meta = ExportMetadata(source=o.source_name if o.source_name is not None else str(getattr(source.info, "path", "") or ""),
                          method=recipe.run.method, tick_rate=float(source.tick_rate), window=first,
                          centre_tick=int(centers[0]), step_ticks=o.step if len(centers) > 1 else None,
                          params=recipe.to_dict())
    infos = _FirstOnly()
    frames = reconstruct_windows(source, centers, recipe, state, roi=o.roi, callback=o.callback, cancel=o.cancel,
                                 sampler=o.sampler, infos=infos, first_observation=o.first_observation)
    cfg, expose = exposure_mapping(recipe, state, out)
    head = expose(next(frames))
    plan = getattr(infos[0], "plan", None) if infos else None
    if plan is not None:  # the first frame's plan: its tile map and the prior's arithmetic, as printed
        meta.plan = {k: plan.reasons[k] for k in ("tiles", "precision") if plan.reasons.get(k)}
        meta.plan["device"] = f"{getattr(plan, 'device', 'cpu')} ({plan.reasons.get('device', '')})"
    kwargs: dict[str, Any] = {}
    if o.progress is not None:
        kwargs["progress"] = o.progress
    if o.cancel is not None:
        kwargs["cancel"] = o.cancel.is_set if hasattr(o.cancel, "is_set") else o.cancel
    ex = open_exporter(Path(out), len(centers), head.shape, cfg, meta, overwrite=o.overwrite,
                       inputs=[getattr(source.info, "path", None), *o.inputs], extra_outputs=o.extra_outputs,
                       announce=o.announce, **kwargs)
    with ex:
        ex.write(head, window=first, centre_tick=int(centers[0]))
        for c, frame in zip(centers[1:], frames):
            ex.write(expose(frame), window=window_range(c, span, source.n_frames), centre_tick=int(c))
        return ex.close()
