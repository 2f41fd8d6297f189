"""Display code of the app over the core packages (no Qt).

Everything the views show is computed here from the core (:mod:`spikeview.io`,
:mod:`spikeview.classical`, :mod:`spikeview.sim`, :mod:`spikeview.ops`, :mod:`spikeview.guided`,
:mod:`spikeview.export`), so the Qt side only moves arrays to the screen. Functions are pure and
thread-safe given a thread-safe source (:class:`spikeview.io.views.LockedSource`); workers call them off the GUI
thread.

Array conventions: frames are row-major ``(H, W)`` or ``(H, W, 3)``; SFR and reconstructions are
float32 in ``[0, 1]``; display images are uint8 (what :class:`pyqtgraph.ImageItem` shows with fixed
levels ``(0, 255)``); ticks are stream readout indices.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.cfa import flip_cfa, parse_cfa
from spikeview.errors import ParameterError
from spikeview.session.model import OpenedStream
from spikeview.io.source import ArraySource, SpikeSource, StreamInfo
from spikeview.io.views import LockedSource, ViewSource

# ------------------------------------------------------------------------------------ imports

#: modules the workers import lazily; :func:`preload` imports them on one thread first
WORKER_MODULES = (
    "spikeview.classical", "spikeview.classical.tfi", "spikeview.classical.reconstruct", "spikeview.classical.display",
    "spikeview.classical.demosaic", "spikeview.classical.colour_cast", "spikeview.session._kernels", "torch",
    "spikeview.ops", "spikeview.guided.observation", "spikeview.guided.plan", "spikeview.guided.sampler",
    "spikeview.guided.baseline", "spikeview.export", "spikeview.pipeline", "spikeview.metrics",
    # the writers' extension modules: a worker importing them holds the interpreter lock through their
    # initialisation, which froze the window for up to 100 ms at the start of the first export
    "spikeview.export.mp4", "spikeview.export.exr", "spikeview.export.png", "av", "OpenImageIO",
)


def preload() -> None:
    """Import every module the app's workers use, in the calling thread.

    The workers import lazily, and two threads importing overlapping sets of modules at the same
    moment can make Python's import locks raise ``_DeadlockError`` (seen with
    ``spikeview.classical.tfi`` imported by the TFI worker while the preview worker imported
    ``spikeview.classical.reconstruct``). The window calls this once, before any worker starts; it
    costs about 3 s on first use (mostly torch) and nothing afterwards.
    """
    import importlib

    for name in WORKER_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:  # an optional writer missing: its export says so when asked for
            pass
    # numba's cached counting kernel loads under the interpreter lock (tens of ms): in the workers, a first file
    # open of the process stalled the window 70-83 ms on it (the demo is an in-memory stream and never loads it)
    from spikeview.io import warm_up_counting

    warm_up_counting()


# ------------------------------------------------------------------------------------ sources


def memory_stream(base: SpikeSource, label: str, ground_truth: Callable[[int], np.ndarray] | None = None,
                  cfa: str | None = None, flip_vertical: bool = False, *, _use_cfa: bool = False) -> OpenedStream:
    """An :class:`OpenedStream` over an in-memory source that re-interprets without copying."""
    cfa = cfa if _use_cfa else base.cfa
    view: SpikeSource = ViewSource(base, cfa, flip_vertical) if (flip_vertical or cfa != base.cfa) else base
    gt = ground_truth
    if gt is not None and flip_vertical:
        def gt(tick: int, _g=ground_truth) -> np.ndarray:  # the ground truth follows the flip
            return np.ascontiguousarray(_g(tick)[::-1])

    def reopen(**settings: Any) -> OpenedStream:
        fv = bool(settings.get("flip_vertical", flip_vertical))
        if "cfa" in settings:
            new_cfa = parse_cfa(settings["cfa"])
        else:  # flipping alone keeps the physical filter: its name follows the flip
            new_cfa = flip_cfa(cfa, base.height, base.width, vertical=fv != flip_vertical)
        return memory_stream(base, label, ground_truth, new_cfa, fv, _use_cfa=True)

    return OpenedStream(source=LockedSource(view), label=label, reopen=reopen, ground_truth=gt,
                        open_kwargs={"cfa": cfa or "none", "flip_vertical": flip_vertical})


#: size of the built-in demo capture (square): simulates in about a second (spikeview.sim.demo)
DEMO_SIZE = 256
DEMO_TICKS = 1000


def demo_stream(size: int = DEMO_SIZE, n_ticks: int = DEMO_TICKS) -> OpenedStream:
    """The built-in demo capture (simulated, with motion and colour, ground truth known)."""
    from spikeview.sim.demo import demo_capture

    cap = demo_capture(size=size, n_ticks=n_ticks)
    return memory_stream(cap, "demo capture", cap.gt_at)


def open_file(path: str | Path, **kwargs: Any) -> OpenedStream:
    """Open a capture with :func:`spikeview.io.open_source` (sidecar, detection, or ``kwargs``); ``camera=PATH``
    attaches a camera profile (:func:`spikeview.classical.calibration.attach`, as ``--camera`` does).

    Raises :class:`~spikeview.errors.GeometryError` (with ``candidates``) when the geometry is
    unknown, and other :class:`~spikeview.errors.SpikeviewError` for bad files.
    """
    from spikeview.io import open_source

    path = Path(path)
    kwargs = {k: v for k, v in kwargs.items() if v is not None}
    camera = kwargs.pop("camera", None)
    if camera is not None:
        camera = str(Path(camera).expanduser().absolute())
    src = open_source(path, **kwargs)
    from spikeview.classical.calibration import attach

    try:
        # the camera profile's corrections (``--camera``), or without one the capture's own hot photosites, filled as
        # the CLI fills them (spikeview.classical.defects)
        attach(src, camera)
    except BaseException:
        src.close()
        raise
    if camera is not None:
        kwargs["camera"] = camera
    info = src.info

    def reopen(**settings: Any) -> OpenedStream:
        merged = {**kwargs, "width": info.width, "height": info.height, "format": info.format, **settings}
        if "flip_vertical" in settings and "cfa" not in settings and info.cfa is not None:
            # a flip re-reads the same photosites upside down: keep the physical CFA
            merged["cfa"] = flip_cfa(info.cfa, info.height, info.width, vertical=settings["flip_vertical"] != info.flip_vertical)
        return open_file(path, **merged)

    gt = _file_ground_truth(path, info, kwargs)
    open_kwargs = {**kwargs, "width": info.width, "height": info.height, "format": info.format,
                   "cfa": info.cfa or "none", "flip_vertical": info.flip_vertical}  # ``camera``: the profile's path
    return OpenedStream(source=LockedSource(src), label=path.name, path=path, reopen=reopen, ground_truth=gt,
                        open_kwargs=open_kwargs)


#: a stored ground-truth frame scores a window whose centre lies at most this many ticks away
GT_TICK_TOLERANCE = 5


def _file_ground_truth(path: Path, info: Any, kwargs: dict[str, Any]) -> Callable[[int], np.ndarray | None] | None:
    """``ground_truth(tick)`` from the ``FILE.gt.npz`` beside a capture (``spikeview simulate`` writes it),
    or ``None`` without one. Only for the orientation it was written in (its sidecar's: no flip or CFA
    given), and only at ticks within :data:`GT_TICK_TOLERANCE` of a stored frame (else ``None``)."""
    from spikeview.sim.write import ground_truth_reader

    if "flip_vertical" in kwargs or "flip_horizontal" in kwargs or not info.extra.get("sidecar"):
        return None
    return ground_truth_reader(path, (info.height, info.width), GT_TICK_TOLERANCE)


def load_ground_truth(path: str | Path, shape: tuple[int, int], colour: bool) -> np.ndarray:
    """An image of a capture's scene (File ▸ Load ground truth…) as the ground truth of every tick: float32 in [0, 1],
    ``(H, W, 3)`` for a colour capture, ``(H, W)`` for a monochrome one (the mean of its channels).

    An 8-bit image (PNG, JPEG, TIFF) counts as linear values / 255 (a 16-bit greyscale one / 65535), as ``spikeview bench`` scores the Spike-Zoo
    clips' PNGs (:func:`spikeview.bench.data.spikezoo_clips`); the scores align it to the observation with a gain
    anyway. A ``.npy`` is taken as it is (values above 1 as 8-bit). Raises :class:`ParameterError` for an unreadable
    file or one of another size than the capture (``shape = (H, W)``).
    """
    path = Path(path)
    try:
        if path.suffix.lower() == ".npy":
            img = np.asarray(np.load(path, allow_pickle=False), dtype=np.float32)
            if img.max(initial=0.0) > 1.0:
                img = img / np.float32(255.0)
        else:
            from PIL import Image

            with Image.open(path) as im:
                if im.mode.startswith("I"):  # 16-bit (or 32-bit integer) greyscale: its own full scale
                    raw = np.asarray(im, dtype=np.float32)
                    img = raw / np.float32(65535.0 if raw.max(initial=0.0) > 255 or "16" in im.mode else 255.0)
                else:
                    img = np.asarray(im.convert("RGB"), dtype=np.float32) / np.float32(255.0)
    except (OSError, ValueError) as e:
        raise ParameterError(f"Cannot read {path.name} as an image ({e}); choose a PNG, JPEG, TIFF or .npy file.") from None
    if img.ndim == 3 and img.shape[-1] == 4:
        img = img[..., :3]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[-1] != 3):
        raise ParameterError(f"{path.name} is not an image (shape {img.shape}); choose an (H, W) or (H, W, 3) one.")
    if img.shape[:2] != tuple(shape):
        raise ParameterError(f"{path.name} is {img.shape[1]}×{img.shape[0]} but the capture is {shape[1]}×{shape[0]}: "
                             "load the ground truth of this capture (the same size).")
    if not colour:
        img = img.mean(axis=-1) if img.ndim == 3 else img
    elif img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    return np.ascontiguousarray(np.clip(img, 0.0, 1.0), dtype=np.float32)


def has_sidecar(path: str | Path) -> bool:
    """Whether ``path`` has a sidecar that says how to read it (:func:`spikeview.io.read_sidecar`)."""
    from spikeview.io import sidecar_path

    return sidecar_path(path).exists()


def probe_file(path: str | Path) -> tuple[dict[str, Any], list[tuple[int, int]], str]:
    """What the open dialog starts from for a file without a sidecar.

    Returns the settings detection found (format, width, height; the CFA the rates show, as
    ``spikeview info`` warns about it: :func:`spikeview.io.geometry.guess_cfa`; rows flipped for
    plain files), the ``(width, height)`` candidates when the
    geometry is ambiguous, and a sentence about it. Other errors (missing, empty file) raise.
    """
    from spikeview.errors import GeometryError, SpikeviewError
    from spikeview.io import open_source

    path = Path(path)
    initial: dict[str, Any] = {"cfa": "none", "flip_vertical": True}
    try:
        with open_source(path) as src:
            info = src.info
            initial.update(format=info.format, width=info.width, height=info.height,
                           flip_vertical=info.flip_vertical, cfa=_cfa_guess(src))
            return initial, [], f"Detected {info.format}, {info.width}×{info.height}, {info.n_frames} ticks."
    except GeometryError as e:
        cands = list(e.candidates)
        if cands:
            initial.update(width=cands[0][0], height=cands[0][1])
            try:  # the colour filter the most likely geometry shows, as `spikeview info` would warn
                with open_source(path, width=cands[0][0], height=cands[0][1], cfa=None) as src:
                    initial["cfa"] = _cfa_guess(src)
            except SpikeviewError:
                pass
        return initial, cands, str(e)


def _cfa_guess(src: Any) -> str:
    """The CFA the rates of ``src`` show (:func:`spikeview.io.geometry.guess_cfa`), ``"none"`` for monochrome."""
    from spikeview.io.geometry import guess_cfa, mean_rates

    return (guess_cfa(mean_rates(src)) or "none") if src.n_frames > 0 else "none"


def write_stream_sidecar(stream: OpenedStream) -> Path:
    """Remember how ``stream``'s file is read: write its sidecar (:func:`spikeview.io.write_sidecar`)."""
    from spikeview.io import write_sidecar

    if stream.path is None:
        raise ParameterError("Only captures opened from a file can get a sidecar.")
    info = stream.source.info
    return write_sidecar(stream.path, info)


