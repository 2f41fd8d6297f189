"""What the guided sampler sees of one window: the mosaicked TFP, the CFA, Δτ and the colour cast.

An :class:`Observation` is built from a :class:`~spikeview.io.source.SpikeSource` and a centre
tick (:meth:`Observation.from_source`) or from a TFP array directly. It carries

* ``y``: the ``(H, W)`` float32 mosaicked SFR (TFP, ``count / Δτ`` in ``{0, 1/Δτ, …, 1}``),
* ``cfa``: the Bayer pattern of ``y``'s top-left 2×2 (``None`` = monochrome),
* ``window``: Δτ in ticks, and ``ticks = (a, b)``, the ticks ``[a, b)`` that were counted,
* ``alpha``: the sequence's gray-world gains ``(3,)`` (``None`` for monochrome), estimated **once
  per sequence** by :func:`spikeview.classical.colour_cast.estimate_alpha` unless given,
* ``eta``: the range parameter; the corrected estimate is ``Y · α / η``.

The noise of ``y`` (:meth:`Observation.variance`) uses the binomial TFP model of
:mod:`spikeview.ops.noise`, **scaled to the data** and evaluated at the local mean rate (:meth:`Observation.local_rate`): an integrate-and-fire pixel with a random phase
fires ``floor(pΔτ + U)`` times, whose variance is far below the binomial one, while sensor noise
(shot noise, jitter, fixed pattern) moves it back up. The scale ``κ_c`` per channel is the ratio
of a robust noise estimate from the frame itself (trimmed mean square of the finest diagonal
Haar detail of each Bayer plane, :func:`haar_noise_variance`) to the model's mean variance, clipped to
``[1e-4, 4]`` (a frame without any noise, e.g. saturated, gets almost none). So the noise level handed to the prior is derived from the data, not set by hand.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spikeview.cfa import channel_map, parse_cfa
from spikeview.classical.noise import haar_noise_variance
from spikeview.classical.tfp import counts_to_sfr, window_counts
from spikeview.classical.windows import window_range
from spikeview.errors import ParameterError
from spikeview.io.source import SpikeSource

#: where the sequence's white point sits in what the prior and the data term see (headroom above it
#: keeps the brightest 0.1 % of values out of the [0, 1] clamp); chosen on the benchmark's tuning scenes
EXPOSURE_LEVEL = 0.9


def exposed_eta(eta: float, white: float, level: float = EXPOSURE_LEVEL) -> float:
    """The range parameter that maps the sequence's white point to ``level``.

    ``white`` is in the units of the linear frame ``Y·α/η`` (see
    :func:`spikeview.classical.colour_cast.estimate_white`); the exposed estimate ``Y·α/η'`` with
    ``η' = η·white/level`` has its white point at ``level``. Gray-world α keeps the channel ratios;
    this only sets the exposure, once per sequence.

    Raises:
        ParameterError: a non-positive or non-finite ``eta``, ``white`` or ``level``.
    """
    for name, v in (("eta", eta), ("white", white), ("level", level)):
        if not (np.isfinite(v) and v > 0):
            raise ParameterError(f"{name} = {v!r} must be a positive finite number (white: the sequence's white point, e.g. from estimate_white).")
    return float(eta) * float(white) / float(level)


#: clip range of the data-derived scale of the binomial variance model
KAPPA_RANGE = (1e-4, 4.0)
#: pseudo-count of the binomial model (Jeffreys), see :func:`spikeview.ops.noise.tfp_variance`
PRIOR_COUNT = 0.5


def binomial_variance(y: np.ndarray, window: "int | np.ndarray", prior: float = PRIOR_COUNT) -> np.ndarray:
    """:func:`spikeview.ops.noise.tfp_variance` on a numpy array (float32, shape of ``y``); ``window``
    may be a per-photosite array of effective windows (a pooled observation's ``dtau``)."""
    import torch

    if isinstance(window, np.ndarray):
        n = window.astype(np.float64)
        p = (np.clip(y, 0.0, 1.0) * n + prior) / (n + 2 * prior)
        return (p * (1.0 - p) / n).astype(np.float32)

    from spikeview.ops.noise import tfp_variance

    return tfp_variance(torch.from_numpy(np.ascontiguousarray(y, dtype=np.float32)), window, prior).numpy()


def _bayer_planes(y: np.ndarray) -> list[tuple[slice, slice]]:
    return [(slice(i, None, 2), slice(j, None, 2)) for i in (0, 1) for j in (0, 1)]


#: spikes per photosite per window: a capture's darkest floor below this is black (no dark rate in its rates), and a
#: pooled observation's Q models its pooled count (:meth:`Observation.quantise_window`); a quarter of Q's own floor
#: (0.12 of a level at k = 20). Simulated scenes without a dark current: 0.002–0.015 a 10-tick window; the simulator's
#: dark rate: 0.05
PEDESTAL_COUNT = 0.03


@dataclass
class Observation:
    """One TFP window of a stream, with everything the forward model needs (see module docstring).

    Attributes:
        y: ``(H, W)`` float32 mosaicked SFR in [0, 1].
        cfa: Bayer pattern (top-left 2×2 after flips) or ``None`` for monochrome.
        window: Δτ in ticks.
        alpha: ``(3,)`` float gray-world gains of the sequence, or ``None`` (monochrome, or no C).
        eta: range parameter η > 0 (corrected estimate ``Y·α/η``).
        ticks: ``(a, b)``: the ticks ``[a, b)`` counted (``None`` when built from an array).
        center: the centre tick asked for (``None`` when built from an array).
        previous: the observation of the window before (same size), for the plan's reuse test.
        dtau: ``(H, W)`` float32 effective window per photosite in ticks when neighbouring windows
            were pooled (:mod:`spikeview.guided.temporal`; ``y`` is then pooled count / ``dtau``),
            ``None`` = ``window`` everywhere.
        pooling: what the temporal support pooled (:class:`spikeview.guided.temporal.Pooling`), or ``None``.
        own: the centre window alone (a pooled observation's reuse test compares own windows).
        corrected: what moved ``y`` off the TFP's 1/Δτ grid (a camera profile's dark rate and flat field:
            :func:`spikeview.classical.calibration.correct_observation`), or ``None``; the plan's Q rule reads it.
        floor: the capture's darkest floor in spikes per tick where it may be a dark rate left in the rates
            (:attr:`spikeview.classical.defects.Defects.pedestal`: 0 on a colour capture without a cast, whose floor
            is light); :meth:`quantise_window` reads it.
    """

    y: np.ndarray
    cfa: str | None
    window: int
    alpha: np.ndarray | None = None
    eta: float = 2.0
    ticks: tuple[int, int] | None = None
    center: int | None = None
    previous: "Observation | None" = field(default=None, repr=False)
    dtau: np.ndarray | None = field(default=None, repr=False)
    pooling: Any = field(default=None, repr=False)
    own: "Observation | None" = field(default=None, repr=False)
    corrected: str | None = None
    floor: float = 0.0

    def __post_init__(self) -> None:
        y = np.asarray(self.y)
        if y.ndim != 2:
            raise ParameterError(f"Observation.y must be an (H, W) mosaicked TFP frame, got shape {y.shape}.")
        if y.shape[0] < 2 or y.shape[1] < 2:
            raise ParameterError(f"Observation.y of shape {y.shape} is too small: frames need at least 2x2 pixels.")
        self.y = np.clip(np.nan_to_num(y.astype(np.float32, copy=False), nan=0.0), -1.0 if self.corrected else 0.0, 1.0)
        self.cfa = parse_cfa(self.cfa)
        if isinstance(self.window, bool) or not isinstance(self.window, (int, np.integer)) or self.window < 1:
            raise ParameterError(f"window = {self.window!r} must be a whole number of ticks >= 1.")
        self.window = int(self.window)
        if not (np.isfinite(self.eta) and self.eta > 0):
            raise ParameterError(f"eta = {self.eta!r} must be a positive finite number (e.g. 2.0).")
        if self.alpha is not None:
            a = np.asarray(self.alpha, dtype=np.float64).reshape(-1)
            if self.cfa is None or a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
                if self.cfa is None:
                    a = None  # monochrome: no cast
                else:
                    raise ParameterError(f"alpha must be three finite positive gains [R, G, B], got {self.alpha!r}.")
            self.alpha = a
        if self.dtau is not None:
            d = np.asarray(self.dtau, dtype=np.float32)
            if d.shape != self.y.shape or not np.all(d >= self.window):
                raise ParameterError(f"Observation.dtau must be an {self.y.shape} map of effective windows >= window ({self.window} ticks).")
            self.dtau = d

    # -------------------------------------------------------------------------- construction
    @classmethod
    def from_source(cls, source: SpikeSource, center: int, window: int, *, alpha: np.ndarray | list[float] | None = None,
                    eta: float, radius: int, previous: bool = False, cache: Any = None,
                    device: Any = None) -> "Observation":
        """The ``window``-tick TFP window around ``center`` (see :func:`~spikeview.classical.windows.window_range`).

        The settings come from the caller, never from defaults here (``guided.window``, ``guided.eta``,
        ``guided.temporal_radius`` have one home, the config): a front end plans its window with
        :func:`spikeview.pipeline.plan_window`, the guided sequence with :func:`spikeview.guided.window.observe_window`.

        Args:
            source: spike stream; its CFA names the mosaic.
            center: centre tick.
            window: Δτ in ticks.
            alpha: the sequence's gray-world gains (estimate them once per sequence with
                :func:`spikeview.classical.colour_cast.estimate_alpha`); ``None`` = no colour cast.
            eta: range parameter.
            previous: also read the window just before (for the plan's reuse test), when there is one.
            radius: pool the aligned neighbouring windows, up to ``radius`` on each side
                (:func:`spikeview.guided.temporal.pool_counts`); 0 = this window alone.
            cache: a :class:`spikeview.guided.temporal.WindowCache` shared by a sequence's frames.
            device: where the pooling's alignment runs (``guided.device``; ``None`` = the CPU).
        """
        a, b = window_range(center, window, source.n_frames)
        from spikeview.classical.defects import find_defects

        floor = find_defects(source).pedestal  # measured once per capture (cached on it)

        def count(x: int, y: int) -> np.ndarray:  # through the sequence's cache (and its lock) when there is one
            return window_counts(source, x, y) if cache is None else cache.counts(source, x, y)

        prev = None
        if previous and a - window >= 0:
            pa, pb = a - window, a
            prev = cls(counts_to_sfr(count(pa, pb), window), source.cfa, window, alpha, eta, (pa, pb), None)
        if radius:
            from spikeview.guided.temporal import pool_counts

            dev = None
            if device is not None and str(device) != "cpu":
                from spikeview.guided.device import resolve_device

                dev = resolve_device(device)
            counts, pool = pool_counts(source, a, b, radius, parse_cfa(source.cfa), cache, device=dev)
            if pool.dtau is not None:
                own = cls(counts_to_sfr(count(a, b), b - a), source.cfa, b - a, alpha, eta, (a, b), int(center))
                y = counts / pool.dtau
                if pool.support is not None:  # at rest: the rate from the intervals between spikes (interval_rates)
                    from spikeview.guided.temporal import interval_rates

                    # photosites that pooled every neighbouring window at rest (the whole ±radius, or more)
                    yi = interval_rates(source, pool.support, parse_cfa(source.cfa), y,
                                        min_ticks=(b - a) * (1 + len(pool.offsets)))
                    took = np.isfinite(yi)
                    y = np.where(took, yi, y)
                    pool.interval_share = float(took.mean())
                    if took.any():  # the plan's temporal row says it
                        pool.reason += (f"; the rate of {100 * float(took.mean()):.0f}% of photosites (pooled at rest) from "
                                        "the intervals between their spikes")
                return cls(y, source.cfa, b - a, alpha, eta, (a, b), int(center), prev, pool.dtau, pool, own, floor=floor)
            return cls(counts / float(b - a), source.cfa, b - a, alpha, eta, (a, b), int(center), prev, None, pool,
                       floor=floor)
        from spikeview.guided.temporal import Pooling, neighbour_offsets

        y = counts_to_sfr(count(a, b), b - a)
        pool = Pooling(0, b - a, neighbour_offsets(a, b, int(source.n_frames), 1), kind="off",
                       reason="off (temporal_radius = 0): the window alone, as in the paper")
        return cls(y, source.cfa, b - a, alpha, eta, (a, b), int(center), prev, None, pool, floor=floor)

    # ------------------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.y.shape[0]), int(self.y.shape[1]))

    @property
    def effective_window(self) -> "int | np.ndarray":
        """Δτ per photosite: ``dtau`` of a pooled observation, else ``window``."""
        return self.window if self.dtau is None else self.dtau

    def mean_count(self) -> float:
        """Mean spikes per photosite over its (effective) window."""
        return float((self.y * self.effective_window).mean())

    def window_count(self) -> float:
        """Mean spikes per photosite per ``window``-tick window: the (pooled) rate × Δτ (equals
        :meth:`mean_count` without pooling)."""
        return float(self.y.mean()) * self.window

    def quantise_window(self) -> int:
        """The ticks whose count Q models: ``window``, or for a pooled observation without a dark rate in its rates its
        mean Δτ_eff (the aligned windows' spikes summed, so its values step by 1/Δτ_eff; Q rounds to that grid).

        On the own window's 1/Δτ grid Q's soft floor (Q(0) ≈ 0.12/Δτ) crushes a rate of a fraction of one spike a
        window to black. Where the capture's darkest patches are black (:attr:`floor` × Δτ under
        :data:`PEDESTAL_COUNT`) that floor ate the least sensitive channel's pooled rate: dark colourful scenes without a
        dark current lost their blue and 8–20 dB (``benchmarks/results/colour.md``, section 8). Where a dark rate is left
        in the rates (no profile subtracted it), the same floor takes it off, and the per-window grid stays (without
        it the bench's coffee sequences lost 0.05–0.17 SSIM, coins_rgb 3° of white balance). Monochrome alike: its
        darkest floor tells black from a pedestal as well (a dark chelsea without a dark current, 0.03 spikes per tick,
        had a third of its photosites at 0 and 19.3 dB; 28.8 dB on the pooled grid), while the real dark capture
        (floor 0.16 a window) and the simulated ones with a dark current (0.07) keep the per-window floor, which takes
        their dark rate off (they lost 0.02 detail and 4 dB without it)."""
        if self.dtau is None or not self._counts_pooled():
            return int(self.window)
        return max(int(self.window), int(round(float(np.mean(self.dtau)))))

    def quantise_count(self) -> float:
        """The count the plan compares with its Q threshold: spikes per photosite over :meth:`quantise_window` ticks
        (the pooled count, or per ``window``-tick window)."""
        return self.mean_count() if (self.dtau is not None and self._counts_pooled()) else self.window_count()

    def _counts_pooled(self) -> bool:
        """Q models the pooled count (:meth:`quantise_window`): an observation whose darkest floor is black."""
        return self.floor * self.window < PEDESTAL_COUNT

    def crop(self, y0: int, y1: int, x0: int, x1: int) -> "Observation":
        """The observation on the photosites ``[y0:y1, x0:x1]`` (``previous`` and ``own`` not kept)."""
        d = None if self.dtau is None else self.dtau[y0:y1, x0:x1]
        pool = None if self.pooling is None else self.pooling.crop(y0, y1, x0, x1)
        return Observation(self.y[y0:y1, x0:x1], self.cfa, self.window, self.alpha, self.eta, self.ticks, self.center,
                           None, d, pool, corrected=self.corrected, floor=self.floor)

    @property
    def channels(self) -> int:
        """3 for a Bayer CFA, 1 for monochrome."""
        return 1 if self.cfa is None else 3

    def channel_map(self) -> np.ndarray:
        """``(H, W)`` int channel index of every photosite (zeros for monochrome)."""
        if self.cfa is None:
            return np.zeros(self.shape, dtype=np.int8)
        return channel_map(self.cfa, *self.shape)

    def gains(self) -> np.ndarray:
        """Sensor-side gain per channel, ``η / α_c`` (ones when there is no cast)."""
        if self.alpha is None:
            return np.ones(self.channels)
        return self.eta / self.alpha

    # --------------------------------------------------------------------------------- noise
    def noise_scale(self) -> np.ndarray:
        """Data-derived scale κ_c of the binomial variance per channel (see module docstring).

        Returns:
            ``(channels,)`` float64 in :data:`KAPPA_RANGE`; 1 where a channel's planes are too small
            or flat (no estimate).
        """
        model = binomial_variance(self.local_rate(), self.effective_window)
        cmap = self.channel_map()
        est: dict[int, list[float]] = {c: [] for c in range(self.channels)}
        mod: dict[int, list[float]] = {c: [] for c in range(self.channels)}
        planes = _bayer_planes(self.y) if self.cfa is not None else [(slice(None), slice(None))]
        for sl in planes:
            v = haar_noise_variance(self.y[sl])
            if v is None:
                continue
            c = int(cmap[sl][0, 0])
            est[c].append(v)
            mod[c].append(float(model[sl].mean()))
        out = np.ones(self.channels)
        for c in range(self.channels):
            if est[c] and np.mean(mod[c]) > 0:
                out[c] = np.clip(np.mean(est[c]) / np.mean(mod[c]), *KAPPA_RANGE)
        return out

    def local_rate(self) -> np.ndarray:
        """``(H, W)`` float32 rate the noise model is evaluated at: the mean of ``y`` over the 3×3
        neighbourhood of each photosite **in its own Bayer plane** (the whole frame for monochrome).

        The binomial variance of a photosite depends on its true rate, not on its own noisy count:
        plugging the count in gives a zero-count photosite almost no variance, so the data term
        trusted noisy zeros and sparse single spikes most. The local mean is a far better estimate
        of the rate (measured on the benchmark's tuning scenes, 128×128: +0.34 dB mean PSNR of the
        default sampler, +1.1 dB on the highlights scene, +0.6 dB on the low-key scene, ±0.05 dB on
        the others).
        """
        from scipy.ndimage import uniform_filter

        y = self.y.astype(np.float32)
        if self.cfa is None:
            return uniform_filter(y, size=3, mode="reflect")
        out = np.empty_like(y)
        for sl in _bayer_planes(y):
            out[sl] = uniform_filter(y[sl], size=3, mode="reflect")
        return out

    def variance(self) -> np.ndarray:
        """``(H, W)`` float32 per-photosite variance of ``y`` (SFR² units): κ_c × the binomial model
        at the :meth:`local_rate` (computed once per observation: the plan, the start estimate and the data
        term all read it; do not write into it)."""
        return self._memo("variance", self._variance)

    def _variance(self) -> np.ndarray:
        kappa = self.noise_scale()
        return (binomial_variance(self.local_rate(), self.effective_window) * kappa[self.channel_map()]).astype(np.float32)

    def _memo(self, name: str, make: Any, *args: Any) -> Any:
        """``make(*args)`` once per observation and its inputs (``y``, the windows, α, η, κ's class): a value
        derived from the window, kept out of the dataclass fields (a crop or a copy starts without it); callers
        treat it as read-only (torch.from_numpy shares it, so it is not flagged read-only)."""
        key = (name, args, id(self.y), id(self.dtau), self.window, self.eta, type(self).noise_scale,
               None if self.alpha is None else tuple(np.asarray(self.alpha, dtype=np.float64).ravel().tolist()))
        memo = self.__dict__.setdefault("_memo_cache", {})
        if key not in memo:
            memo[key] = make(*args)
        return memo[key]


def start_variance(obs: Observation, use_mosaic: bool = True, use_cast: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(var, gain)``: the per-pixel variance of the bilinear-demosaicked TFP estimate Y₀ before the
    colour correction, ``(C, H, W)`` float32 (``C`` = 3, or 1 for monochrome / ``use_mosaic=False``), and
    the correction gains α_c/η ``(C,)`` (ones without a cast): σ² of a pixel of Y₀ is ``var · gain²``.

    Propagates :meth:`Observation.variance` (binomial model scaled to the data) through bilinear
    demosaicking (:func:`spikeview.ops.noise.demosaic_variance`). :func:`estimate_sigma` averages it over
    the frame, the per-tile plan (:func:`spikeview.guided.tiles.plan_tiles`) over each tile.
    """
    from spikeview.errors import check_cancelled

    check_cancelled("while planning")
    return obs._memo("start_variance", lambda m, c: _start_variance(obs, m, c), bool(use_mosaic), bool(use_cast))


def _start_variance(obs: Observation, use_mosaic: bool, use_cast: bool) -> tuple[np.ndarray, np.ndarray]:
    import torch

    from spikeview.ops.noise import demosaic_variance

    var = obs.variance()
    if obs.cfa is None or not use_mosaic:
        return var[None], np.ones(1)
    v = demosaic_variance(torch.from_numpy(var)[None, None], obs.cfa)[0].numpy()
    gain = (obs.alpha / obs.eta) if (use_cast and obs.alpha is not None) else np.ones(3)
    return v, np.asarray(gain, dtype=np.float64)


#: blocks (pixels) over which :func:`worst_block_sigma` looks for noise the frame's mean hides
NOISE_BLOCK = 32


def worst_block_sigma(var: np.ndarray, gain: np.ndarray, block: int = NOISE_BLOCK) -> float:
    """The largest σ over :data:`NOISE_BLOCK`-pixel blocks (RMS over each block of a :func:`start_variance` map,
    times the gains, the worst channel): a region that pooled less stays noisy where the frame's mean is quiet."""
    c, h, w = var.shape
    bh, bw = -(-h // block), -(-w // block)
    pad = np.zeros((c, bh * block, bw * block), np.float64)
    cnt = np.zeros((bh * block, bw * block), np.float64)
    pad[:, :h, :w] = var
    cnt[:h, :w] = 1.0
    sums = pad.reshape(c, bh, block, bw, block).sum(axis=(2, 4))
    n = cnt.reshape(bh, block, bw, block).sum(axis=(1, 3))
    sig = np.sqrt(sums / np.maximum(n, 1.0)) * np.asarray(gain, dtype=np.float64).reshape(-1, 1, 1)
    return float(sig.max())


def sigma_of(var: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Per-channel σ (float64, ``(C,)``) of a :func:`start_variance` map: the RMS over its pixels × gain."""
    if var.shape[0] == 1:
        return np.array([math.sqrt(float(var[0].mean()))]) * gain
    return np.sqrt(var.reshape(var.shape[0], -1).mean(axis=1)) * gain


def estimate_sigma(obs: Observation, use_mosaic: bool = True, use_cast: bool = True) -> np.ndarray:
    """Per-channel noise σ of the bilinear-demosaicked, colour-corrected TFP estimate Y₀: the RMS over
    pixels of :func:`start_variance` times the correction gains α_c/η. Monochrome (or
    ``use_mosaic=False``): RMS of the photosite σ.

    Returns:
        ``(3,)`` (or ``(1,)``) float64 σ in [0, 1] image units.
    """
    return sigma_of(*start_variance(obs, use_mosaic, use_cast))
