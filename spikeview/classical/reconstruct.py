"""Classical reconstruction pipeline: TFP/TFI → colour cast → demosaic, and the live preview.

``reconstruct_frame`` is the reference path (float32 frames for export, metrics and the guided
sampler's initial estimate); ``preview_rgb`` is the fast path for the GUI: it fuses bilinear
demosaicking, the colour-cast gains and the display curve into one pass over the spike counts.

Order of operations: the colour cast is undone on the **mosaic**, before demosaicking. For
bilinear demosaicking this is identical to correcting afterwards (it is linear per channel);
Malvar and Menon exploit the correlation between channels and need white-balanced input, the usual
raw-processing order.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numba
import numpy as np

from spikeview.classical.calibration import correct_rates
from spikeview.classical.colour_cast import DEFAULT_ETA, apply_colour_cast_mosaic, colour_gains, sequence_alpha
from spikeview.classical.demosaic import DEMOSAIC_METHODS, check_method, demosaic
from spikeview.classical.demosaic._common import quad_codes
from spikeview.classical.config import CLASSICAL_METHODS, ClassicalConfig  # noqa: F401 (re-exported)
from spikeview.classical.display import Gamma, _check_gamma, _check_levels, encode8, to_display, transfer
from spikeview.classical.noise import choose_demosaic, haar_noise_variance
from spikeview.classical.tfi import tfi
from spikeview.classical.tfp import counts_to_sfr, tfp, window_counts
from spikeview.classical.windows import window_range
from spikeview.io.source import SpikeSource

def resolve_alpha(source: SpikeSource, config: ClassicalConfig, alpha: np.ndarray | list[float] | None = None) -> np.ndarray | None:
    """The α a reconstruction of ``source`` uses: ``alpha`` if given, else ``config.alpha``, else the
    gray-world estimate (:func:`~spikeview.classical.colour_cast.sequence_alpha`, the rule of
    :func:`spikeview.pipeline.prepare_sequence`). ``None`` when no colour correction applies (monochrome stream or
    ``config.colour_cast`` off)."""
    if source.cfa is None or not config.colour_cast:
        return None
    if alpha is None:
        alpha = sequence_alpha(source, config)[0]  # config.alpha, else the estimate: pipeline.prepare_sequence's rule
    return colour_gains(alpha, 1.0, 3)


def reconstruct_frame(source: SpikeSource, center: int, config: ClassicalConfig | None = None,
                      alpha: np.ndarray | list[float] | None = None) -> np.ndarray:
    """One classical frame at tick ``center``.

    TFP (window from :func:`window_range`) or TFI per photosite; then, for a Bayer stream, the
    colour cast is undone on the mosaic (``Y_c · α_c / η``) and the mosaic is demosaicked.

    Args:
        source: the spike stream (flips applied; ``source.cfa`` names the CFA).
        center: centre tick, ``0 <= center < n_frames``.
        config: settings (defaults: 10-tick TFP, bilinear, colour cast on, η = 2).
        alpha: gray-world gains ``(3,)`` to use instead of ``config.alpha`` / an estimate. Pass the
            same α for every frame of a sequence (see :func:`reconstruct_frames`); leaving it and
            ``config.alpha`` unset estimates it from ``source`` on every call.

    Returns:
        float32 ``(H, W, 3)`` RGB for a Bayer stream, ``(H, W)`` for monochrome; in ``[0, 1]``
        when ``config.clip`` (default).
    """
    config = config if config is not None else ClassicalConfig()
    return _reconstruct(source, center, config, resolve_alpha(source, config, alpha))


def _reconstruct(source: SpikeSource, center: int, config: ClassicalConfig, alpha: np.ndarray | None) -> np.ndarray:
    if config.method == "tfp":
        y = tfp(source, center, config.window)
    else:
        y = tfi(source, center, config.tfi_half_window)
    return finish_frame(source, y, config, alpha)


def finish_frame(source: SpikeSource, y: np.ndarray, config: ClassicalConfig, alpha: np.ndarray | None) -> np.ndarray:
    """A TFP or TFI rate mosaic of ``source`` as its frame: the camera profile's correction, the colour cast, the
    demosaic (``auto``: decided on the corrected mosaic) and the clip of ``config`` — the CLI's frames, and the app's
    previews where a profile (or the capture's own dark rate and hot photosites) corrects the rates."""
    y = correct_rates(source, y)  # the camera profile's dark, flat and hot-pixel correction (none without one)
    if source.cfa is not None:
        if alpha is not None:
            y = apply_colour_cast_mosaic(y, source.cfa, alpha, config.eta)
        y = demosaic(y, source.cfa, auto_demosaic(y, source.cfa, config.demosaic)[0])
    if config.clip:
        np.clip(y, 0.0, 1.0, out=y)
    return y


def auto_demosaic(mosaic: np.ndarray, cfa: str, requested: str = "auto") -> tuple[str, str]:
    """The demosaic of a TFP/TFI output (not denoised afterwards) and the reason.

    ``requested`` other than ``"auto"`` is used as set. ``"auto"`` measures the noise of the
    (colour-corrected) mosaic — the largest per-Bayer-plane σ of the trimmed finest diagonal Haar
    detail (:func:`spikeview.classical.noise.haar_noise_variance`) — and picks bilinear where
    noise dominates, Malvar-2004 where the window is clean
    (:func:`spikeview.classical.noise.choose_demosaic`, the same rule as the guided plan's).
    """
    if requested != "auto":
        return requested, f"set by demosaic={requested}"
    var = [haar_noise_variance(mosaic[i::2, j::2]) for i in (0, 1) for j in (0, 1)]
    sigma = max((float(np.sqrt(v)) for v in var if v is not None), default=0.0)
    return choose_demosaic(sigma, "auto", denoised=False, shape=mosaic.shape[-2:])


def reconstruct_frames(source: SpikeSource, centers: Iterable[int], config: ClassicalConfig | None = None,
                       alpha: np.ndarray | list[float] | None = None) -> Iterator[np.ndarray]:
    """Frames at each tick of ``centers``, with one α for the whole sequence.

    α is resolved once, before the first frame (``alpha``, ``config.alpha`` or one
    :func:`estimate_alpha` over the whole stream), so colours do not drift between frames.

    Yields:
        the frames of :func:`reconstruct_frame`, in the order of ``centers``.
    """
    config = config if config is not None else ClassicalConfig()
    a = resolve_alpha(source, config, alpha)
    for c in centers:
        yield _reconstruct(source, c, config, a)


# --- live preview -------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True, inline="always")
def _g_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, xm, xp):  # type: ignore[no-untyped-def]  # pragma: no cover
    # green photosite: own value, colour ci from the row neighbours, vi from the column neighbours
    o[x, 1] = lg[4 * np.int64(row[x])]
    o[x, ci] = lc[2 * (np.int64(row[xm]) + np.int64(row[xp]))]
    o[x, vi] = lv[2 * (np.int64(rowm[x]) + np.int64(rowp[x]))]


