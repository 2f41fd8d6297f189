"""The scene plan: which stages a window needs, decided from the data before sampling, with reasons.

:func:`make_plan` looks at one :class:`~spikeview.guided.observation.Observation` and the
:class:`~spikeview.guided.config.GuidedConfig` and returns a :class:`Plan`. Every choice carries a
one-line reason and every one can be overridden by the config (the reason then says so):

============  ==========================================================================  ==================
choice        rule                                                                        override
============  ==========================================================================  ==================
mosaic (M)    on for a Bayer CFA, off for a monochrome stream (nothing to demosaic)        ``use_mosaic``
cast (C)      off when the gains η/α_c are all within ``cast_tolerance`` of 1 (C would      ``use_cast``
              change nothing; gains neutral in colour but not 1 set the exposure: on);
              on otherwise; off without M
levels        ``levels``, capped at what the frame size allows (each level halves the        ``levels_cap``
              size; the coarsest band keeps at least 1 pixel)
diffusion     skipped when the data-derived noise σ of the corrected TFP estimate is at    ``diffusion``
              or below ``noise_target`` (bright or long windows: TFP already meets the
              target); then ``fallback`` is ``"tfp"`` when σ <= noise_target / 4, else
              the one-pass ``"baseline"``
quantise (Q)  DPS: on; HQS: on at low rates (mean spikes per photosite per window below   ``quantise``
              ``Q_COUNT`` = 1.1: small integer counts, where Q gains), off above; a
              pooled observation counts per Δτ-tick window (its rate × Δτ: the pooled
              value is the mean of its windows' TFP values, each on Q's 1/Δτ grid); off
              when a camera profile's dark rate or flat field moved the rates off that grid
demosaic      ``auto``: Malvar-2004 for an estimate the prior denoises (diffusion start,  ``demosaic``
              one-pass input) unless counts are sparse (< ``SPARSE_COUNT`` = 0.3 spikes per
              photosite per window: bilinear); the TFP fallback: bilinear where the noise
              σ exceeds ``DEMOSAIC_CLEAN_SIGMA`` (8/255), Malvar-2004 where it is clean;
              ``none`` without M (monochrome: no mosaic, no demosaic, no cast)
reuse         the previous window's result is reused when the counts of this window and   ``reuse``
              the previous one agree within their noise (χ² test at level
              ``reuse_alpha``); ``changed`` marks the 16×16 blocks that did change
temporal      what the observation pooled from its aligned neighbouring windows, per      ``temporal_radius``
              photosite (:mod:`spikeview.guided.temporal`: static, aligned, mixed, fast
              motion), or why it could not (capture too short)
balance       with gray-world gains and Q on, or a camera profile's corrected rates and its  ``balance`` (set
              gains, the finished frame's channel means kept at the data's                  by the pipeline)
              (:mod:`spikeview.guided.balance`)
chroma        the finished colour frame's chroma smoothed over ``chroma`` pixels, guided     ``chroma``
              by its luma (:mod:`spikeview.guided.chroma`); none for a gray frame
precision     the prior's arithmetic: ``auto`` = the fastest path within 0.1 dB / 0.005    ``precision``
              SSIM of float32 on the bench for this CPU's features (bfloat16 on high-noise
              steps, NNPACK float32, or oneDNN float32: :mod:`spikeview.guided.precision`)
============  ==========================================================================  ==================

``str(plan)`` prints the decisions and their reasons, one per line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtri  # chi2.ppf(1 - a, k) = chdtri(k, a), without importing scipy.stats (0.3 s)

from spikeview.classical.noise import choose_demosaic
from spikeview.errors import ParameterError
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import NOISE_BLOCK, Observation, sigma_of, start_variance, worst_block_sigma
from spikeview.ops.pyramid import max_levels

#: block size (pixels) of the region-level change test
BLOCK = 16


@dataclass
class Plan:
    """What the guided reconstruction of one window will do, and why.

    Attributes:
        mosaic: use M (a Bayer CFA and a 3-channel prior); False = reconstruct a gray frame.
        cast: use C in the forward model (and correct the start estimate by it).
        levels: pyramid levels actually used (band-pass levels; 0 = plain residual).
        diffusion: run the sampler; False = return ``fallback``.
        fallback: ``"baseline"`` or ``"tfp"``: what a window without diffusion gets.
        reuse: the previous result can be returned unchanged (the window did not change).
        changed: ``(ceil(H/16), ceil(W/16))`` bool map of blocks whose counts changed, or ``None``
            when there is no previous window.
        sigma: per-channel data-derived noise level of the corrected TFP estimate (fraction of 1).
        reasons: one sentence per choice, keyed by the attribute name.
        demosaic: the demosaic of the start estimate / TFP fallback; ``"none"`` without M.
        precision: the prior's arithmetic (``guided.precision`` resolved for this CPU or GPU; ``""`` for
            the sd prior, which runs in ``guided.dtype``).
        tile_map: the per-tile plan (:class:`spikeview.guided.tiles.TileMap`) when ``guided.tile``
            splits the frame, else ``None``.
    """

    mosaic: bool
    cast: bool
    levels: int
    diffusion: bool
    fallback: str
    reuse: bool
    changed: np.ndarray | None
    sigma: np.ndarray
    reasons: dict[str, str] = field(default_factory=dict)
    quantise: bool = False
    demosaic: str = "malvar2004"
    temporal: str = "off"
    precision: str = ""
    pooling: object = field(default=None, repr=False)
    #: where the window runs (``"cpu"``, ``"cuda:0"``: ``guided.device`` resolved)
    device: str = "cpu"
    tile_map: object = field(default=None, repr=False)
    #: how much darker than :data:`WHITE_REF` the image the sampler sees is (≥ 1): noise is judged × this
    exposure: float = 1.0
    #: the σ the diffusion rule compared with ``noise_target``: the worst block's (or the frame's) × ``exposure``
    judged_sigma: float = 0.0
    #: σ in pixels of the chroma smoothing of the finished frame (0: none; :mod:`spikeview.guided.chroma`)
    chroma: float = 0.0
    #: the finished frame's channel means are kept at the data's (:mod:`spikeview.guided.balance`)
    balance: bool = False

    def __str__(self) -> str:
        sig = ", ".join(f"{255 * s:.1f}" for s in self.sigma)
        rel = ("" if self.exposure <= 1.0 else
               f"; {', '.join(f'{255 * s * self.exposure:.1f}' for s in self.sigma)} /255 of the frame's white, "
               "which the diffusion row judges at its noisiest block")
        lines = [f"plan (noise σ of the TFP estimate per channel: {sig} /255 of the image the sampler sees{rel}):"]
        values = {
            "mosaic": "on" if self.mosaic else "off",
            "cast": "on" if self.cast else "off",
            "quantise": "on" if self.quantise else "off",
            "demosaic": self.demosaic,
            "levels": str(self.levels),
            "diffusion": "on" if self.diffusion else f"off -> {self.fallback}",
            "reuse": "yes" if self.reuse else "no",
            "temporal": self.temporal,
            "balance": "kept" if self.balance else "-",
            "chroma": f"σ {self.chroma:g} px" if self.chroma > 0 else "off",
            "precision": self.precision or "-",
            "device": self.device,
            "tiles": "off" if self.tile_map is None else f"{len(self.tile_map.tiles)}",
        }
        for key, val in values.items():
            lines.append(f"  {key:<9} {val:<16} {self.reasons.get(key, '')}")
        return "\n".join(lines)


def _count_words(obs: Observation, count: float, per_window: bool = False) -> str:
    """``count`` in words that say what it counts: the window's own spikes, or, for a pooled observation,
    the spikes pooled from the aligned neighbouring windows (over Δτ_eff ticks, :meth:`Observation.mean_count`)
    or, ``per_window``, the pooled rate per Δτ-tick window (:meth:`Observation.window_count`), with the
    own window's count beside them."""
    if obs.dtau is None:
        return f"{count:.2f} spikes per photosite per window"
    own = f"; {obs.own.mean_count():.2f} in its own {obs.window}-tick window" if obs.own is not None else ""
    if per_window:
        return (f"{count:.2f} spikes per photosite per {obs.window}-tick window, the rate pooled over the aligned windows "
                f"(Δτ_eff {float(np.mean(obs.effective_window)):.0f} ticks{own})")
    return (f"{count:.2f} spikes per photosite pooled over the aligned windows "
            f"(Δτ_eff {float(np.mean(obs.effective_window)):.0f} ticks{own})")