# ------------------------------------------------------------------------------ classical
def window_range(tick: int, window: int, n_frames: int) -> tuple[int, int]:
    """Ticks ``[a, b)`` of the window around ``tick`` (the core's rule; window capped at the stream)."""
    from spikeview.classical.windows import window_range as wr

    return wr(int(tick), int(min(window, n_frames)), int(n_frames))


def display_gamma(params: dict[str, Any]) -> str | float:
    """The ``gamma`` argument of :func:`spikeview.classical.to_display` for the session's curve."""
    t = params["transfer"]  # "auto" resolved by the controller's snapshot; alone (no capture) it is sRGB, as an export's
    return "srgb" if t in ("srgb", "auto") else (1.0 if t == "linear" else 1.0 / float(params["gamma"]))


def to_display(img: np.ndarray, black: float = 0.0, white: float = 1.0, gamma: str | float = 1.0) -> np.ndarray:
    """Fixed levels → uint8 (:func:`spikeview.classical.to_display`; never auto-levels)."""
    from spikeview.classical.display import to_display as td

    return td(img, black, white, gamma)


def site_at(cfa: str | None, x: int, y: int) -> str:
    """The Bayer site (``R``, ``Gr``, ``Gb``, ``B``) of photosite ``(x, y)`` under ``cfa``, ``""`` for a monochrome
    capture (:func:`spikeview.cfa.site_offsets`' rule)."""
    from spikeview.cfa import site_offsets

    if cfa is None:
        return ""
    return next(name for name, (py, px) in site_offsets(cfa).items() if (py, px) == (y % 2, x % 2))