@numba.njit(cache=True, nogil=True, inline="always")
def _c_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, xm, xp):  # type: ignore[no-untyped-def]  # pragma: no cover
    # red/blue photosite ci: own value, green from the 4 edge neighbours, vi from the 4 diagonals
    o[x, ci] = lc[4 * np.int64(row[x])]
    o[x, 1] = lg[np.int64(rowm[x]) + np.int64(rowp[x]) + np.int64(row[xm]) + np.int64(row[xp])]
    o[x, vi] = lv[np.int64(rowm[xm]) + np.int64(rowm[xp]) + np.int64(rowp[xm]) + np.int64(rowp[xp])]


@numba.njit(cache=True, nogil=True, inline="always")
def _lut_row(o, row, rowm, rowp, w, g_even, lg, lc, lv, ci, vi):  # type: ignore[no-untyped-def]  # pragma: no cover
    # one output row; ci (the row's red/blue) and vi (the other one) are literals after inlining
    for x in (0, w - 1):
        xm = x - 1 if x > 0 else 1  # mirror about the edge pixel
        xp = x + 1 if x < w - 1 else w - 2
        if ((x & 1) == 0) == g_even:
            _g_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, xm, xp)
        else:
            _c_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, xm, xp)
    # interior, two photosites per step so that the site type is fixed in the loop: a green first
    # photosite is done on its own, and the rest of the row starts at a colour site
    x = 1
    if not g_even and x < w - 1:
        _g_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, x - 1, x + 1)
        x = 2
    while x + 1 < w - 1:
        _c_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, x - 1, x + 1)
        _g_site(o, x + 1, lg, lc, lv, ci, vi, row, rowm, rowp, x, x + 2)
        x += 2
    if x < w - 1:
        _c_site(o, x, lg, lc, lv, ci, vi, row, rowm, rowp, x - 1, x + 1)