#: HQS: mean spikes per photosite per window below which Q (soft quantisation) is switched on.
#: Chosen on the tuning scenes of the guided benchmark (256×256, k = 20): Q gained +0.02 to +0.16 dB
#: PSNR and +0.04 to +0.08 SSIM at 0.16–0.95 spikes, lost 0.22–0.34 dB at 1.3–2.1 spikes; the
#: threshold sits between (benchmarks/results/guided.md)
Q_COUNT = 1.1


def changed_blocks(obs: Observation, alpha: float = 1e-3) -> np.ndarray | None:
    """Blocks whose counts differ from the previous window by more than their noise.

    For every photosite ``d = y − y_prev`` has variance ``Var[y] + Var[y_prev]`` when nothing moved;
    per 16×16 block, ``Σ d² / (Var[y] + Var[y_prev])`` is compared with the ``1 − alpha`` quantile of
    χ² with as many degrees of freedom as photosites.

    Returns:
        ``(ceil(H/16), ceil(W/16))`` bool array (True = changed), or ``None`` without a previous window.
    """
    prev = obs.previous
    obs = obs.own if obs.own is not None else obs  # a pooled window: compare the own windows (independent counts)
    if prev is None or prev.y.shape != obs.y.shape:
        return None
    var = obs.variance() + prev.variance()
    z = (obs.y - prev.y) ** 2 / np.maximum(var, 1e-8)
    h, w = z.shape
    bh, bw = -(-h // BLOCK), -(-w // BLOCK)
    out = np.zeros((bh, bw), dtype=bool)
    for i in range(bh):
        for j in range(bw):
            blk = z[i * BLOCK:(i + 1) * BLOCK, j * BLOCK:(j + 1) * BLOCK]
            out[i, j] = float(blk.sum()) > chdtri(blk.size, alpha)
    return out


def _cast_neutral(obs: Observation, tol: float) -> tuple[bool, str]:
    g = obs.gains()
    # which η and α: the sampler's exposed η (not the classical one) over α = 1/mean SFR, the Rates panel's α
    words = f"gains η/α = {np.round(g, 3).tolist()} (η {obs.eta:.3g}, the sampler's exposed η; α = 1/mean SFR, ticks/spike)"
    dev = float(np.max(np.abs(g / g.mean() - 1.0)))
    scale = abs(float(g.mean()) - 1.0)
    if dev <= tol and scale <= tol:
        return True, f"{words} are within {100 * tol:.0f}% of 1: neutral, C would change nothing"
    if dev <= tol:  # neutral in colour, but C also carries the sequence's exposure (the white point at 0.9)
        return False, (f"{words} are neutral in colour ({100 * dev:.1f}%) but set the "
                       f"exposure (×{1 / float(g.mean()):.3g})")
    return False, f"{words} deviate {100 * dev:.0f}% from neutral"


def _distinct(a: float, b: float) -> tuple[str, str]:
    """``a`` and ``b`` to 2 decimals, or to as many more (up to 4) as it takes for unequal numbers to print
    unequal (a σ just above its target read "σ = 4.00/255 is above the target 4.00/255")."""
    for digits in (2, 3, 4):
        fa, fb = f"{a:.{digits}f}", f"{b:.{digits}f}"
        if fa != fb or a == b:
            break
    return fa, fb


#: the white of the image the sampler sees at which the noise target is judged (the colour cast's exposure puts a
#: Bayer frame's white here): a dark capture's σ is judged relative to its own white, so its noise, small in
#: absolute units, is not taken for "already meets the target" (a real capture at 0.03 spikes per tick was)
WHITE_REF = 0.9


def exposure_scale(obs: Observation, mosaic: bool, cast: bool) -> float:
    """:data:`WHITE_REF` over the 99.5th percentile of the image the sampler sees (the local rate, times α/η with
    a cast), at least 1: how much the display will brighten this frame's noise."""
    r = obs.local_rate().astype(np.float64)
    if mosaic and cast and obs.alpha is not None and obs.cfa is not None:
        r = r * (np.asarray(obs.alpha, dtype=np.float64) / obs.eta)[obs.channel_map()]
    top = float(np.quantile(r, 0.995)) if r.size else 1.0
    return max(1.0, WHITE_REF / max(top, 1e-6))


def _judged(scale: float, worst: float, sigma: np.ndarray) -> str:
    """What the judged σ is, when it is not the frame's RMS: its worst block, relative to the frame's white."""
    parts = []
    if worst > float(sigma.max()) * 1.05:
        parts.append(f"the worst {NOISE_BLOCK}-px block's, {255 * worst:.2f}/255")
    if scale > 1.0:
        parts.append(f"× {scale:.3g}: judged relative to the frame's white, its 99.5th percentile brought to {WHITE_REF:g}")
    return f" ({'; '.join(parts)})" if parts else ""


def make_plan(obs: Observation, params: GuidedConfig | None = None) -> Plan:
    """Analyse one window and decide the stages (see the module docstring for the rules).

    Args:
        obs: the window (with ``previous`` set when the reuse test should run).
        params: the reconstruction settings (defaults if ``None``).

    Raises:
        ParameterError: ``params.levels`` exceeds the size cap while ``params.levels_cap`` is False.
    """
    p = params if params is not None else GuidedConfig()
    r: dict[str, str] = {}

    # --- M
    if p.use_mosaic is not None:
        mosaic = bool(p.use_mosaic) and obs.cfa is not None
        r["mosaic"] = f"set by use_mosaic={p.use_mosaic}" + ("" if mosaic or not p.use_mosaic else " (but the stream is monochrome)")
    elif obs.cfa is None:
        mosaic, r["mosaic"] = False, "monochrome stream: no CFA to model"
    else:
        mosaic, r["mosaic"] = True, f"Bayer {obs.cfa} stream"

    # --- C
    if not mosaic:
        cast, r["cast"] = False, "no colour channels (M is off)"
    elif obs.alpha is None:
        cast, r["cast"] = False, "no colour-cast estimate (α) given"
    elif p.use_cast is not None:
        cast, r["cast"] = bool(p.use_cast), f"set by use_cast={p.use_cast}"
    else:
        neutral, why = _cast_neutral(obs, p.cast_tolerance)
        cast, r["cast"] = (not neutral), why

    # --- Q
    if p.quantise is not None:
        quantise, r["quantise"] = bool(p.quantise), f"set by quantise={p.quantise}"
    elif obs.corrected:
        # Q rounds to the 1/Δτ levels of raw counts; the corrected rates (y − dark) / gain lie between them, and a Q
        # that rounds them biases each channel by its own offset (a colour shift: 3.8° and −2 dB on a calibrated
        # simulated capture, benchmarks/results/colour.md)
        quantise, r["quantise"] = False, (f"{obs.corrected} moved the rates off the TFP's 1/Δτ grid that Q models; "
                                          "--quantise on forces it")
    elif p.guidance == "dps" or p.prior == "sd":
        quantise, r["quantise"] = True, "DPS guidance: the residual of the non-squared loss sees the TFP's 1/Δτ steps"
    else:
        # the spikes Q's value is made of: over Δτ_eff ticks (a pooled value without a dark rate in it), else per
        # window (Observation.quantise_window says why)
        count, qw = obs.quantise_count(), obs.quantise_window()
        per_window = qw == obs.window
        step = "1/Δτ" if per_window else f"1/{qw}-tick"
        if count < Q_COUNT:
            quantise, r["quantise"] = True, (f"low count ({_count_words(obs, count, per_window)} < {Q_COUNT:g}): the "
                                             f"counts are small integers and Q models their {step} steps")
            share = float(getattr(obs.pooling, "interval_share", 0.0) or 0.0)
            if per_window and share >= 0.5:
                # the darkest floor was read as a dark rate, which the per-window grid takes off; on a capture without
                # one (a noise-free simulation whose darkest patch holds light) it takes scene light off and rounds
                # the interval rates to its steps: an ecosystem-style dark chelsea 25.45 dB, 33.24 without Q
                r["quantise"] += (f"; the capture's darkest floor ({obs.floor:.2g} spikes per tick) is taken for a dark "
                                  f"rate, which this grid takes off, though {100 * share:.0f}% of the rates come from "
                                  "spike intervals: if the capture has no dark current (a noise-free simulation), "
                                  "--no-quantise keeps its shadows (or calibrate the camera with a dark capture)")
        else:
            quantise, r["quantise"] = False, (f"count {_count_words(obs, count, per_window)} >= {Q_COUNT:g}: Q's slope, "
                                              "between 0 and k/2Δτ, costs PSNR in the HQS data step here; --quantise turns it on")

    # --- levels
    top = max_levels(*obs.shape)
    size = f"{obs.shape[1]}x{obs.shape[0]}"  # width x height, as the tiles row
    if p.levels > top:
        if not p.levels_cap:
            raise ParameterError(
                f"GuidedConfig.levels = {p.levels} is too many for a {size} frame: use at most {top}."
            )
        levels, r["levels"] = top, f"capped from {p.levels}: a {size} frame allows at most {top}"
    else:
        levels, r["levels"] = p.levels, f"as set (a {size} frame allows up to {top})"

    # --- diffusion
    var, gain = start_variance(obs, mosaic, cast)  # per pixel: the tile plan averages it per tile
    sigma = sigma_of(var, gain)
    scale = exposure_scale(obs, mosaic, cast)
    worst = worst_block_sigma(var, gain)
    # judged against the target: the worst block's σ, relative to the frame's white (WHITE_REF)
    smax = max(float(sigma.max()), worst) * scale
    auto_fallback = "tfp" if smax <= p.noise_target / 4 else "baseline"
    fallback = p.fallback or auto_fallback
    if p.diffusion == "always":
        diffusion, r["diffusion"] = True, "set by diffusion='always'"
    elif p.diffusion == "never":
        diffusion, r["diffusion"] = False, "set by diffusion='never'"
    elif smax <= p.noise_target:
        diffusion = False
        a, b = _distinct(255 * smax, 255 * p.noise_target)
        r["diffusion"] = f"TFP noise σ = {a}/255{_judged(scale, worst, sigma)} already meets the target {b}/255 (bright or long window)"
    else:
        diffusion = True
        a, b = _distinct(255 * smax, 255 * p.noise_target)
        r["diffusion"] = f"TFP noise σ = {a}/255{_judged(scale, worst, sigma)} is above the target {b}/255"
    if not diffusion:
        r["diffusion"] += f"; fallback {fallback}" + (" (set by fallback)" if p.fallback else "")

    # --- reuse
    changed = changed_blocks(obs, p.reuse_alpha) if p.reuse is not False else None
    if p.reuse is False:
        reuse, r["reuse"] = False, "set by reuse=False"
    elif changed is None:
        reuse, r["reuse"] = False, "no previous window to compare with"
    elif not changed.any():
        reuse, r["reuse"] = True, f"counts match the previous window within their noise (all {changed.size} blocks)"
    else:
        reuse = False
        r["reuse"] = f"{int(changed.sum())} of {changed.size} blocks changed beyond their noise"
    # --- demosaic (of the start estimate / the one-pass input / the TFP fallback)
    denoised = diffusion or fallback == "baseline"
    if not mosaic:  # a gray frame: no mosaic, so nothing to demosaic (whatever demosaic is set to)
        demosaic, r["demosaic"] = "none", ("monochrome stream: no mosaic, no demosaic, no cast" if obs.cfa is None
                                           else "M is off: the gray frame is not demosaicked")
    else:
        demosaic, r["demosaic"] = choose_demosaic(smax, p.demosaic, denoised=denoised, mean_count=obs.mean_count(),
                                                  shape=obs.shape, count_words=lambda c: _count_words(obs, c))
    # --- temporal support (what the observation pooled: spikeview.guided.temporal)
    pool = obs.pooling
    temporal = "off" if pool is None or pool.kind in ("off", "unavailable") else pool.kind
    r["temporal"] = pool.reason if pool is not None else "off (temporal_radius = 0): the window alone, as in the paper"
    # --- the finished frame's colour balance (spikeview.guided.balance)
    corrected = obs.corrected is not None
    balance = bool(mosaic and diffusion and p.balance and (quantise or corrected))
    if not mosaic:
        r["balance"] = "none: a gray frame"
    elif balance:
        r["balance"] = ("each channel's mean kept at the data's (" + (
            "the camera profile's gains; the frame's clip at 0 would lift each channel's black by its own noise"
            if corrected else "gray-world gains; Q's floor would crush the weaker channels' small counts") + ")")
    elif not diffusion:
        r["balance"] = "as computed (no diffusion)"
    elif not p.balance:
        r["balance"] = "as sampled (the gains are neither gray-world's nor the camera profile's)"
    else:
        r["balance"] = "as sampled (Q off, rates not corrected by a profile)"
    # --- chroma smoothing of the finished frame (spikeview.guided.chroma)
    if not mosaic:
        r["chroma"] = "none: a gray frame has no colour to smooth"
    elif p.chroma <= 0:
        r["chroma"] = "off (chroma = 0)"
    else:
        r["chroma"] = f"colour smoothed over σ {p.chroma:g} px, guided by the luma (its edges kept); luma untouched"
    # --- per-tile plan (spikeview.guided.tiles): only for a frame larger than one tile that needs diffusion
    tile_map = None
    if p.tile and max(obs.shape) > p.tile and diffusion and p.prior != "sd" and p.guidance == "hqs":
        from spikeview.guided.tiles import plan_tiles

        probe = Plan(mosaic, cast, levels, diffusion, fallback, False, None, sigma, {}, quantise, demosaic, exposure=scale)
        tile_map = plan_tiles(obs, probe, p, variance=(var, gain))
        r["tiles"] = tile_map.summary()
    elif not p.tile:
        r["tiles"] = "off (guided.tile = 0): the whole frame at once"
    else:
        why = ("the frame fits in one tile" if max(obs.shape) <= p.tile else "no diffusion to tile" if not diffusion
               else "the sd prior runs on the whole frame" if p.prior == "sd"
               else "DPS guidance takes one gradient of the whole frame's residual norm")
        r["tiles"] = f"off: {why}"
    # --- where the window runs (spikeview.guided.device) and the prior's arithmetic there (spikeview.guided.precision:
    # resolved from the CPU's features, or the GPU)
    from spikeview.guided.device import describe_device, device_label, resolve_device

    dev = resolve_device(p.device)
    r["device"] = describe_device(p.device)
    if p.prior == "sd":
        precision, r["precision"] = "", f"the sd prior runs in guided.dtype = {p.dtype}"
    else:
        from spikeview.guided.precision import resolve_precision

        precision, r["precision"] = resolve_precision(p.precision, device=dev)
    return Plan(mosaic, cast, levels, diffusion, fallback, reuse, changed, sigma, r, quantise, demosaic, temporal,
                pooling=pool, precision=precision, tile_map=tile_map, device=device_label(dev), exposure=scale,
                judged_sigma=smax, chroma=p.chroma if mosaic else 0.0, balance=balance)
