"""What the guided sampler actually does, asserted on its iterates rather than on its clamped output.

Each test here was checked by mutation (the mutation named in its docstring makes it fail):

* a diverging run (non-finite iterate) is an error with one sentence, not a black frame;
* the data residual of x̂₀ falls under guidance, along DPS and HQS steps (a DPS step of the wrong
  sign, or an HQS data step of the wrong sign, fails);
* the per-channel σ handed to the prior matches a Monte-Carlo estimate of the start estimate's
  noise within a few per cent (σ × 1.3 fails);
* ``ForwardModel.loss`` compares the variance-stabilised values when ``vst`` is on.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikeview.errors import ParameterError
from spikeview.guided.baseline import start_estimate
from spikeview.guided.config import GuidedConfig
from spikeview.guided.guidance import DPSGuidance, HQSGuidance
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.guided.sampler import GuidedSampler
from spikeview.ops.forward import ForwardModel
from spikeview.ops.noise import binomial_vst
from spikeview.ops.pyramid import multiscale_loss
from test_guided_helpers import BlurDenoiser, Recorder, SigmaSpy, make_source

ALPHA = np.array([1 / 0.6, 1.0, 1 / 0.5]) / 0.6


def _obs(h=32, w=32):
    src = make_source("texture", h, w, ticks=30)
    return Observation.from_source(src, 15, 10, alpha=ALPHA, eta=1.0, radius=0)


def _run(params, rule, obs=None):
    obs = obs if obs is not None else _obs()
    rec = Recorder(rule)
    out = GuidedSampler(params, prior=BlurDenoiser(), guidance=rec).run(obs, params)
    return rec, out


# ------------------------------------------------------------------------------- divergence
class NaNRule:
    """A guidance rule whose steps diverge (what a far too large step does to a real sampler)."""

    needs_grad = False

    def step(self, prior, schedule, data, x_t, index, sigma, **kw):
        bad = torch.full_like(x_t, float("nan"))
        return bad, bad


@pytest.mark.parametrize("guidance", ["dps", "hqs"])
def test_a_diverging_run_is_an_error_with_one_sentence(guidance):
    p = GuidedConfig(guidance=guidance, steps=3, diffusion="always", eta=1.0)
    with pytest.raises(ParameterError, match=r"diverged \(non-finite values at step 1 of 3") as err:
        GuidedSampler(p, prior=BlurDenoiser(), guidance=NaNRule()).run(_obs(), p)
    msg = str(err.value)
    assert msg.count(". ") == 0 and msg.endswith(".")  # one sentence, with the fix
    assert ("lower s" if guidance == "dps" else "raise lam") in msg


def test_a_prior_returning_nan_is_an_error_too():
    class NaNPrior(BlurDenoiser):
        def denoise(self, x, sigma):
            return torch.full_like(x, float("nan"))

    p = GuidedConfig(steps=2, diffusion="always", eta=1.0)
    with pytest.raises(ParameterError, match="diverged"):
        GuidedSampler(p, prior=NaNPrior()).run(_obs(), p)


# ------------------------------------------------------------------------ residual under guidance
def test_dps_steps_lower_the_data_residual():
    """Mutation: ``prev + s·grad`` instead of ``prev − s·grad`` in DPSGuidance makes this fail."""
    p = dict(guidance="dps", steps=4, diffusion="always", eta=1.0, self_ensemble=False)
    free, _ = _run(GuidedConfig(s=0.0, **p), DPSGuidance(0.0))
    guided, _ = _run(GuidedConfig(s=2.0, **p), DPSGuidance(2.0))
    assert all(guided.finite) and all(free.finite)
    # step 1's x̂₀ is computed before any guidance: the same; every later one is closer to the data
    assert guided.residual[0] == pytest.approx(free.residual[0], rel=1e-6)
    for g, f in zip(guided.residual[1:], free.residual[1:]):
        assert g < 0.97 * f
    assert guided.residual[-1] < guided.residual[0]  # and it falls along the steps


def test_hqs_steps_lower_the_data_residual():
    """Mutation: a data step of the wrong sign in DataTerm.prox makes this fail."""
    p = dict(guidance="hqs", steps=4, diffusion="always", eta=1.0, self_ensemble=False)
    free, _ = _run(GuidedConfig(data_steps=0, **p), HQSGuidance(2.0, 0, False, 1.0))
    guided, _ = _run(GuidedConfig(lam=2.0, data_steps=1, **p), HQSGuidance(2.0, 1, False, 1.0))
    assert all(guided.finite) and all(free.finite)
    # every x̂₀ is much closer to the data than without data steps (along the steps the residual then
    # rises towards the noise level as ρ_t = λσ_n²/σ_t² grows: the prior is trusted more at low σ_t)
    for g, f in zip(guided.residual, free.residual):
        assert g < 0.75 * f


def test_hqs_prox_lowers_its_objective():
    obs = _obs()
    p = GuidedConfig(diffusion="always", eta=1.0)
    plan = make_plan(obs, p)
    data = GuidedSampler.data_term(obs, plan, p)
    z = torch.from_numpy(start_estimate(obs, True, True, "bilinear")).permute(2, 0, 1)[None]
    z = (z + 0.1 * torch.randn(z.shape, generator=torch.Generator().manual_seed(1))).clamp(0, 1)
    rho = 0.5
    for steps in (1, 3):
        x = data.prox(z, rho, steps)
        f = lambda v: float(data.squared(v)) + 0.5 * rho * float(((v - z) ** 2).sum())  # noqa: E731
        assert f(x) < 0.9 * f(z)


# ------------------------------------------------------------------------- σ handed to the prior
def _ramp_scene(h=64, w=64):
    """Smooth per-photosite rates (no texture at the finest scale) of an RGGB sensor with a cast."""
    yy, xx = np.mgrid[0:h, 0:w]
    base = 0.25 + 0.35 * (xx + 0.5 * yy) / (w + 0.5 * h)
    cmap = np.zeros((h, w), dtype=int)
    cmap[0::2, 1::2] = 1
    cmap[1::2, 0::2] = 1
    cmap[1::2, 1::2] = 2
    return base * np.array([0.6, 1.0, 0.5])[cmap]


def _draw(rates, window, rng, model):
    if model == "binomial":
        return rng.binomial(window, rates) / window
    # integrate-and-fire with a random phase and threshold jitter: far below binomial variance
    return np.floor(rates * window * rng.normal(1.0, 0.05, rates.shape) + rng.uniform(0, 1, rates.shape)).clip(0, window) / window


@pytest.mark.parametrize("model", ["binomial", "integrate_and_fire"])
def test_sigma_told_to_the_prior_matches_a_monte_carlo_estimate(model):
    """Mutation: σ × 1.3 (in estimate_sigma or in the sampler) makes this fail.

    Expected value: the per-channel RMS over pixels of the standard deviation of the bilinear,
    colour-corrected start estimate over 400 independent windows of the same scene (Monte Carlo).
    """
    rng = np.random.default_rng(3)
    rates, window = _ramp_scene(), 10
    eta = 2.5  # keeps every channel's σ below the prior's cap (75/255)
    draws = np.stack([start_estimate(Observation(_draw(rates, window, rng, model), "RGGB", window, ALPHA, eta),
                                     True, True, "bilinear") for _ in range(400)])
    inner = (slice(None), slice(2, -2), slice(2, -2))  # the one-pixel mirrored border is not independent
    mc = np.sqrt(draws.var(axis=0)[inner[1:]].reshape(-1, 3).mean(axis=0))

    obs = Observation(_draw(rates, window, rng, model), "RGGB", window, ALPHA, eta)
    spy = SigmaSpy()
    p = GuidedConfig(steps=2, diffusion="always", eta=eta, t_start=1e-3, sigma_end=1e-3, top_up=True,
                     sigma_scale=1.0, demosaic="bilinear", self_ensemble=False)
    GuidedSampler(p, prior=spy).run(obs, p)
    told = spy.told[0]
    assert told.shape == (3,)
    np.testing.assert_allclose(told, mc, rtol=0.06)  # measured: within 2 %


# ------------------------------------------------------------------------------------ VST loss
def test_forward_model_loss_compares_vst_values_when_vst_is_on():
    """Mutation: ``ForwardModel.loss`` ignoring ``vst`` makes this fail."""
    g = torch.Generator().manual_seed(5)
    x = torch.rand((1, 3, 16, 16), generator=g, dtype=torch.float64) * 0.8 + 0.1
    y = torch.rand((1, 1, 16, 16), generator=g, dtype=torch.float64)
    fm = ForwardModel("RGGB", 10, None, 1.0, None, True, True, 2, vst=True)
    pred = fm(x)
    want = multiscale_loss(binomial_vst(pred, 10), binomial_vst(y, 10), 2, None, "l2", "sum")
    torch.testing.assert_close(fm.loss(x, y), want)
    plain = ForwardModel("RGGB", 10, None, 1.0, None, True, True, 2, vst=False).loss(x, y)
    # the VST residual is in noise units (≈ 1/σ ≈ 6 times the SFR residual at Δτ = 10)
    assert float(fm.loss(x, y)) > 3.0 * float(plain)