@numba.njit(cache=True, nogil=True)
def _bilinear_lut_kernel(cnt: np.ndarray, quad: np.ndarray, luts: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Bilinear demosaic of integer counts fused with per-channel display tables.

    Bilinear estimates of counts are multiples of 1/4, so ``4 ×`` the estimate is an integer
    ``k`` in ``[0, 4Δτ]`` and ``luts[c, k]`` is the display code of channel ``c``. Mirror edges
    (neighbour -1 is pixel 1, neighbour W is pixel W-2). Needs H, W >= 2.
    """
    h, w = cnt.shape
    lg = luts[1]
    for y in range(h):
        ym = y - 1 if y > 0 else 1
        yp = y + 1 if y < h - 1 else h - 2
        g_even = quad[y & 1, 0] == 1  # green at even columns of this row
        ci = quad[y & 1, 1] if g_even else quad[y & 1, 0]  # the row's other colour
        # literal channel indices let the compiler fold the output offsets (about 2x faster)
        if ci == 0:
            _lut_row(out[y], cnt[y], cnt[ym], cnt[yp], w, g_even, lg, luts[0], luts[2], 0, 2)
        else:
            _lut_row(out[y], cnt[y], cnt[ym], cnt[yp], w, g_even, lg, luts[2], luts[0], 2, 0)


def mosaic_display(mosaic: np.ndarray, cfa: str | None, *, alpha: np.ndarray | list[float] | None = None,
                   eta: float = DEFAULT_ETA, demosaic_method: str = "auto", black: float = 0.0, white: float = 1.0,
                   gamma: Gamma = "srgb") -> np.ndarray:
    """A mosaicked rate frame (a TFP or TFI SFR) as display RGB, uint8 ``(H, W, 3)``: the colour cast on
    the mosaic (with ``alpha``; ``None`` = none), the demosaic (``"auto"``: :func:`auto_demosaic`) and
    the fixed display levels (:func:`~spikeview.classical.display.to_display`). Monochrome frames get
    the levels only, repeated into three channels."""
    if cfa is None:
        return np.repeat(to_display(mosaic, black, white, gamma)[..., None], 3, axis=-1)
    method = auto_demosaic(mosaic, cfa, demosaic_method)[0]
    if alpha is not None:
        mosaic = apply_colour_cast_mosaic(mosaic, cfa, alpha, eta)
    return to_display(demosaic(mosaic, cfa, method), black, white, gamma)


def preview_rgb(source: SpikeSource, center: int, window: int = 32, *, alpha: np.ndarray | list[float] | None = None,
                colour_cast: bool = True, eta: float = DEFAULT_ETA, demosaic_method: str = "bilinear",
                black: float = 0.0, white: float = 1.0, gamma: Gamma = "srgb") -> np.ndarray:
    """8-bit RGB preview of the TFP window around tick ``center``: the GUI's fast path.

    Counts the window with ``source.count`` (packed bits for file sources), undoes the colour
    cast, demosaics and applies the display curve with fixed levels. For the default bilinear
    method the last three steps are one table-driven pass over the counts (a few ms at
    1000×1000); its codes are within one code value of ``to_display(reconstruct_frame(…))`` with
    ``clip`` off (exactly the display curve of the true values, without the float32 rounding and
    the 65,536-entry table of :func:`to_display`).

    Args:
        source: the spike stream.
        center: centre tick (window from :func:`window_range`: centred, shifted at the edges).
        window: Δτ in ticks.
        alpha: gray-world gains ``(3,)``: estimate them once per sequence with
            :func:`estimate_alpha` and pass them in; ``None`` estimates them on every call (slow).
        colour_cast: apply ``α_c / η`` (Bayer streams only); when off, the SFR is shown as is.
        eta: range parameter η.
        demosaic_method: a :data:`DEMOSAIC_METHODS` name.
        black, white, gamma: fixed display levels and curve (see :func:`to_display`).

    Returns:
        ``(H, W, 3)`` uint8 (a monochrome stream is repeated over the three channels).
    """
    black, white = _check_levels(black, white)
    gamma = _check_gamma(gamma)
    method = check_method(demosaic_method)
    a, b = window_range(center, window, source.n_frames)
    dt = b - a
    counts = window_counts(source, a, b)
    cfa = source.cfa
    if cfa is None:  # no colour cast for monochrome, as in reconstruct_frame
        lut = encode8(transfer(np.arange(dt + 1) / dt, black, white, gamma))
        return np.repeat(lut[counts][..., None], 3, axis=-1)
    if colour_cast:
        if alpha is None:
            alpha = sequence_alpha(source, ClassicalConfig())[0]
        gains = colour_gains(alpha, eta, 3).astype(np.float64)
    else:
        gains = np.ones(3)
    if method == "bilinear" and min(counts.shape) >= 2:
        levels = np.arange(4 * dt + 1, dtype=np.float64) / (4 * dt)
        luts = encode8(transfer(levels[None, :] * gains[:, None], black, white, gamma))
        out = np.empty(counts.shape + (3,), dtype=np.uint8)
        _bilinear_lut_kernel(np.ascontiguousarray(counts), quad_codes(cfa), luts, out)
        return out
    y = apply_colour_cast_mosaic(counts_to_sfr(counts, dt), cfa, gains, 1.0)
    return to_display(demosaic(y, cfa, method), black, white, gamma)


__all__ = [
    "CLASSICAL_METHODS",
    "DEMOSAIC_METHODS",
    "ClassicalConfig",
    "preview_rgb",
    "reconstruct_frame",
    "reconstruct_frames",
    "resolve_alpha",
]