def roi_origin(roi: tuple[int, int, int, int] | None, shape: tuple[int, int]) -> tuple[int, int]:
    """Top-left ``(x, y)`` of the crop an ROI job works on (:func:`spikeview.cfa.crop_roi`'s rule: even pixels, the
    CFA phase kept), so the app places an ROI-sized result where it belongs in the frame."""
    from spikeview.cfa import crop_roi

    if roi is None:
        return (0, 0)
    y, x = crop_roi(np.broadcast_to(np.uint8(0), tuple(shape[:2])), roi)[1]
    return int(x), int(y)


def show(img: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """A float scene image → uint8 with the session's display levels and curve."""
    return to_display(img, params["black"], max(params["white"], params["black"] + 1e-3), display_gamma(params))


def signed_display(img: np.ndarray, scale: float) -> np.ndarray:
    """Signed image → uint8 with 0 at mid-gray and ``±scale`` at black/white (linear)."""
    s = max(float(scale), 1e-6)
    return to_display(np.asarray(img, dtype=np.float32) / np.float32(2 * s) + np.float32(0.5), 0.0, 1.0, 1.0)


def alpha_note(means: np.ndarray) -> tuple[np.ndarray, str | None]:
    """Gray-world α from channel means with the core's zero-mean rule, the sentence instead of a warning
    (:func:`spikeview.classical.colour_cast.alpha_with_note`: warnings are process-global in threads)."""
    from spikeview.classical.colour_cast import alpha_with_note

    return alpha_with_note(means)


# ----------------------------------------------------------------------------- stream frames


def downsample(img: np.ndarray, factor: int) -> np.ndarray:
    """Block mean of a uint8 image over ``factor × factor`` pixels (edges cropped to a multiple).

    The display is downsampled here, in the worker, to about the screen's resolution: pyqtgraph's
    own downsampling runs in the GUI thread and costs tens of ms per 1000×1000 frame. A block mean
    (not decimation) keeps sparse spike frames readable as a spike density.
    """
    f = int(factor)
    if f <= 1 or img.shape[0] < f or img.shape[1] < f:
        return img
    from spikeview.session._kernels import block_mean_u8

    arr = np.ascontiguousarray(img)
    out = block_mean_u8(arr if arr.ndim == 3 else arr[..., None], f)
    return out if img.ndim == 3 else out[..., 0]


@dataclass
class StreamFrames:
    """The three Stream-panel images of one window (uint8, ready to show).

    ``raw``, ``tfp`` and ``tfi`` are downsampled by ``factor`` for display (they still cover the
    whole ``shape``); ``mosaic`` is always full resolution.
    """

    tick: int
    a: int
    b: int
    raw: np.ndarray  # (H, W) uint8 0/255: spikes of the centre tick
    tfp: np.ndarray  # (H, W, 3) uint8: demosaicked, colour-corrected TFP with the display levels
    tfi: np.ndarray | None  # (H, W, 3) uint8 TFI, None when not computed
    spike_rate: float  # mean SFR of the window (spikes per photosite per tick)
    mosaic: np.ndarray  # (H, W) float32 TFP SFR (what the rates panel and the physics see)
    factor: int = 1
    shape: tuple[int, int] = (0, 0)  # full frame (H, W)


def stream_frames(source: SpikeSource, tick: int, params: dict[str, Any], alpha: np.ndarray | None,
                  want_tfi: bool = True, factor: int = 1) -> StreamFrames:
    """Raw spikes at ``tick``, TFP and TFI previews of the window around it.

    One read covers the TFP window and the TFI search span, so a frame costs one source access;
    the TFP image is :func:`spikeview.classical.preview_rgb` (the core's fast path) on that block.
    """
    from spikeview.classical.calibration import camera_of
    from spikeview.classical.reconstruct import preview_rgb
    from spikeview.classical.tfi import tfi_block, tfi_span
    from spikeview.classical.tfp import counts_to_sfr

    n = source.n_frames
    window = int(min(params["window"], n))
    a, b = window_range(tick, window, n)
    hw = int(params["tfi_half_window"])
    lo, hi = a, b
    if want_tfi:
        t_lo, t_hi = tfi_span(tick, hw, n)
        lo, hi = min(a, t_lo), max(b, t_hi)
    block = source.read(lo, hi)
    raw = block[tick - lo] * np.uint8(255)
    cfa = source.cfa
    sub = ArraySource(block, info=StreamInfo(width=source.width, height=source.height, n_frames=hi - lo,
                                             tick_rate=source.tick_rate, cfa=cfa))
    use_cast = bool(params["colour_cast"]) and cfa is not None
    if use_cast and alpha is None:
        alpha = alpha_note(_channel_means(block[a - lo:b - lo], cfa))[0]
    levels = {"black": params["black"], "white": max(params["white"], params["black"] + 1e-3), "gamma": display_gamma(params)}
    sfr = counts_to_sfr(block[a - lo:b - lo].sum(axis=0, dtype=np.uint16), b - a)  # the classical TFP (same numbers)
    if camera_of(source) is None:  # the fast path: a table over the counts
        tfp_img = preview_rgb(sub, tick - lo, window, alpha=alpha, colour_cast=use_cast, eta=params["eta"],
                              demosaic_method=demosaic_for(sfr, cfa, params["demosaic"]), **levels)
    else:  # the camera profile's (or the capture's own) dark rate, flat field and hot photosites: the CLI's frame
        tfp_img = _cli_frame(source, sfr, params, alpha if use_cast else None)
    tfi_img = None
    if want_tfi:
        tfi_img = _cli_frame(source, tfi_block(block, lo, tick, hw, n), params, alpha if use_cast else None)
    f = max(1, int(factor))
    return StreamFrames(tick=tick, a=a, b=b, raw=downsample(raw, f), tfp=downsample(tfp_img, f),
                        tfi=None if tfi_img is None else downsample(tfi_img, f),
                        spike_rate=float(sfr.mean()), mosaic=sfr, factor=f, shape=(source.height, source.width))


def tfi_frame(source: SpikeSource, tick: int, params: dict[str, Any], alpha: np.ndarray | None,
              factor: int = 1) -> np.ndarray:
    """The TFI preview at ``tick`` alone (uint8 RGB, downsampled by ``factor``), for its own worker."""
    from spikeview.classical.tfi import tfi

    cfa = source.cfa
    use_cast = bool(params["colour_cast"]) and cfa is not None
    img = tfi(source, int(tick), int(params["tfi_half_window"]))
    if use_cast and alpha is None:
        alpha = alpha_note(_channel_means(img[None], cfa))[0]
    return downsample(_cli_frame(source, img, params, alpha if use_cast else None), factor)


def _channel_means(block: np.ndarray, cfa: str | None) -> np.ndarray:
    from spikeview.classical.colour_cast import channel_means as cm

    return cm(block.mean(axis=0, dtype=np.float32), cfa)


def _cli_frame(source: SpikeSource, mosaic: np.ndarray, params: dict[str, Any], alpha: np.ndarray | None) -> np.ndarray:
    """A TFP/TFI rate mosaic as the CLI makes its frame (:func:`spikeview.classical.reconstruct.finish_frame`: the
    camera's correction, the cast, the demosaic decided on the corrected mosaic), shown with the session's levels."""
    from spikeview.classical.config import ClassicalConfig
    from spikeview.classical.display import to_display
    from spikeview.classical.reconstruct import finish_frame

    cfg = ClassicalConfig(eta=params["eta"], demosaic=params["demosaic"])
    y = finish_frame(source, np.asarray(mosaic, dtype=np.float32), cfg, alpha)
    out = to_display(y, params["black"], max(params["white"], params["black"] + 1e-3), display_gamma(params))
    return out if out.ndim == 3 else np.repeat(out[..., None], 3, axis=-1)


def demosaic_for(mosaic: np.ndarray, cfa: str | None, requested: str) -> str:
    """The demosaic the TFP/TFI outputs use for this frame (``"auto"``: the plan's rule from its noise)."""
    if requested != "auto":
        return requested
    if cfa is None:
        return "bilinear"  # nothing to demosaic; any valid name
    from spikeview.classical.reconstruct import auto_demosaic

    return auto_demosaic(mosaic, cfa, requested)[0]


# ----------------------------------------------------------------------------- firing rates


@dataclass
class RatesResult:
    """Per-site SFR histograms and gray-world α of one window (or its ROI)."""

    tick: int
    edges: np.ndarray  # (n_bins + 1,) SFR bin edges
    hists: dict[str, np.ndarray]  # site name → (n_bins,) fraction of photosites per bin
    means: dict[str, float]  # site name → mean SFR
    alpha: np.ndarray  # (3,) gray-world α of this window (R, G, B), (1,) for monochrome


def site_rates(sfr: np.ndarray, cfa: str | None, window: int, roi: tuple[int, int, int, int] | None = None,
               tick: int = 0) -> RatesResult:
    """The Rates panel's histograms of the SFR per Bayer site (:func:`spikeview.classical.colour_cast.site_histograms`)
    and the window's gray-world α."""
    from spikeview.classical.colour_cast import site_histograms

    edges, hists, means, ch = site_histograms(sfr, cfa, window, roi)
    return RatesResult(tick=tick, edges=edges, hists=hists, means=means, alpha=alpha_note(ch)[0])


# ----------------------------------------------------------------------------- degradation


@dataclass
class DegradationResult:
    """The forward model applied operator by operator to the current reconstruction X.

    Images are uint8 ready to show: ``x`` (X, RGB), ``mx`` (M X), ``cmx`` (C M X), ``qcmx`` (Q(C M X)),
    ``y`` (the observed mosaicked TFP), ``residual`` (Y − Q(C M X), mid-gray = 0) and, when asked,
    ``bands`` (the residual's Laplacian pyramid, finest first). ``rmse`` is the residual's RMS.
    """

    images: dict[str, np.ndarray]
    bands: list[np.ndarray] = field(default_factory=list)
    rmse: float = 0.0
    residual_scale: float = 0.0


#: fixed display range of the residual images (no per-frame scaling): ±0.5 SFR
RESIDUAL_RANGE = 0.5


def stage_images(x_img: np.ndarray, stages: dict[str, Any], display: dict[str, Any], show_pyramid: bool,
                 scene_scale: float = 1.0) -> DegradationResult:
    """Display images of the sampler's data-term stages (:meth:`spikeview.guided.likelihood.DataTerm.stages`).

    Args:
        x_img: ``(H, W, 3)`` (or ``(H, W)``) float32 reconstruction X in [0, 1].
        stages: ``x``, ``mx``, ``cmx``, ``a`` (= A X), ``y``, ``residual`` (noise-weighted
            ``√w̃ (A X − Y)``) and ``bands`` (its pyramid), as tensors.
        display: the session's display parameters for the scene-side images.
        show_pyramid: include the residual's bands (when the data term has more than one).
        scene_scale: factor from the sampler's exposure back to X's units
            (:func:`spikeview.pipeline.guided_scale`), so M X is shown like X.

    Sensor-side images (C M X onwards, Y, residual) are shown in gray, linear 0..1 through the sRGB
    curve, so the checkerboard of the mosaic stays visible; the residual is shown as ``√w̃ (Y − A X)``
    with ±:data:`RESIDUAL_RANGE` at black/white (fixed, never per frame).
    """
    def arr(t: Any) -> np.ndarray:
        return t[0, 0].detach().cpu().numpy()

    res = -arr(stages["residual"])
    rmse = float(np.sqrt(np.mean(res.astype(np.float64) ** 2)))
    sensor = {"black": 0.0, "white": 1.0, "gamma": "srgb"}
    images = {
        "x": show(x_img, display),
        "mx": show(arr(stages["mx"]) * np.float32(scene_scale), display),
        "cmx": to_display(arr(stages["cmx"]), **sensor),
        "qcmx": to_display(arr(stages["a"]), **sensor),
        "y": to_display(arr(stages["y"]), **sensor),
        "residual": signed_display(res, RESIDUAL_RANGE),
    }
    bands = []
    if show_pyramid and len(stages["bands"]) > 1:
        bands = [signed_display(-arr(b), RESIDUAL_RANGE / 2) for b in stages["bands"]]
    return DegradationResult(images=images, bands=bands, rmse=rmse, residual_scale=RESIDUAL_RANGE)



# ------------------------------------------------------------------------------------ the pooling map
#: ``palette(n) -> (n + 1, 3)`` uint8 colours of 0 … n pooled windows; the app registers its own (viridis,
#: spikeview.gui.panels.pooling) so that the jobs colour the map in their worker without importing Qt here
POOLING_PALETTE: Callable[[int], np.ndarray] | None = None


def pooling_unavailable(pool: Any, knobs: dict[str, str | None] | None = None) -> str | None:
    """Why this window has no pooling map (a sentence), or None when it has one.

    ``knobs`` is :func:`spikeview.guided.knobs.knob_status` of the window's plan: its
    ``guided.temporal_radius`` sentence is used where the capture holds no neighbouring window.
    """
    if pool is None:
        return "no window has been planned yet"
    if pool.radius <= 0 or pool.kind == "off":
        return ("temporal_radius is 0: the window alone, as in the paper; raise Neighbours ± to pool the aligned "
                "neighbouring windows")
    if pool.dtau is None or not pool.offsets:
        why = (knobs or {}).get("guided.temporal_radius")
        return why or pool.reason
    return None


def pooling_image(dtau: np.ndarray, window: int, n: int) -> np.ndarray:
    """``(H, W, 3)`` uint8: each photosite coloured by its number of pooled neighbours ``Δτ_eff/Δτ − 1`` (0 … n)."""
    idx = np.clip(np.rint(np.asarray(dtau, dtype=np.float32) / float(window) - 1.0), 0, n).astype(np.intp)
    if POOLING_PALETTE is None:
        raise RuntimeError("no pooling palette registered (spikeview.gui.panels.pooling registers the app's)")
    return POOLING_PALETTE(n)[idx]


def pooling_display(pool: Any) -> np.ndarray | None:
    """The map's image of ``pool`` (:func:`pooling_image`), or None where there is no map.

    Called by the jobs that report a pooling (the degradation preview, a guided run's plan), in their
    worker: at 1000×1000 the colour mapping took 45 ms of the GUI thread (issue 15).
    """
    if pooling_unavailable(pool) is not None:
        return None
    if POOLING_PALETTE is None:  # no app registered its palette: the app colours the map itself
        return None
    return pooling_image(pool.dtau, pool.window, len(pool.offsets))




#: the white-balance picker's patch: (2·half + 1)² photosites around the click, over this many ticks around the tick
PICK_HALF, PICK_TICKS = 12, 200


def neutral_gains(source: SpikeSource, tick: int, x: int, y: int, half: int = PICK_HALF,
                  ticks: int = PICK_TICKS) -> np.ndarray:
    """Fixed colour-cast gains ``(R, G, B)`` that make the patch around frame pixel ``(x, y)`` neutral (the app's
    white-balance picker; ``--white-balance R,G,B``): per channel, the patch's mean rate over ``ticks`` ticks around
    ``tick``, inverted, scaled as gray-world's gains are (1 / the frame's mean rate over those ticks).

    Raises:
        ParameterError: a monochrome capture, a point outside the frame, or a patch with a channel without spikes.
    """
    from spikeview.cfa import channel_map
    from spikeview.classical.tfp import window_counts
    from spikeview.errors import ParameterError

    if source.cfa is None:
        raise ParameterError("a monochrome capture has no colour to balance.")
    h, w = source.height, source.width
    if not (0 <= x < w and 0 <= y < h):
        raise ParameterError(f"({x}, {y}) is outside the {w}x{h} frame: click on the image.")
    a = max(0, int(tick) - ticks // 2)
    b = min(source.n_frames, a + ticks)
    counts = np.asarray(window_counts(source, a, b), dtype=np.float64) / max(1, b - a)
    ch = channel_map(source.cfa, h, w)
    y0, y1, x0, x1 = max(0, y - half), min(h, y + half + 1), max(0, x - half), min(w, x + half + 1)
    patch, pch = counts[y0:y1, x0:x1], ch[y0:y1, x0:x1]
    means = np.array([patch[pch == c].mean() if (pch == c).any() else 0.0 for c in range(3)])
    if not (means > 0).all():
        raise ParameterError("the picked patch has a colour without spikes: pick a brighter white or gray surface.")
    frame = float(counts.mean())
    return (means.mean() / means) / max(frame, 1e-12)
