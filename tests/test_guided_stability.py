"""Stability grid of the guided sampler: every setting at its extremes gives finite iterates.

The assertions are on what the sampler did, not on its (clamped) output: every iterate x_t and x̂₀
of every step is finite (a non-finite one is an error, see ``test_guided_behaviour.py``), the
sampler made as many steps as asked, and the data residual of the last x̂₀ is finite. Step sizes
beyond the config's range (DPS ``s`` up to 1e6) are applied through the guidance rule itself.
Most cases use the tiny stand-in denoiser (:class:`BlurDenoiser`) on 16×16 scenes with 2 steps;
at least one case per axis runs the real FFDNet at 16×16 (marked ``real``). Gradients are checked
through the prior with both data losses (DPS's norm and HQS's squared norm).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikeview.classical.colour_cast import ColourCastWarning
from spikeview.errors import ParameterError
from spikeview.guided.config import SIGMA_MAX, GuidedConfig
from spikeview.guided.guidance import DPSGuidance
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan, max_levels
from spikeview.guided.sampler import GuidedSampler, load_prior
from spikeview.guided.video import resolve_alpha
from test_guided_helpers import BlurDenoiser, Recorder, make_source

ALPHA = np.array([1 / 0.6, 1.0, 1 / 0.5]) / 0.6
FAST = dict(steps=2, diffusion="always", eta=1.0)


@pytest.fixture(scope="module")
def ffdnet():
    return load_prior(GuidedConfig(), 3)


def _obs(kind="texture", h=16, w=16, window=10, cfa="RGGB", alpha=ALPHA):
    src = make_source(kind, h, w, ticks=max(3 * window, 30), cfa=cfa)
    return Observation.from_source(src, src.n_frames // 2, window, alpha=alpha if cfa else None, eta=1.0, radius=0)


def _check(obs, params, prior=None, rule=None):
    """Run the sampler; assert finite iterates at every step, and finite data-term gradients through the prior."""
    prior = prior if prior is not None else BlurDenoiser(3 if obs.cfa else 1)
    rec = Recorder(rule if rule is not None else GuidedSampler.guidance_for(params))
    smp = GuidedSampler(params, prior=prior, guidance=rec)
    out = smp.run(obs, params)
    assert smp.info.mode == "diffusion" and smp.info.steps == params.steps
    assert len(rec.finite) == params.steps and all(rec.finite)
    assert np.all(np.isfinite(rec.residual))
    assert out.shape[:2] == obs.shape
    assert np.all(np.isfinite(out)) and out.min() >= 0.0 and out.max() <= 1.0
    plan = make_plan(obs, params)
    data = smp.data_term(obs, plan, params)
    c = 3 if plan.mosaic else 1
    x = torch.full((1, c) + obs.shape, 0.5).requires_grad_(True)
    sigma = torch.full((1, c), 0.1)
    for loss in (data.norm, data.squared):
        (g,) = torch.autograd.grad(loss(prior.denoise(x, sigma).clamp(0, 1)), x)
        assert torch.isfinite(g).all()
    return out


@pytest.mark.parametrize("guidance", ["dps", "hqs"])
@pytest.mark.parametrize("k", [0.0, 1.0, 50.0, 1e3])
def test_k_axis(guidance, k):
    _check(_obs(), GuidedConfig(guidance=guidance, k=k, quantise=True, levels=1, **FAST))


@pytest.mark.parametrize("s", [0.0, 1e-3, 1.0, 1e3, 1e6])
def test_s_axis(s):
    _check(_obs(), GuidedConfig(guidance="dps", quantise=True, **FAST), rule=DPSGuidance(s))


def test_large_s_still_moves_the_sample():
    # s matters: a huge step changes the result (the guidance is not silently ignored)
    obs = _obs()
    p = GuidedConfig(guidance="dps", **FAST)
    a = GuidedSampler(prior=BlurDenoiser(), guidance=DPSGuidance(0.0)).run(obs, p)
    b = GuidedSampler(prior=BlurDenoiser(), guidance=DPSGuidance(1e3)).run(obs, p)
    assert np.abs(a - b).max() > 1e-3


@pytest.mark.parametrize("guidance", ["dps", "hqs"])
@pytest.mark.parametrize("levels", list(range(0, max_levels(16, 16) + 1)))
def test_levels_axis(guidance, levels):
    _check(_obs(), GuidedConfig(guidance=guidance, levels=levels, **FAST))


def test_levels_beyond_the_cap_are_capped_or_refused():
    obs = _obs()
    top = max_levels(16, 16)
    assert top == 4  # 16 -> 8 -> 4 -> 2 -> 1: four halvings
    plan = make_plan(obs, GuidedConfig(levels=top + 2))
    assert plan.levels == top and "capped" in plan.reasons["levels"]
    _check(obs, GuidedConfig(levels=top + 2, **FAST))
    with pytest.raises(ParameterError, match="at most 4"):
        make_plan(obs, GuidedConfig(levels=top + 1, levels_cap=False))


@pytest.mark.parametrize("guidance", ["dps", "hqs"])
@pytest.mark.parametrize("t_start", [0.0, SIGMA_MAX])
def test_t_start_axis(guidance, t_start):
    _check(_obs(), GuidedConfig(guidance=guidance, t_start=t_start, sigma_end=min(2 / 255, max(t_start, 1 / 255)), **FAST))


def test_t_start_beyond_the_prior_range_is_refused():
    with pytest.raises(ParameterError, match="t_start"):
        GuidedConfig(t_start=0.5)


@pytest.mark.parametrize("window", [1, 2, 10, 64])
def test_window_axis(window):
    _check(_obs(window=window), GuidedConfig(window=window, quantise=True, levels=2, **FAST))


@pytest.mark.parametrize("kind", ["dark", "saturated", "no_blue", "constant", "checker"])
@pytest.mark.parametrize("guidance", ["dps", "hqs"])
def test_scene_axis(kind, guidance):
    _check(_obs(kind), GuidedConfig(guidance=guidance, quantise=True, levels=2, **FAST))


@pytest.mark.parametrize("h,w", [(8, 8), (15, 17), (9, 16)])
def test_size_axis(h, w):
    out = _check(_obs(h=h, w=w), GuidedConfig(levels=6, quantise=True, **FAST))  # above every cap here
    assert out.shape == (h, w, 3)


def test_monochrome_stream_gives_a_gray_frame():
    obs = _obs(cfa=None)
    out = _check(obs, GuidedConfig(**FAST))
    assert out.shape == obs.shape


def test_zero_mean_channel_in_gray_world_warns_and_falls_back():
    src = make_source("no_blue", 16, 16, ticks=30)
    with pytest.warns(ColourCastWarning):
        alpha = resolve_alpha(src, GuidedConfig())
    assert np.all(np.isfinite(alpha)) and np.all(alpha > 0)
    # the fallback gain is the mean of the informative channels' means (see classical.colour_cast)
    assert alpha[2] == pytest.approx(1.0 / np.mean([1.0 / alpha[0], 1.0 / alpha[1]]), rel=1e-5)
    obs = Observation.from_source(src, 15, 10, alpha=alpha, eta=2.0, radius=0)
    _check(obs, GuidedConfig(**FAST))


# --------------------------------------------------------------------------- real FFDNet, 16x16
@pytest.mark.parametrize(
    "changes",
    [
        dict(guidance="dps", k=1e3, quantise=True),  # k axis
        dict(guidance="dps"),  # s axis (s = 1e6 through the rule)
        dict(guidance="hqs", levels=4),  # L axis (max for 16x16)
        dict(guidance="hqs", t_start=SIGMA_MAX),  # t_s axis
        dict(guidance="hqs", window=1),  # Δτ axis
    ],
    ids=["k", "s", "levels", "t_start", "window"],
)
def test_real_ffdnet_per_axis(ffdnet, changes):
    window = changes.get("window", 10)
    rule = DPSGuidance(1e6) if changes == dict(guidance="dps") else None
    _check(_obs(window=window), GuidedConfig(**(FAST | changes)), prior=ffdnet, rule=rule)


@pytest.mark.parametrize("guidance", ["dps", "hqs"])
@pytest.mark.parametrize("kind", ["dark", "saturated", "checker"])
def test_real_ffdnet_scenes(ffdnet, kind, guidance):
    out = _check(_obs(kind), GuidedConfig(guidance=guidance, quantise=True, levels=2, **(FAST | dict(steps=4))), prior=ffdnet)
    if kind == "dark":
        assert out.mean() < 0.05  # no spikes: the frame stays (near) black
    if kind == "saturated":
        # a spike every tick: at least the sensor's full scale 1/(rate·gain) clipped to 1 on average
        assert out.mean() > 0.6
