"""The scene plan: every rule on a scene made to trigger it and on one made not to, plus overrides."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation, haar_noise_variance
from spikeview.guided.plan import make_plan, max_levels
from spikeview.io.source import ArraySource
from test_guided_helpers import make_source, scene_rates, spikes_from_rates

CAST = np.array([1 / 0.6, 1.0, 1 / 0.5]) / 0.6  # the simulator's default green-heavy response, η = 1


def _obs(kind="texture", h=32, w=32, window=10, cfa="RGGB", alpha=CAST, eta=1.0, previous=False, src=None, center=None):
    src = src if src is not None else make_source(kind, h, w, ticks=max(4 * window, 40), cfa=cfa)
    c = center if center is not None else src.n_frames // 2
    return Observation.from_source(src, c, window, alpha=alpha if cfa else None, eta=eta, previous=previous, radius=0)


def test_mosaic_off_for_monochrome_on_for_bayer():
    mono = make_plan(_obs(cfa=None))
    assert not mono.mosaic and not mono.cast and "monochrome" in mono.reasons["mosaic"]
    bayer = make_plan(_obs())
    assert bayer.mosaic and "RGGB" in bayer.reasons["mosaic"]


def test_cast_off_when_neutral_on_when_not():
    neutral = make_plan(_obs(alpha=np.array([2.0, 2.02, 1.99]), eta=2.0))
    assert not neutral.cast and "neutral" in neutral.reasons["cast"]
    cast = make_plan(_obs())
    assert cast.cast and "deviate" in cast.reasons["cast"]


def test_levels_capped_by_frame_size():
    small = make_plan(_obs(h=8, w=8), GuidedConfig(levels=6))
    assert small.levels == max_levels(8, 8) == 3 and "capped" in small.reasons["levels"]
    big = make_plan(_obs(h=32, w=32), GuidedConfig(levels=3))
    assert big.levels == 3 and "capped" not in big.reasons["levels"]


def test_no_diffusion_for_long_windows_diffusion_for_short():
    # a 10-tick window of a mid-grey texture is far noisier than the target; a 400-tick window is not
    src = make_source("ramp", 32, 32, ticks=800)
    short = make_plan(_obs(src=src, window=10))
    assert short.diffusion and "above the target" in short.reasons["diffusion"]
    long = make_plan(_obs(src=src, window=400))
    assert not long.diffusion and "meets the target" in long.reasons["diffusion"]
    assert long.sigma.max() < short.sigma.max() / 10


def test_no_diffusion_for_saturated_windows_with_tfp_fallback():
    sat = make_plan(_obs("saturated"))
    assert not sat.diffusion and sat.fallback == "tfp"
    # a bright but textured window keeps the baseline fallback when forced off
    forced = make_plan(_obs(), GuidedConfig(diffusion="never"))
    assert not forced.diffusion and forced.fallback == "baseline" and "diffusion='never'" in forced.reasons["diffusion"]


def test_reuse_when_the_window_did_not_change():
    rates = scene_rates("texture", 32, 32)
    static = ArraySource(spikes_from_rates(rates, 60, seed=3), cfa="RGGB")
    plan = make_plan(_obs(src=static, previous=True, center=35))
    assert plan.changed is not None and not plan.changed.any()
    assert plan.reuse and "match" in plan.reasons["reuse"]


def test_no_reuse_when_the_window_changed():
    rates = scene_rates("texture", 32, 32)
    spikes = spikes_from_rates(rates, 60, seed=3)
    moved = spikes_from_rates(np.roll(rates, 4, axis=1)[:, :], 60, seed=4)
    spikes[30:] = moved[30:]  # the scene jumps at tick 30: window [30, 40) differs from [20, 30)
    plan = make_plan(_obs(src=ArraySource(spikes, cfa="RGGB"), previous=True, center=35))
    assert not plan.reuse and plan.changed.any() and "changed" in plan.reasons["reuse"]


def test_reuse_override_and_no_previous():
    assert not make_plan(_obs()).reuse  # no previous window
    rates = scene_rates("texture", 32, 32)
    static = ArraySource(spikes_from_rates(rates, 60, seed=3), cfa="RGGB")
    off = make_plan(_obs(src=static, previous=True, center=35), GuidedConfig(reuse=False))
    assert not off.reuse and off.reasons["reuse"] == "set by reuse=False"


@pytest.mark.parametrize("field,value,attr,expect", [
    ("use_mosaic", False, "mosaic", False),
    ("use_cast", False, "cast", False),
    ("use_cast", True, "cast", True),
    ("diffusion", "always", "diffusion", True),
    ("fallback", "tfp", "fallback", "tfp"),
])
def test_overrides_win_and_say_so(field, value, attr, expect):
    obs = _obs(alpha=np.array([2.0, 2.0, 2.0]), eta=2.0) if field == "use_cast" else _obs()
    plan = make_plan(obs, GuidedConfig(**{field: value}))
    assert getattr(plan, attr) == expect
    if attr != "fallback":
        assert "set by" in plan.reasons[attr]


def test_str_lists_every_choice_with_its_reason():
    text = str(make_plan(_obs()))
    for key in ("mosaic", "cast", "levels", "diffusion", "reuse"):
        assert key in text
    assert "/255" in text and "deviate" in text


def test_data_derived_noise_matches_the_measured_error():
    # the noise level the plan hands the prior is within 25 % of the real error of the estimate
    rates = np.full((64, 64), 0.35)  # 3.5 spikes per window: counts 3 or 4
    src = ArraySource(spikes_from_rates(rates, 40, seed=1), cfa=None)
    obs = Observation.from_source(src, 20, 10, eta=2.0, radius=0)
    true_sigma = float(np.std(obs.y - 0.35))
    est = float(make_plan(obs).sigma[0])
    assert est == pytest.approx(true_sigma, rel=0.25)


def test_haar_estimator_on_gaussian_noise():
    rng = np.random.default_rng(0)
    v = haar_noise_variance(rng.normal(0, 0.1, (128, 128)))
    assert v == pytest.approx(0.01, rel=0.1)
    assert haar_noise_variance(np.zeros((1, 5))) is None


# ------------------------------------------------------------------------------------ demosaic
def test_demosaic_auto_bilinear_where_noise_dominates_malvar_where_clean_or_denoised():
    from spikeview.classical.noise import DEMOSAIC_CLEAN_SIGMA, choose_demosaic

    assert choose_demosaic(2 * DEMOSAIC_CLEAN_SIGMA)[0] == "bilinear"
    assert choose_demosaic(DEMOSAIC_CLEAN_SIGMA / 2)[0] == "malvar2004"
    assert choose_demosaic(2 * DEMOSAIC_CLEAN_SIGMA, denoised=True)[0] == "malvar2004"
    name, why = choose_demosaic(0.5, "menon2007")
    assert name == "menon2007" and "set by demosaic" in why
    # in the plan: a noisy 10-tick window that runs the sampler starts from Malvar, with the reason
    plan = make_plan(_obs(), GuidedConfig(diffusion="always"))
    assert plan.demosaic == "malvar2004" and "prior denoises" in plan.reasons["demosaic"]
    assert "demosaic" in str(plan)
    # without diffusion and with the TFP fallback, the same noisy window is demosaicked bilinearly
    plan = make_plan(_obs(), GuidedConfig(diffusion="never", fallback="tfp"))
    assert plan.demosaic == "bilinear" and "noise dominates" in plan.reasons["demosaic"]


def test_classical_auto_demosaic_measures_the_noise_of_the_mosaic():
    from spikeview.classical.reconstruct import auto_demosaic

    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:32, 0:32]
    smooth = 0.3 + 0.2 * np.sin(xx / 5.0) * np.cos(yy / 7.0)
    assert auto_demosaic(smooth, "RGGB")[0] == "malvar2004"  # no noise at all: clean
    noisy = rng.binomial(10, smooth) / 10.0  # a 10-tick TFP window: σ ≈ 0.15
    name, why = auto_demosaic(noisy, "RGGB")
    assert name == "bilinear" and "noise dominates" in why
    assert auto_demosaic(noisy, "RGGB", "malvar2004")[0] == "malvar2004"


def test_demosaic_auto_starts_sparse_counts_bilinearly():
    from spikeview.classical.noise import SPARSE_COUNT, choose_demosaic

    assert choose_demosaic(0.2, denoised=True, mean_count=SPARSE_COUNT / 2)[0] == "bilinear"
    assert choose_demosaic(0.2, denoised=True, mean_count=2 * SPARSE_COUNT)[0] == "malvar2004"
    rates = scene_rates("texture", 32, 32) * 0.02  # about 0.07 spikes per photosite per 10-tick window
    src = ArraySource(spikes_from_rates(rates, 40, seed=1), cfa="RGGB")
    plan = make_plan(Observation.from_source(src, 20, 10, alpha=CAST, eta=1.0, radius=0), GuidedConfig(diffusion="always"))
    assert plan.demosaic == "bilinear" and "sparse counts" in plan.reasons["demosaic"]


def test_noise_model_uses_the_local_rate_not_the_photosite_count():
    # a lone spike among zeros: its neighbours get the variance of the local rate, not of a zero count
    y = np.zeros((16, 16), dtype=np.float32)
    y[8, 8] = 0.1
    obs = Observation(y, None, 10)
    rate = obs.local_rate()
    assert rate[8, 8] == pytest.approx(0.1 / 9) and rate[7, 7] == pytest.approx(0.1 / 9) and rate[0, 0] == 0.0
    var = obs.variance()
    assert var[7, 7] == pytest.approx(var[8, 8]) and var[7, 7] > var[0, 0]


def test_q_is_on_for_hqs_at_low_rates_only():
    from spikeview.guided.plan import Q_COUNT

    low = ArraySource(spikes_from_rates(scene_rates("texture", 32, 32) * 0.1, 40, seed=1), cfa="RGGB")  # ~0.3 spikes
    high = ArraySource(spikes_from_rates(np.full((32, 32), 0.5), 40, seed=1), cfa="RGGB")  # 5 spikes per window
    for src, on in ((low, True), (high, False)):
        obs = Observation.from_source(src, 20, 10, alpha=CAST, eta=1.0, radius=0)
        assert (float(obs.y.mean()) * 10 < Q_COUNT) == on
        plan = make_plan(obs, GuidedConfig(diffusion="always"))
        assert plan.quantise == on and ("low count" if on else ">=") in plan.reasons["quantise"]
        assert make_plan(obs, GuidedConfig(quantise=False)).quantise is False  # the override wins


def test_demosaic_auto_is_bilinear_for_frames_too_small_for_malvar():
    from spikeview.classical.reconstruct import auto_demosaic

    assert auto_demosaic(np.zeros((2, 2), np.float32), "RGGB")[0] == "bilinear"
    plan = make_plan(Observation(np.full((2, 4), 0.5, np.float32), "RGGB", 10, CAST, 1.0), GuidedConfig(diffusion="always"))
    assert plan.demosaic == "bilinear" and "too small" in plan.reasons["demosaic"]


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_q_reason_says_what_the_count_counts_when_windows_are_pooled(cfa):
    """With temporal_radius > 0 the count compared with Q_COUNT is, where the darkest floor is black, the spikes pooled
    over Δτ_eff (a pooled value is the aligned windows' spikes summed, on a 1/Δτ_eff grid): a rate of 0.3 spikes a
    window, which the own window alone would quantise, is pooled to ~2 spikes: Q off, in colour and monochrome alike
    (a dark rate left in keeps the per-window count: test_a_dark_rate_left_in_keeps_q_on_the_window_grid). The reason
    says which count and gives the own window's beside it."""
    from spikeview.guided.plan import Q_COUNT

    rates = np.full((32, 32), 0.03)
    rates[:16, :16] = 0.0  # a black corner: no dark rate in the rates (Observation.quantise_window)
    src = ArraySource(spikes_from_rates(rates, 120, seed=2), cfa=cfa)  # static: ~0.3 spikes per 10 ticks
    alpha = CAST if cfa else None
    pooled = Observation.from_source(src, 60, 10, alpha=alpha, eta=1.0, radius=3)
    assert pooled.dtau is not None and pooled.own is not None
    plan = make_plan(pooled, GuidedConfig(diffusion="always"))
    reason = plan.reasons["quantise"]
    own = pooled.own.mean_count()
    assert own < Q_COUNT <= pooled.mean_count() and f"{own:.2f} in its own 10-tick window" in reason
    assert not plan.quantise and pooled.quantise_window() > 5 * 10
    assert f"count {pooled.mean_count():.2f} spikes per photosite pooled over the aligned windows (Δτ_eff " in reason
    assert f">= {Q_COUNT:g}" in reason
    alone = Observation.from_source(src, 60, 10, alpha=alpha, eta=1.0, radius=0)
    plan = make_plan(alone, GuidedConfig(diffusion="always"))
    assert plan.quantise and f"{alone.mean_count():.2f} spikes per photosite per window" in plan.reasons["quantise"]
    assert "pooled" not in plan.reasons["quantise"] and "1/Δτ steps" in plan.reasons["quantise"]


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_q_of_a_pooled_observation_rounds_to_its_pooled_step(cfa):
    """Where Q is on for a pooled observation whose darkest floor is black its grid is 1/Δτ_eff, not 1/Δτ (k scaled
    with it): on the 10-tick grid Q's soft floor (Q(0) ≈ 0.12/Δτ at k = 20) read a dark channel's pooled rate, a fraction
    of a spike a window, as black (monochrome alike: its darker half went to 0)."""
    import torch

    from spikeview.guided.sampler import GuidedSampler

    rates = np.full((32, 32), 0.008)
    rates[:16, :16] = 0.0  # a black corner: no dark rate in the rates
    src = ArraySource(spikes_from_rates(rates, 120, seed=3), cfa=cfa)  # ~0.6 spikes over 70 ticks
    alpha = CAST if cfa else None
    pooled = Observation.from_source(src, 60, 10, alpha=alpha, eta=1.0, radius=3)
    plan = make_plan(pooled, GuidedConfig(diffusion="always"))
    q = pooled.quantise_window()
    fm = GuidedSampler.forward_model(pooled, plan, GuidedConfig())
    assert plan.quantise and fm.quantise.window == q
    floor = float(fm.quantise(torch.zeros(1)))
    assert q >= 60 and f"1/{q}-tick steps" in plan.reasons["quantise"]
    assert 0 < floor < 0.13 / q  # the pooled grid's floor, several times below the own window's
    alone = Observation.from_source(src, 60, 10, alpha=alpha, eta=1.0, radius=0)
    fm0 = GuidedSampler.forward_model(alone, make_plan(alone, GuidedConfig(diffusion="always")), GuidedConfig())
    assert fm0.quantise.window == 10 and float(fm0.quantise(torch.zeros(1))) > 0.1 / 10


def test_sparse_demosaic_reason_names_the_pooled_count():
    # 70 ticks: ±3 windows and no more (a longer dark capture pools further at rest: temporal.LOW_LIGHT_RADIUS)
    src = ArraySource(spikes_from_rates(np.full((32, 32), 0.003), 70, seed=3), cfa="RGGB")
    pooled = Observation.from_source(src, 35, 10, alpha=CAST, eta=1.0, radius=3)
    plan = make_plan(pooled, GuidedConfig(diffusion="always"))
    assert plan.demosaic == "bilinear" and "pooled over the aligned windows" in plan.reasons["demosaic"]


def test_cast_reason_names_the_eta_and_the_alpha_it_divides():
    """The plan's gains η/α name their η (the sampler's exposed η) and α's unit, so that they can be
    matched with the Rates panel's α = 1/mean SFR (a factor of the exposure scale apart otherwise)."""
    obs = _obs(eta=6.0)
    reason = make_plan(obs).reasons["cast"]
    g = np.round(6.0 / np.asarray(CAST), 3).tolist()
    assert f"gains η/α = {g} (η 6, the sampler's exposed η; α = 1/mean SFR, ticks/spike)" in reason
    assert "monochrome" in make_plan(_obs(cfa=None)).reasons["cast"] or "no colour" in make_plan(_obs(cfa=None)).reasons["cast"]


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_a_dark_rate_left_in_keeps_q_on_the_window_grid(cfa):
    """The same dim static scene without black (its darkest floor 0.03 spikes per tick: a dark rate no profile
    took off): Q stays on the own window's grid, whose floor takes the pedestal off, and decides per window. (A colour
    sensor has a cast, the typical one here: a capture without one is taken as made from RGB frames, without a dark
    current; see the next test.)"""
    rates = np.full((32, 32), 0.03)
    if cfa:  # a gray scene through the typical response: R 0.6 / G 1 / B 0.5 of G's 0.05
        rates[:] = 0.05
        rates[0::2, 0::2], rates[1::2, 1::2] = 0.03, 0.025
    src = ArraySource(spikes_from_rates(rates, 120, seed=2), cfa=cfa)
    pooled = Observation.from_source(src, 60, 10, alpha=CAST if cfa else None, eta=1.0, radius=3)
    assert pooled.floor * pooled.window >= 0.03 and pooled.quantise_window() == 10
    plan = make_plan(pooled, GuidedConfig(diffusion="always"))
    assert plan.quantise and "per 10-tick window, the rate pooled" in plan.reasons["quantise"]
