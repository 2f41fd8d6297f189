"""Colour cast: gray-world per-channel gains, and per-site rate statistics.

The sensor's per-channel response is far from neutral (real captures look green). SpikeDiff's
forward model scales the clean image ``X`` per channel before it is observed,

    ``Y_c = (η / α_c) · X_c``,   so the correction is   ``X_c = Y_c · α_c / η``,

with the gray-world estimate ``α_c = 1 / mean(Y_c)`` (mean SFR over the photosites of channel ``c``
and **over the whole sequence**, so one α per sequence keeps colours stable from frame to frame).
After correction every channel's sequence mean is ``1/η``: η is the range parameter that sets the
overall brightness (η = 2 maps each channel's mean to 0.5).

Zero means: a channel with no spikes at all (dark scene, a colour the scene lacks, a monochrome
scene read as Bayer) has no gray-world gain. Instead of dividing by zero, :func:`alpha_from_means`
warns with :class:`ColourCastWarning` and uses ``1 / mean`` of the valid channels' means (the
channel is treated as if it were as bright as the others); if no channel is valid it uses α = 1.
Either way the result is finite and positive.

Monochrome streams have a single channel: α has shape ``(1,)`` and the "correction" is a plain
brightness gain.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from spikeview.cfa import CHANNEL_INDEX, CHANNEL_NAMES, parse_cfa, site_offsets
from spikeview.classical.tfp import window_counts
from spikeview.errors import ParameterError
from spikeview.io.source import SpikeSource

from spikeview.classical.config import DEFAULT_ALPHA_WINDOWS, DEFAULT_ETA  # noqa: E402  (one home: the settings)


class ColourCastWarning(UserWarning):
    """A gray-world gain could not be estimated for a channel (zero mean) and a fallback was used."""


# --- per-site / per-channel statistics -------------------------------------------------------
def _as_frames(frame: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(frame)
    if arr.ndim not in (2, 3) or min(arr.shape[-2:]) < 2:
        raise ParameterError(f"{name} must be an (H, W) or (T, H, W) array with H, W >= 2, got shape {arr.shape}; pass a mosaicked frame.")
    return arr


def _site_sums(frame: np.ndarray, cfa: str | None) -> dict[str, tuple[float, int]]:
    """(sum, number of values) per site name (``"Y"`` for monochrome); float64 sums."""
    if cfa is None:
        return {"Y": (float(frame.sum(dtype=np.float64)), frame.size)}
    out = {}
    for name, (py, px) in site_offsets(cfa).items():
        sub = frame[..., py::2, px::2]
        out[name] = (float(sub.sum(dtype=np.float64)), sub.size)
    return out


def site_rates(frame: np.ndarray, cfa: str | None) -> dict[str, float]:
    """Mean value per Bayer photosite class.

    Args:
        frame: mosaicked ``(H, W)`` frame or ``(T, H, W)`` stack, e.g. TFP SFR in [0, 1] (then the
            result is the mean firing rate in spikes per tick), flips applied so ``cfa`` names
            its top-left 2×2.
        cfa: ``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"`` or ``None`` for monochrome.

    Returns:
        ``{"R": …, "Gr": …, "Gb": …, "B": …}`` (Gr shares rows with R, Gb with B) as Python
        floats, or ``{"Y": …}`` for monochrome. A clear Gr/Gb mismatch or a wildly dominant
        channel usually means a wrong CFA, flip or width setting.
    """
    arr = _as_frames(frame, "frame")
    return {k: s / n for k, (s, n) in _site_sums(arr, parse_cfa(cfa)).items()}


def site_histograms(sfr: np.ndarray, cfa: str | None, window: int, roi: tuple[int, int, int, int] | None = None
                    ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, float], np.ndarray]:
    """Histograms of the SFR per Bayer site (``R``, ``Gr``, ``Gb``, ``B``; ``all`` for mono), their means, and the
    channel means (R, G, B; greens weighted by their photosites; ``(1,)`` for mono).

    One bin per TFP level ``{0, 1/Δτ, …, 1}`` (for Δτ ≤ 64; longer windows use 65 bins), so the
    histogram shows the quantisation exactly. The ROI ``(x, y, w, h)`` is cut from the full frame and sites keep
    their full-frame parity (the CFA phase does not depend on the ROI).

    Returns:
        ``(edges, hists, means, channel_means)``: ``(n_bins + 1,)`` bin edges, per site the fraction of photosites
        per bin, per site the mean SFR, the channel means.
    """
    n = int(min(max(window, 1), 64))
    edges = np.linspace(-0.5 / n, 1 + 0.5 / n, n + 2)
    x0 = y0 = 0
    sub = sfr
    if roi is not None:
        x0, y0, w, h = roi
        sub = sfr[y0:y0 + h, x0:x0 + w]
    planes = {"all": sub} if cfa is None else {
        name: sub[(py - y0) % 2::2, (px - x0) % 2::2] for name, (py, px) in site_offsets(parse_cfa(cfa)).items()}
    hists, means, sizes = {}, {}, {}
    for name, plane in planes.items():
        idx = np.rint(plane * np.float32(n)).astype(np.intp).ravel()
        np.clip(idx, 0, n, out=idx)
        sizes[name] = idx.size
        hists[name] = np.bincount(idx, minlength=n + 1).astype(np.float64) / max(idx.size, 1)
        means[name] = float(plane.mean(dtype=np.float64)) if plane.size else 0.0
    if cfa is None:
        ch = np.array([means["all"]])
    else:
        ngr, ngb = sizes["Gr"], sizes["Gb"]
        g = (means["Gr"] * ngr + means["Gb"] * ngb) / max(ngr + ngb, 1)
        ch = np.array([means["R"], g, means["B"]])
    return edges, hists, means, ch


def _channel_means_from_sums(sums: dict[str, tuple[float, int]], cfa: str | None) -> np.ndarray:
    if cfa is None:
        s, n = sums["Y"]
        return np.array([s / n])
    tot = np.zeros(3)
    cnt = np.zeros(3)
    for name, (s, n) in sums.items():
        c = CHANNEL_INDEX[name[0]]
        tot[c] += s
        cnt[c] += n
    # a channel without photosites (a capture one pixel wide or high) has no mean: 0, as a channel without spikes
    return np.divide(tot, cnt, out=np.zeros(3), where=cnt > 0)


def channel_means(frame: np.ndarray, cfa: str | None) -> np.ndarray:
    """Mean of a mosaicked ``(H, W)`` / ``(T, H, W)`` array over the sites of each channel.

    Returns:
        float64 array ``(3,)`` in R, G, B order for a Bayer CFA, ``(1,)`` for monochrome.
    """
    arr = _as_frames(frame, "frame")
    cfa = parse_cfa(cfa)
    return _channel_means_from_sums(_site_sums(arr, cfa), cfa)


# --- gray-world α ------------------------------------------------------------------------------
def alpha_with_note(means: np.ndarray) -> tuple[np.ndarray, str | None]:
    """Gray-world gains and, when the zero-mean fallback was used, the sentence saying so.

    The same rule as :func:`alpha_from_means` without a warning, for callers that show the
    sentence themselves (the GUI's status bar; warnings are process-global and unreliable from
    worker threads).

    Returns:
        ``(alpha, note)``: float32 gains of the shape of ``means``, and ``None`` or one sentence.
    """
    m = np.asarray(means, dtype=np.float64).reshape(-1)
    valid = np.isfinite(m) & (m > 0)
    alpha = np.ones_like(m)
    alpha[valid] = 1.0 / m[valid]
    note = None
    if not valid.all():
        names = CHANNEL_NAMES if m.size == 3 else ("Y",) * m.size
        bad = ", ".join(names[i] for i in np.flatnonzero(~valid))
        if valid.any():
            fill = 1.0 / float(m[valid].mean())
            how = f"using the other channels' mean instead (alpha = {fill:.4g})"
        else:
            fill = 1.0
            how = "using alpha = 1 (no colour correction)"
        alpha[~valid] = fill
        note = f"Colour cast: channel {bad} has no spikes in the sampled ticks, so its gray-world gain is undefined; {how}."
    return alpha.astype(np.float32), note


def alpha_from_means(means: np.ndarray) -> np.ndarray:
    """Gray-world gains ``α_c = 1 / mean_c`` with the zero-mean fallback of the module docstring.

    Args:
        means: per-channel mean SFR, shape ``(3,)`` (R, G, B) or ``(1,)`` (monochrome).

    Returns:
        float32 array of the same shape, finite and positive.

    Warns:
        ColourCastWarning: when a channel's mean is zero (or not finite) and a fallback is used.
    """
    alpha, note = alpha_with_note(means)
    if note is not None:
        warnings.warn(note, ColourCastWarning, stacklevel=3)
    return alpha


def alpha_from_sfr(sfr: np.ndarray, cfa: str | None) -> np.ndarray:
    """Gray-world α from mosaicked SFR held in memory.

    Args:
        sfr: ``(H, W)`` frame or ``(T, H, W)`` stack of mosaicked SFR (e.g. TFP), flips applied.
            Pass the whole sequence (or a sample of it) to get the per-sequence α.
        cfa: the CFA of ``sfr`` or ``None`` for monochrome.

    Returns:
        float32 ``(3,)`` (R, G, B) or ``(1,)`` (monochrome); see :func:`alpha_from_means`.
    """
    return alpha_from_means(channel_means(sfr, cfa))


def sample_starts(n_frames: int, window: int, max_windows: int) -> list[int]:
    """First ticks of ``max_windows`` windows of ``window`` ticks spread evenly over the stream.

    Includes the first and the last possible window. Returns ``[0, window, 2·window, …]``
    covering the whole stream instead when that needs no more than ``max_windows`` windows.
    """
    if window < 1 or max_windows < 1:
        raise ParameterError(f"window and max_windows must be at least 1, got {window} and {max_windows}; pass positive values.")
    if window > n_frames:
        raise ParameterError(f"window of {window} ticks is longer than the stream's {n_frames} ticks; choose a window of at most {n_frames}.")
    if -(-n_frames // window) <= max_windows:
        return list(range(0, n_frames, window))
    return sorted({round(float(s)) for s in np.linspace(0, n_frames - window, max_windows)})


def sequence_channel_means(source: SpikeSource, window: int = 10, max_windows: int = DEFAULT_ALPHA_WINDOWS) -> np.ndarray:
    """Mean SFR per channel over the whole sequence, from spike counts (see :func:`estimate_alpha`).

    Returns:
        float64 ``(3,)`` (R, G, B) or ``(1,)`` (monochrome), in spikes per tick.
    """
    starts = sample_starts(source.n_frames, window, max_windows)
    total = np.zeros((source.height, source.width), dtype=np.uint64)
    ticks = 0
    for s in starts:
        e = min(s + window, source.n_frames)
        total += window_counts(source, s, e)
        ticks += e - s
    cfa = source.cfa
    sums = {k: (v / ticks, n) for k, (v, n) in _site_sums(total, cfa).items()}
    return _channel_means_from_sums(sums, cfa)


def sequence_images(source, window: int = 10, max_windows: int = 64, correct=None
                    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray], int, np.ndarray]:
    """What the white-balance estimators see (:mod:`spikeview.classical.white_balance`): the sequence image, the same of
    the even and of the odd sampled windows, the ticks averaged, and the channel means.

    The images hold the mean rate (spikes per tick) of each 2×2 cell's R, G, B
    (:func:`~spikeview.classical.white_balance.cells_rgb`) over the windows :func:`sample_starts` picks (the gray-world
    estimate's windows), binned to at most :data:`~spikeview.classical.white_balance.MAX_CELLS` cells a side; float64
    ``(h, w, 3)``. The channel means (R, G, B, both greens) are those of :func:`sequence_channel_means`. ``correct``: a
    function ``(rates (H, W) float64) → rates`` (a camera profile's dark and flat correction,
    :meth:`spikeview.classical.calibration.CameraProfile.correct`) or ``None``.
    """
    from spikeview.classical import white_balance as wb

    window = min(int(window), source.n_frames)
    totals = [np.zeros((source.height, source.width), dtype=np.float64) for _ in (0, 1)]
    ticks = [0, 0]
    for i, s in enumerate(sample_starts(source.n_frames, window, max_windows)):
        e = min(s + window, source.n_frames)
        totals[i % 2] += window_counts(source, s, e)
        ticks[i % 2] += e - s

    def rates(total: np.ndarray, n: int) -> np.ndarray:
        r = total / max(n, 1)
        return r if correct is None else np.asarray(correct(r), dtype=np.float64)

    def image(r: np.ndarray) -> np.ndarray:
        return wb.binned(wb.cells_rgb(r, source.cfa))

    every = rates(totals[0] + totals[1], ticks[0] + ticks[1])
    means = _channel_means_from_sums(_site_sums(every, source.cfa), source.cfa)
    whole = image(every)
    if ticks[1] == 0:
        return whole, (whole, whole), ticks[0], means
    return whole, (image(rates(totals[0], ticks[0])), image(rates(totals[1], ticks[1]))), ticks[0] + ticks[1], means


def sequence_alpha(source: SpikeSource, config: Any, *, warn: bool = True) -> tuple[np.ndarray | None, str | None]:
    """The sequence's gains α by the one rule, and the note for a channel without spikes (else ``None``).

    ``(gains, note)`` of :func:`sequence_white_balance` (which also says which estimator and why).
    """
    a, note, _ = sequence_white_balance(source, config, warn=warn)
    return a, note


def sequence_white_balance(source: SpikeSource, config: Any, *, warn: bool = True, detail: dict | None = None
                           ) -> tuple[np.ndarray | None, str | None, str | None]:
    """The sequence's gains α, the note for a channel without spikes, and which white balance gave them and why.

    ``config`` is a :class:`~spikeview.classical.config.ClassicalConfig` (its ``colour_cast``, ``alpha``,
    ``white_balance``, ``alpha_window`` and ``alpha_max_windows``). No α (``None``) for a monochrome stream or with
    the colour cast off; ``config.alpha`` when set (the gains a run recorded); else by ``config.white_balance``
    (:mod:`spikeview.classical.white_balance`): fixed gains ``R,G,B``, the camera profile's colour response
    (``profile``: ``source.info.camera``), gray-world (one estimate of the stream from ``alpha_window``-tick windows,
    :func:`sequence_channel_means`, :func:`alpha_with_note`), another estimator, or ``auto``. A profile's dark and
    flat correction applies to the rates every estimator sees. α is float64 ``(3,)``. A channel without spikes gets
    the others' mean gain; with ``warn`` the note is also issued as a :class:`ColourCastWarning`.

    ``detail``: a dict that receives ``keep_balance``: whether the gains are gray-world's or the camera profile's
    colour response's for this stream (the estimator was one of :data:`KEEP_BALANCE`, or recorded / fixed gains equal
    theirs within 1e-6): the guided frame then keeps that balance (:mod:`spikeview.guided.balance`). Not for the
    other estimators.
    """
    from spikeview.classical import white_balance as wb

    out = detail if detail is not None else {}
    out["keep_balance"] = False
    if source.cfa is None or not config.colour_cast:
        return None, None, None
    camera = getattr(source.info, "camera", None)
    # on dark-subtracted rates the guided frame's clip at 0 lifts each channel's black by its own noise, whatever the
    # gains: there it keeps the balance for every white balance (the plan applies it only where the rates moved)
    moved = bool(camera is not None and camera.moves_rates())
    given = None
    if config.alpha is not None:
        given = np.asarray(config.alpha, dtype=np.float64), "white balance: the recorded gains classical.alpha"
    choice = wb.parse_white_balance(getattr(config, "white_balance", "gray-world"), "classical.white_balance")
    if given is None and not isinstance(choice, str):
        given = np.asarray(choice, dtype=np.float64), "white balance: the fixed gains R,G,B given"
    if given is not None:
        if detail is not None:
            out["keep_balance"] = moved or _balanced_gains(source, config, given[0])
        return given[0], None, given[1]
    if choice == "profile" and (camera is None or camera.colour_response is None):
        raise ParameterError("--white-balance profile needs a camera profile with a colour response: pass --camera "
                             "PROFILE.toml made by `spikeview calibrate --flat FLAT` (or choose auto).")
    if choice == "auto" and camera is not None and camera.colour_response is not None:
        # a measured neutral beats every blind estimator (none of them can tell a tinted scene from a tinted sensor)
        choice, why = "profile", "auto → profile: the camera profile measured this sensor's response to a neutral"
    else:
        why = None
    window = min(config.alpha_window, source.n_frames)
    tiny = min(source.height, source.width) < 2  # no 2×2 cell: nothing but the channel means
    if tiny and choice != "profile":
        choice = "gray-world"
    if choice == "gray-world" and (camera is None or tiny):  # the paper's rule from the counts (exactly as before)
        means = sequence_channel_means(source, window=window, max_windows=config.alpha_max_windows)
        how = wb.WhiteBalance("gray-world", means, "white balance gray-world (as asked)")
    else:
        img, halves, ticks, means = sequence_images(source, window, config.alpha_max_windows,
                                                    None if camera is None else camera.correct)
        how = wb.choose(img, choice, halves, ticks) if choice != "profile" else wb.WhiteBalance(
            "profile", camera.colour_response, why or f"white balance profile: the colour response of {camera.name} "
                                                      "(measured on a flat capture)")
    empty = not (np.isfinite(means) & (means > 0)).all()
    if how.method not in ("gray-world", "profile") and empty:  # a channel without spikes: gray-world's rule, its note
        how = wb.WhiteBalance("gray-world", means, f"white balance {choice} → gray-world: a channel has no spikes")
    if how.method == "gray-world":
        gains, note = alpha_with_note(means)
    else:
        gains, note = wb.gains_from_illuminant(how.illuminant, means), None
    if note is not None and warn:
        warnings.warn(note, ColourCastWarning, stacklevel=3)
    out["keep_balance"] = moved or how.method in KEEP_BALANCE
    return np.asarray(gains, dtype=np.float64), note, how.reason


#: the white balances whose colour the guided frame keeps (:mod:`spikeview.guided.balance`): gray-world's and the
#: camera profile's. Not auto's ``combined+typical``: keeping its balance where Q is on measured worse on 7 of the 9
#: colourful rows it changed (coffee 1.9° → 3.2°, bench coffee 1.0° → 2.7°; better only on rocket 4.9° → 1.6°)
KEEP_BALANCE = ("gray-world", "profile")


def _balanced_gains(source: SpikeSource, config: Any, a: np.ndarray) -> bool:
    """Whether recorded or fixed gains ``a`` are this stream's gray-world gains or its camera profile's (within 1e-6,
    up to scale): the white balances whose colour the guided frame keeps (:func:`sequence_white_balance`)."""
    from spikeview.classical import white_balance as wb

    a = np.asarray(a, dtype=np.float64)
    if a.shape != (3,) or not a[1] > 0:
        return False
    camera = getattr(source.info, "camera", None)
    window = min(config.alpha_window, source.n_frames)
    if camera is None:
        candidates = [alpha_with_note(sequence_channel_means(source, window=window,
                                                             max_windows=config.alpha_max_windows))[0]]
    else:
        means = sequence_images(source, window, config.alpha_max_windows, camera.correct)[3]
        candidates = [alpha_with_note(means)[0]]
        if camera.colour_response is not None:
            candidates.append(wb.gains_from_illuminant(camera.colour_response, means))
    return any(c[1] > 0 and np.allclose(a / a[1], c / c[1], rtol=1e-6, atol=0.0) for c in map(np.asarray, candidates))


def estimate_alpha(source: SpikeSource, window: int = 10, max_windows: int = DEFAULT_ALPHA_WINDOWS) -> np.ndarray:
    """Gray-world α of a whole sequence, from spike counts.

    The mean TFP of a channel over a set of windows is its total spike count divided by
    (ticks × photosites), whatever the window length, so α is computed from counts:

    * streams of at most ``window · max_windows`` ticks are counted completely (exact α);
    * longer streams are sampled with ``max_windows`` windows of ``window`` ticks spread evenly
      from the first to the last tick (640 ticks by default, a few ms from a file, whatever its
      length).

    Args:
        source: the sequence (flips applied; ``source.cfa`` names the CFA).
        window: ticks per sampled window (at most the stream length).
        max_windows: how many windows to sample from a long stream.

    Returns:
        float32 ``(3,)`` (R, G, B) or ``(1,)`` (monochrome); see :func:`alpha_from_means`.

    Warns:
        ColourCastWarning: a channel had no spikes in the sampled ticks. (Use
        ``alpha_with_note(sequence_channel_means(source))`` to get the sentence instead.)
    """
    alpha, note = alpha_with_note(sequence_channel_means(source, window, max_windows))
    if note is not None:
        warnings.warn(note, ColourCastWarning, stacklevel=2)
    return alpha


# --- applying the correction -------------------------------------------------------------------
def _check_alpha(alpha: np.ndarray | list[float], n: int) -> np.ndarray:
    a = np.asarray(alpha, dtype=np.float64).reshape(-1)
    if a.size == 1 and n == 3:
        a = np.repeat(a, 3)
    if a.size != n or not (np.isfinite(a).all() and (a > 0).all()):
        raise ParameterError(f"alpha must hold {n} finite positive gain(s), got {np.asarray(alpha).tolist()}; use estimate_alpha to get one.")
    return a


def _check_eta(eta: float) -> float:
    if not (np.isfinite(eta) and eta > 0):
        raise ParameterError(f"eta must be a finite positive number, got {eta!r}; use e.g. {DEFAULT_ETA}.")
    return float(eta)


def colour_gains(alpha: np.ndarray | list[float], eta: float = DEFAULT_ETA, n_channels: int = 3) -> np.ndarray:
    """The correction gains ``α_c / η`` as float32 ``(n_channels,)``."""
    return (_check_alpha(alpha, n_channels) / _check_eta(eta)).astype(np.float32)


def apply_colour_cast(rgb: np.ndarray, alpha: np.ndarray | list[float], eta: float = DEFAULT_ETA, clip: bool = False) -> np.ndarray:
    """Undo the colour cast of a demosaicked image: ``X_c = Y_c · α_c / η``.

    Args:
        rgb: ``(..., 3)`` RGB (e.g. ``(H, W, 3)``), or ``(H, W)`` monochrome with a 1-element α.
        alpha: gray-world gains, ``(3,)`` R, G, B (a single value is used for every channel).
        eta: range parameter η (each channel's sequence mean maps to ``1/η``).
        clip: clip the result to ``[0, 1]`` (for display); off by default so that the values
            the forward model needs are kept.

    Returns:
        float32 array of the shape of ``rgb``.
    """
    arr = np.asarray(rgb, dtype=np.float32)
    n = 3 if (arr.ndim >= 3 and arr.shape[-1] == 3) else 1
    if n == 1 and arr.ndim != 2:
        raise ParameterError(f"rgb must be (..., 3) colour or (H, W) monochrome, got shape {arr.shape}; pass an image.")
    out = arr * colour_gains(alpha, eta, n)
    return np.clip(out, 0.0, 1.0, out=out) if clip else out


def apply_colour_cast_mosaic(mosaic: np.ndarray, cfa: str | None, alpha: np.ndarray | list[float], eta: float = DEFAULT_ETA,
                             clip: bool = False) -> np.ndarray:
    """Undo the colour cast on a mosaicked image, site by site (before demosaicking).

    Bilinear demosaicking commutes with this per-channel gain; Malvar and Menon use the
    correlation between channels and need white-balanced input, so the pipeline corrects the
    mosaic first (the usual raw-processing order).

    Args:
        mosaic: ``(H, W)`` mosaicked values whose top-left 2×2 is ``cfa`` (``None``: monochrome,
            one gain).
        alpha: ``(3,)`` R, G, B gains, or ``(1,)`` for monochrome.
        eta: range parameter η.
        clip: clip to ``[0, 1]``.

    Returns:
        ``(H, W)`` float32.
    """
    arr = _as_frames(mosaic, "mosaic")
    if arr.ndim != 2:
        raise ParameterError(f"mosaic must be one (H, W) frame, got shape {arr.shape}; pass a single frame.")
    cfa = parse_cfa(cfa)
    if cfa is None:
        out = arr.astype(np.float32) * colour_gains(alpha, eta, 1)[0]
    else:
        g = colour_gains(alpha, eta, 3)
        out = np.array(arr, dtype=np.float32, copy=True)
        for (py, px), ch in zip(((0, 0), (0, 1), (1, 0), (1, 1)), cfa):
            out[py::2, px::2] *= g[CHANNEL_INDEX[ch]]
    return np.clip(out, 0.0, 1.0, out=out) if clip else out


# --- exposure: the white point of a sequence ---------------------------------------------------
#: default percentile of :func:`estimate_white`: at most 0.1 % of photosites lie above the white point
WHITE_PERCENTILE = 99.9
#: :func:`estimate_white` lengthens its windows when the white holds fewer spikes a window than this (a dark
#: capture: the count levels set the percentile) ...
WHITE_LOW_COUNT = 3.0
#: ... until it holds at least this many ...
WHITE_MIN_COUNT = 6.0
#: ... up to this many reconstruction windows (the ±3 the guided default pools on a still scene)
WHITE_MAX_WINDOWS = 7


def estimate_white(source: SpikeSource, alpha: np.ndarray | list[float] | None, window: int = 10,
                   max_windows: int = DEFAULT_ALPHA_WINDOWS, eta: float = DEFAULT_ETA,
                   percentile: float = WHITE_PERCENTILE, detail: dict | None = None) -> float:
    """White point of a whole sequence: a robust high percentile of its colour-corrected rates.

    Gray-world (:func:`estimate_alpha`) sets the channel **ratios**; this sets the **exposure**.
    The corrected TFP values ``Y_c · α_c / η`` of every photosite of ``max_windows`` windows of
    ``window`` ticks spread over the stream (:func:`sample_starts`; the same windows as the α
    estimate) are pooled, each spread over its quantisation step (a count ``k`` of ``window`` ticks
    stands for the rates within half a step of ``k/window``, never above one spike per tick), and the
    ``percentile``-th percentile of that spread is returned. Mapping it to full scale puts at most
    ``100 − percentile`` % of the TFP values of such windows at full scale (0.1 % by default) even
    when the level the percentile falls on holds more photosites than that, and it
    is chosen **once per sequence**, so frames do not flicker. Use the reconstruction's own window:
    shorter windows are noisier and put the percentile higher. Where the white holds fewer than
    :data:`WHITE_LOW_COUNT` spikes a window (a dark capture: a 10-tick window holds 1 or 2 spikes where it is
    brightest, and the percentile lands high in that level's spread, up to twice the brightest rate: the real dark
    capture's frames came out at half brightness), the windows grow until it holds :data:`WHITE_MIN_COUNT`, up to
    :data:`WHITE_MAX_WINDOWS` reconstruction windows (the span the guided default pools on a still scene, which its
    frames average too); ``detail["ticks"]`` (when a dict is given) says the length used.

    Args:
        source: the sequence (flips applied; ``source.cfa`` names the CFA).
        alpha: the sequence's gray-world gains ``(3,)``; ``None`` when no colour cast applies
            (monochrome streams always: their frames are ``Y``).
        window: ticks per sampled window (at most the stream length).
        max_windows: windows sampled from a long stream.
        eta: range parameter η of the linear frame (``Y · α / η``).
        percentile: in ``(0, 100]``.

    Returns:
        The white point in the units of the linear frame (> 0): ``Y · α / η`` for a Bayer stream with
        gains ``alpha``; the plain rate ``Y`` (spikes per tick) for monochrome streams and without
        gains, whose frames carry neither α nor η (``alpha`` and ``eta`` are then ignored). A stream
        without any spike gives the gray-world mean ``1/η`` (``1`` without gains) instead of 0.
    """
    if not 0.0 < float(percentile) <= 100.0:
        raise ParameterError(f"percentile = {percentile!r} is out of range: use a value in (0, 100], e.g. {WHITE_PERCENTILE}.")
    eta = _check_eta(eta)
    cfa = source.cfa
    gains = None
    if cfa is not None and alpha is not None:
        g = _check_alpha(alpha, 3)
        gains = np.ones((2, 2))
        for (py, px), ch in zip(((0, 0), (0, 1), (1, 0), (1, 1)), cfa):
            gains[py, px] = g[CHANNEL_INDEX[ch]]
    else:
        # no colour cast applies (monochrome, or a Bayer stream with the cast off): the frames are the
        # plain rates Y (reconstruct_frame applies neither α nor η to them), and so is the white point
        eta = 1.0
    n_ticks = min(int(window), source.n_frames)

    def at(n_ticks: int) -> float:
        camera = getattr(source.info, "camera", None)
        if camera is not None and not camera.from_capture:
            return _white_corrected(source, gains, n_ticks, max_windows, eta, percentile)
        # the capture's own hot photosites (spikeview.classical.defects) are left out of the histogram
        keep_px = None if camera is None else ~camera.hot
        # a histogram per distinct gain: counts take only n_ticks + 1 values per photosite class
        hist: dict[float, np.ndarray] = {}
        for s in sample_starts(source.n_frames, n_ticks, max_windows):
            if s + n_ticks > source.n_frames:  # a partial last window has other levels: left out
                continue
            counts = window_counts(source, s, s + n_ticks)
            for py in (0, 1):
                for px in (0, 1):
                    g = 1.0 if gains is None else float(gains[py, px])
                    plane = np.asarray(counts[py::2, px::2])
                    if keep_px is not None:
                        plane = plane[keep_px[py::2, px::2]]
                    h = np.bincount(plane.ravel(), minlength=n_ticks + 1)[: n_ticks + 1]
                    hist[g] = hist.get(g, 0) + h
        # TFP values are quantised (multiples of 1/Δτ): a level can hold several percent of the photosites
        # (3 % of a Spike-Zoo clip sit on its top level), and a white point ON that level would show them
        # all at full scale. Each count k stands for the rates within half a step of k/Δτ (never above 1
        # spike per tick), so the percentile is taken of that spread: a level holding the tail is split
        levels = np.arange(n_ticks + 1, dtype=np.float64)
        lo = np.concatenate([np.maximum(levels - 0.5, 0.0) / n_ticks * g / eta for g in hist])
        hi = np.concatenate([np.minimum(levels + 0.5, n_ticks) / n_ticks * g / eta for g in hist])
        weights = np.concatenate([hist[g] for g in hist]).astype(np.float64)
        spiking = float(sum(float(h[1:].sum()) for h in hist.values()))
        keep = weights > 0
        lo, hi, weights = lo[keep], hi[keep], weights[keep]
        total = float(weights.sum())
        if total <= 0 or spiking <= 0:  # no spike at all: any white point shows black; the gray-world mean
            if detail is not None:
                detail["no_spikes"] = True
            return 1.0 / eta
        target = float(percentile) / 100.0 * total
        a, b = float(lo.min()), float(hi.max())
        width = np.maximum(hi - lo, 1e-300)
        for _ in range(60):  # bisection on the piecewise-linear cumulative weight
            mid = 0.5 * (a + b)
            if float((weights * np.clip((mid - lo) / width, 0.0, 1.0)).sum()) < target:
                a = mid
            else:
                b = mid
        white = b
        return white if white > 0 else 1.0 / eta

    white = at(n_ticks)
    if detail is not None:
        detail["window_white"] = white
    # few spikes at the white: the count levels themselves set the percentile (a 10-tick window of a dark capture
    # holds 1 or 2 spikes where it is brightest, and the percentile lands in that level's spread, up to twice the
    # brightest rate); longer windows, up to the span the guided default pools, until the white holds enough spikes
    span = min(source.n_frames, WHITE_MAX_WINDOWS * n_ticks)
    top = 1.0 if gains is None else float(gains.max()) / eta  # the value of one spike per tick of the least sensitive class
    for i in range(4):
        raw = white / top  # spikes per tick at the white, the least sensitive class
        if raw <= 0 or raw * n_ticks >= (WHITE_LOW_COUNT if i == 0 else WHITE_MIN_COUNT) or n_ticks >= span:
            break
        longer = min(span, int(np.ceil(WHITE_MIN_COUNT / raw)))
        if longer <= n_ticks:
            break
        n_ticks = longer
        white = at(n_ticks)
    if detail is not None:
        detail["ticks"] = n_ticks
    return white


#: the conversion rate of the ecosystem's synthetic data sets (Spike-Zoo's ``BaseDatasetConfig.rate``, its
#: REDS-based sets alike): a frame of intensity ``I`` in [0, 1] fires ``0.6·I`` spikes per tick, and its tools show
#: ``rate / 0.6``. Measured on the five clips the ``spikezoo`` wheel ships: mean rate / mean ground truth = 0.598–0.600.
ECOSYSTEM_RATE = 0.6
#: how near the estimate must lie to :data:`ECOSYSTEM_RATE` (a factor) for a file without a sidecar to take it: the
#: 10-tick windows' 99.9th percentile of those clips reads 0.54–0.65 (0.90–1.08×), a scene without full white lower
ECOSYSTEM_BAND = 1.25


def ecosystem_white(white: float, source: SpikeSource, alpha: np.ndarray | None) -> tuple[float, str]:
    """The white point a file without a sidecar takes, and how it was found: :data:`ECOSYSTEM_RATE` spikes per tick
    when the estimate (:func:`estimate_white`, plain rates: monochrome, or no colour gains) lies within
    :data:`ECOSYSTEM_BAND` of it: the capture is then read as one of the ecosystem's synthetic data sets, whose
    ground truth is ``rate / 0.6`` (its tools divide by it); otherwise, and for spikeview's own captures (they carry a
    sidecar), the estimate. A real camera's file without a sidecar that happens to lie in the band is shown at most
    25 % darker or brighter than its estimate would; ``--white`` sets any other."""
    from spikeview.transfer import DISPLAY_KEY, WHITE_HOW

    extra = getattr(source.info, "extra", None) or {}
    if (alpha is None and "sidecar" not in extra and extra.get(DISPLAY_KEY) == "linear" and white > 0
            and 1.0 / ECOSYSTEM_BAND <= white / ECOSYSTEM_RATE <= ECOSYSTEM_BAND):
        return ECOSYSTEM_RATE, (f"a file without a sidecar whose 99.9th percentile rate, {white:.3g}, is within "
                                f"{100 * (ECOSYSTEM_BAND - 1):.0f} % of {ECOSYSTEM_RATE:g} spikes per tick: the conversion "
                                "rate of the ecosystem's synthetic data sets (Spike-Zoo), whose tools show rate / "
                                f"{ECOSYSTEM_RATE:g}; --white for another")
    return white, WHITE_HOW


def _white_corrected(source: SpikeSource, gains: np.ndarray | None, n_ticks: int, max_windows: int, eta: float,
                     percentile: float) -> float:
    """:func:`estimate_white` of a source with a camera profile: the percentile of its corrected TFP values.

    The profile's correction moves every photosite off the ``1/Δτ`` grid by its own gain, so the values are no longer
    quantised and a plain percentile of them is used (the windows and the gains are those of the histogram rule).
    """
    from spikeview.classical.calibration import correct_rates

    g = np.ones((2, 2)) if gains is None else gains
    vals = []
    for s in sample_starts(source.n_frames, n_ticks, max_windows):
        if s + n_ticks > source.n_frames:
            continue
        y = correct_rates(source, window_counts(source, s, s + n_ticks) / np.float32(n_ticks))
        h, w = y.shape
        tile = np.tile(g, (h // 2 + 1, w // 2 + 1))[:h, :w].astype(np.float32)
        vals.append((y * tile / np.float32(eta)).ravel())
    if not vals:
        return 1.0 / eta
    allv = np.concatenate(vals)
    if not (allv > 0).any():
        return 1.0 / eta
    white = float(np.percentile(allv, percentile))
    return white if white > 0 else 1.0 / eta
