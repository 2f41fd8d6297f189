"""The optional latent-diffusion backend (spikeview[sd]) on tiny randomly initialised models.

The models are built from configs (as diffusers' own tests do), saved with ``save_pretrained`` and
loaded back through :meth:`LatentDiffusionPrior.from_pretrained`; no weights are downloaded. The VAE
has four blocks like SD's, so its downsampling factor is SD's 8 and odd frame sizes get padded.

Sampling goes through the one guided driver, :class:`spikeview.guided.sampler.GuidedSampler`, with
``GuidedConfig(prior="sd", guidance="dps", ...)`` and the latent parts of :mod:`spikeview.guided.latent`.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
import sys
import threading
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from spikeview.errors import Cancelled, InputFileError, ParameterError
from spikeview.guided.baseline import start_estimate
from spikeview.guided.config import GuidedConfig
from spikeview.guided.latent import DDIMLadder, LatentDPSGuidance, make_ladder, start_timestep
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.guided.priors.base import PriorUnavailableError
from spikeview.guided.priors import sd_arch
from spikeview.guided.sampler import GuidedSampler, load_prior

HAS_DIFFUSERS = importlib.util.find_spec("diffusers") is not None
needs_diffusers = pytest.mark.skipif(not HAS_DIFFUSERS, reason='needs the optional extra: pip install "spikeview[sd]"')

# the library's tiny architectures, the VAE narrower still
TINY_VAE = sd_arch.TINY_VAE | dict(block_out_channels=(32, 32, 32, 32), sample_size=32)
H, W = 13, 22  # not multiples of 8: padded to 16 x 24, latent 2 x 3
# the sd path of the guided sampler: 3 DDIM steps from the pixel noise level 60/255; diffusion always
# (the plan could otherwise skip a clean window)
SD = dict(prior="sd", guidance="dps", steps=3, t_start=60 / 255, s=1.0, device="cpu", diffusion="always")


def _cfg(**changes) -> GuidedConfig:
    return GuidedConfig(**(SD | changes))


def _tiny_modules(seed: int = 0, **unet_changes):
    return sd_arch.random_modules(sd_arch.TINY_UNET | unet_changes, TINY_VAE, seed=seed)


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    # Tiny networks: one thread is faster, and several threads spin badly on a shared, loaded CPU.
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    if not HAS_DIFFUSERS:
        pytest.skip('needs the optional extra: pip install "spikeview[sd]"')
    root = tmp_path_factory.mktemp("tiny_sd")
    unet, vae, sched = _tiny_modules()
    unet.save_pretrained(root / "unet")
    vae.save_pretrained(root / "vae")
    sched.save_pretrained(root / "scheduler")
    return root


@pytest.fixture(scope="module")
def prior(model_dir):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    return LatentDiffusionPrior.from_pretrained(model_dir, device="cpu")


def _observation(h: int = H, w: int = W, cfa: str | None = "RGGB", seed: int = 1) -> Observation:
    rng = np.random.default_rng(seed)
    y = (rng.binomial(10, 0.4, size=(h, w)) / 10).astype(np.float32)
    alpha = None if cfa is None else np.array([2.5, 2.0, 3.0])
    return Observation(y, cfa, 10, alpha=alpha, eta=2.0)


# ------------------------------------------------------------------------------------- loading
@needs_diffusers
def test_loader_reads_saved_model(prior, model_dir):
    unet, _, _ = _tiny_modules()  # same seed: the weights that were saved
    assert prior.prediction_type == "v_prediction"
    assert prior.scaling_factor == pytest.approx(0.18215)  # AutoencoderKL's default = SD's latent scale
    assert prior.vae_factor == 8
    assert prior.num_train_timesteps == 1000
    # ᾱ of the scaled-linear schedule: β_t = (√β₀ + t/(T−1)·(√β_T − √β₀))², ᾱ_t = Π(1 − β)
    betas = np.linspace(0.00085**0.5, 0.012**0.5, 1000) ** 2
    np.testing.assert_allclose(prior.alphas_cumprod.numpy(), np.cumprod(1 - betas), rtol=1e-5)
    saved = unet.state_dict()
    for k, v in prior.unet.state_dict().items():
        torch.testing.assert_close(v, saved[k], rtol=0, atol=0)
    assert not any(p.requires_grad for p in prior.unet.parameters())
    assert not any(p.requires_grad for p in prior.vae.parameters())
    assert prior._cond.shape == (1, 1, 32) and not prior._cond.any()  # zero conditioning


@needs_diffusers
@pytest.mark.parametrize(
    "remove, named",
    [("unet", "unet/"), ("vae", "vae/"), ("scheduler", "scheduler/"), ("unet/config.json", "config.json"),
     ("vae/diffusion_pytorch_model.safetensors", "no weights file"), ("scheduler/scheduler_config.json", "scheduler_config.json")],
)
def test_incomplete_model_folder_names_what_is_missing(model_dir, tmp_path, remove, named):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    root = tmp_path / "model"
    shutil.copytree(model_dir, root)
    target = root / remove
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    with pytest.raises(InputFileError) as err:
        LatentDiffusionPrior.from_pretrained(root, device="cpu")
    msg = str(err.value)
    assert named in msg
    assert "unet/ and vae/" in msg and "scheduler/" in msg  # states the expected layout


@needs_diffusers
def test_missing_folder_and_damaged_config(tmp_path, model_dir):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    with pytest.raises(InputFileError, match="model folder not found"):
        LatentDiffusionPrior.from_pretrained(tmp_path / "nowhere")
    root = tmp_path / "model"
    shutil.copytree(model_dir, root)
    (root / "unet" / "config.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(InputFileError, match="config.json: not a readable JSON config"):
        LatentDiffusionPrior.from_pretrained(root, device="cpu")


def test_missing_diffusers_says_how_to_install(monkeypatch, tmp_path):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    monkeypatch.setitem(sys.modules, "diffusers", None)  # makes `import diffusers` raise ImportError
    with pytest.raises(PriorUnavailableError, match=r'pip install "spikeview\[sd\]"'):
        LatentDiffusionPrior.from_pretrained(tmp_path)


@needs_diffusers
def test_rejects_unets_that_are_not_text_to_image():
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    unet, vae, sched = _tiny_modules(in_channels=9)  # an inpainting-style UNet
    with pytest.raises(ParameterError, match="9 to 4 channels"):
        LatentDiffusionPrior(unet, vae, sched, device="cpu")


@needs_diffusers
def test_prompt_embeds_file_is_used(model_dir, tmp_path):
    from safetensors.torch import save_file

    from spikeview.guided.priors.sd import LatentDiffusionPrior

    root = tmp_path / "model"
    shutil.copytree(model_dir, root)
    emb = torch.randn(77, 32, generator=torch.Generator().manual_seed(3))
    save_file({"prompt_embeds": emb}, str(root / "prompt_embeds.safetensors"))
    p = LatentDiffusionPrior.from_pretrained(root, device="cpu")
    torch.testing.assert_close(p._cond, emb[None])
    save_file({"prompt_embeds": torch.zeros(77, 16)}, str(root / "prompt_embeds.safetensors"))
    with pytest.raises(ParameterError, match=r"\(L, 32\)"):
        LatentDiffusionPrior.from_pretrained(root, device="cpu")


@needs_diffusers
def test_half_precision_needs_cuda(prior):
    if torch.cuda.is_available():
        pytest.skip("only meaningful without a GPU")
    with pytest.raises(ParameterError, match="needs a CUDA GPU"):
        prior.to("cpu", "float16")
    assert prior.dtype == torch.float32


# ----------------------------------------------------------------------------- schedule, Tweedie
@needs_diffusers
@pytest.mark.parametrize("prediction_type", ["epsilon", "v_prediction", "sample"])
def test_tweedie_split_inverts_the_forward_process(prior, prediction_type):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    p = LatentDiffusionPrior(prior.unet, prior.vae, sd_arch.SD21_SCHEDULER | {"prediction_type": prediction_type}, device="cpu")
    g = torch.Generator().manual_seed(0)
    z0, eps = torch.randn(1, 4, 3, 5, generator=g), torch.randn(1, 4, 3, 5, generator=g)
    t = 600
    a = p.alpha_bar(t)
    z_t = a**0.5 * z0 + (1 - a) ** 0.5 * eps
    # the training targets of each parametrisation (diffusers' DDPMScheduler.get_velocity for v)
    target = {"epsilon": eps, "v_prediction": a**0.5 * eps - (1 - a) ** 0.5 * z0, "sample": z0}[prediction_type]
    eps_hat, z0_hat = p.split_prediction(target, z_t, t)
    torch.testing.assert_close(z0_hat, z0, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(eps_hat, eps, rtol=1e-5, atol=1e-5)


def test_ddim_ladder_timesteps_and_update():
    betas = torch.linspace(0.00085**0.5, 0.012**0.5, 1000, dtype=torch.float64) ** 2
    abar = torch.cumprod(1 - betas, 0)
    ladder = DDIMLadder(abar)
    np.testing.assert_array_equal(ladder.set_timesteps(4, 400), [400, 300, 200, 100])
    g = torch.Generator().manual_seed(0)
    z0, eps = torch.randn(1, 4, 2, 2, generator=g), torch.randn(1, 4, 2, 2, generator=g)
    # deterministic DDIM with the true (z0, eps) lands on the forward process at the next timestep
    out = ladder.step(z0, eps, 0).prev_sample
    a300 = float(abar[300])
    torch.testing.assert_close(out, a300**0.5 * z0 + (1 - a300) ** 0.5 * eps)
    assert ladder.alpha_bar(3)[1] == 1.0  # the last step lands on the clean latent
    torch.testing.assert_close(ladder.step(z0, eps, 3).prev_sample, z0)
    with pytest.raises(ParameterError, match="at most 3 steps"):
        ladder.set_timesteps(5, 3)
    with pytest.raises(ParameterError, match="needs fresh noise"):
        ladder.step(z0, eps, 0, eta=0.5)


def _abar() -> torch.Tensor:
    betas = torch.linspace(0.00085**0.5, 0.012**0.5, 1000, dtype=torch.float64) ** 2
    return torch.cumprod(1 - betas, 0)


def test_start_timestep_from_pixel_sigma():
    abar = _abar()
    for sigma in (5 / 255, 40 / 255, 50 / 255, 75 / 255):
        t = start_timestep(abar, sigma)
        target = 1 / (1 + (2 * sigma) ** 2)  # √((1−ᾱ)/ᾱ) = 2σ: the VAE works in [−1, 1]
        assert abar[t] <= target < abar[t - 1]
    assert start_timestep(abar, 50 / 255) > start_timestep(abar, 40 / 255)  # more noise, later start
    assert start_timestep(abar, 100.0) == 999  # beyond the schedule: its last timestep
    # the ladder starts there, and its σ of step 0 is the noise-to-signal ratio that reaches 2σ
    ladder = make_ladder(SimpleNamespace(alphas_cumprod=abar), 4, 50 / 255)
    t_s = start_timestep(abar, 50 / 255)
    assert ladder.timesteps[0] == t_s and len(ladder.timesteps) == 4
    nsr = float(ladder.sigma(0, torch.zeros(1)))
    assert nsr == pytest.approx(math.sqrt((1 - float(abar[t_s])) / float(abar[t_s])), rel=1e-6)
    assert nsr >= 2 * 50 / 255
    with pytest.raises(ParameterError, match="above 0"):
        make_ladder(SimpleNamespace(alphas_cumprod=abar), 4, 0.0)


def test_sd_fields_of_the_guided_config_round_trip(tmp_path):
    cfg = GuidedConfig(prior="sd", guidance="dps", model_path="/models/sd21", steps=30, t_start=40 / 255, s=0.5, zeta=0.25,
                       seed=7, k=20.0, quantise=True, levels=2, device="cpu", dtype="bfloat16")
    path = cfg.save(tmp_path / "sd.toml")
    back = GuidedConfig.load(path)
    assert back == cfg
    assert (back.prior, back.model_path, back.dtype, back.zeta, back.t_start) == ("sd", "/models/sd21", "bfloat16", 0.25, 40 / 255)
    with pytest.raises(ParameterError, match="dtype"):
        GuidedConfig(prior="sd", guidance="dps", dtype="float64")
    with pytest.raises(ParameterError, match="device"):
        GuidedConfig(prior="sd", guidance="dps", device="tpu")


# ------------------------------------------------------------------------------------- sampling
@needs_diffusers
def test_run_shape_range_and_padding(prior):
    for h, w in ((H, W), (16, 24)):  # padded and not
        rule = LatentDPSGuidance(1.0, (h, w))
        out = GuidedSampler(_cfg(), prior=prior, guidance=rule).run(_observation(h, w))
        assert out.shape == (h, w, 3) and out.dtype == np.float32
        assert np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0
        assert len(rule.losses) == 3 and all(math.isfinite(v) and v > 0 for v in rule.losses)


@needs_diffusers
def test_odd_sizes_are_edge_replicated_to_the_vae_factor(prior):
    seen = []

    class Spy:
        def __getattr__(self, name):
            return getattr(prior, name)

        def encode(self, x):
            seen.append(x.detach().clone())
            return prior.encode(x)

    obs = _observation()
    cfg = _cfg(steps=1)
    smp = GuidedSampler(cfg, prior=Spy())
    smp.run(obs)
    (x,) = seen
    assert x.shape == (1, 3, 16, 24)  # 13 x 22 padded to multiples of 8
    y0 = torch.from_numpy(start_estimate(obs, smp.info.plan.mosaic, smp.info.plan.cast, cfg.demosaic)).permute(2, 0, 1)[None]
    torch.testing.assert_close(x[..., :H, :W], y0.clamp(0, 1))
    torch.testing.assert_close(x[..., H:, :W], x[..., H - 1:H, :W].expand(-1, -1, 16 - H, -1))  # last row repeated
    torch.testing.assert_close(x[..., :, W:], x[..., :, W - 1:W].expand(-1, -1, -1, 24 - W))  # last column repeated


@needs_diffusers
def test_run_is_deterministic_for_a_seed(prior):
    obs = _observation()
    cfg = _cfg(zeta=0.5)  # fresh DDIM noise every step too
    a = GuidedSampler(cfg, prior=prior).run(obs)
    b = GuidedSampler(cfg, prior=prior).run(obs)
    c = GuidedSampler(cfg.replace(seed=1), prior=prior).run(obs)
    d = GuidedSampler(cfg.replace(zeta=0.0), prior=prior).run(obs)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-4
    assert np.abs(a - d).max() > 1e-4  # zeta is DDIM's η: it changes the path


@needs_diffusers
def test_callback_every_step_with_preview(prior):
    calls = []
    smp = GuidedSampler(_cfg(), prior=prior)
    out = smp.run(_observation(), callback=lambda i, n, pv: calls.append((i, n, pv)))
    assert [(i, n) for i, n, _ in calls] == [(1, 3), (2, 3), (3, 3)]
    for _, _, pv in calls:
        assert pv.shape == (H, W, 3) and pv.dtype == np.float32 and 0 <= pv.min() and pv.max() <= 1
    assert out.shape == (H, W, 3)
    assert smp.info.mode == "diffusion" and smp.info.steps == 3


@needs_diffusers
def test_cancel_midway_and_before_start(prior):
    smp = GuidedSampler(_cfg(), prior=prior)
    stop = threading.Event()
    calls = []

    def cb(i, n, pv):
        calls.append(i)
        if i == 2:
            stop.set()

    with pytest.raises(Cancelled):
        smp.run(_observation(), _cfg(steps=5), callback=cb, cancel=stop)
    assert calls == [1, 2]
    calls.clear()
    with pytest.raises(Cancelled):
        smp.run(_observation(), callback=cb, cancel=lambda: True)
    assert calls == []


@needs_diffusers
def test_dps_gradient_reaches_the_latent_and_descends(prior):
    obs = _observation(16, 24)
    # Q and a 3-band pyramid in the loss; the exact mosaic (the dense-gradient one is a surrogate backward
    # pass, by design not the gradient of L)
    cfg = _cfg(levels=2, k=20.0, dense_gradient=False)
    plan = make_plan(obs, cfg)
    assert plan.quantise and plan.levels == 2
    data = GuidedSampler.data_term(obs, plan, cfg)
    ladder = make_ladder(prior, 3, cfg.t_start)
    z = torch.randn(1, 4, 2, 3, generator=torch.Generator().manual_seed(0))
    t = int(ladder.timesteps[0])

    def loss_of(z_in):  # L = ‖P(√w̃ (A(clamp(D(ẑ₀))) − Y))‖ through decoder and UNet
        _, z0 = prior.predict(z_in, t)
        return data.norm(prior.decode(z0)[..., :16, :24].clamp(0.0, 1.0))

    with torch.enable_grad():
        zg = z.clone().requires_grad_(True)
        (grad,) = torch.autograd.grad(loss_of(zg), zg)
    assert grad.shape == z.shape and torch.isfinite(grad).all() and grad.norm() > 0

    def step(rule, z_in):
        return rule.step(prior, ladder, data, z_in, 0, ladder.sigma(0, z_in))[0]

    # the rule's step is DDIM minus s·∇_{Z_t} L
    s = 2.0
    rule = LatentDPSGuidance(s, (16, 24))
    unguided = LatentDPSGuidance(0.0, (16, 24))
    torch.testing.assert_close(step(unguided, z) - step(rule, z), s * grad, rtol=1e-3, atol=1e-5)
    assert unguided.losses == []  # s = 0: no loss, no backward pass
    assert float(rule.losses[-1]) == pytest.approx(float(loss_of(z)), rel=1e-5)
    # a small step against the gradient lowers the loss the rule records, one along it raises it, at the
    # rate |∇L| (the gradient is that of L with respect to Z_t). Q's steep flanks make a finite difference
    # meaningless, so the rate is checked on the smooth data term (no Q).
    smooth = _cfg(levels=2, quantise=False, dense_gradient=False)
    data_s = GuidedSampler.data_term(obs, make_plan(obs, smooth), smooth)

    def loss_s(z_in):
        _, z0 = prior.predict(z_in, t)
        return data_s.norm(prior.decode(z0)[..., :16, :24].clamp(0.0, 1.0))

    with torch.enable_grad():
        zg = z.clone().requires_grad_(True)
        (grad_s,) = torch.autograd.grad(loss_s(zg), zg)
    eps = 1e-3
    d = eps * grad_s / grad_s.norm()
    rule_s = LatentDPSGuidance(s, (16, 24))
    for z_in in (z - d, z, z + d):
        rule_s.step(prior, ladder, data_s, z_in, 0, ladder.sigma(0, z_in))
    lower, mid, higher = rule_s.losses
    assert lower < mid < higher
    assert (higher - lower) / (2 * eps) == pytest.approx(float(grad_s.norm()), rel=0.1)
    # the sampler uses a rule it is given, and the data term of the config: one loss per step
    rule.losses.clear()
    GuidedSampler(cfg, prior=prior, guidance=rule).run(obs)
    assert len(rule.losses) == 3 and all(math.isfinite(v) and v > 0 for v in rule.losses)


@needs_diffusers
def test_guidance_strength_changes_the_result(prior):
    obs = _observation()
    rule = LatentDPSGuidance(0.0, (H, W))
    unguided = GuidedSampler(_cfg(s=0.0), prior=prior, guidance=rule).run(obs)
    assert rule.losses == []
    np.testing.assert_array_equal(GuidedSampler(_cfg(s=0.0), prior=prior).run(obs), unguided)  # s from the config
    guided = GuidedSampler(_cfg(s=5.0), prior=prior).run(obs)
    assert np.abs(guided - unguided).max() > 1e-4


@needs_diffusers
def test_start_latent_is_the_noised_encoding_of_y0(prior):
    seen = []

    class Spy:
        """The prior, recording what the UNet is asked at each step."""

        def __getattr__(self, name):
            return getattr(prior, name)

        def predict(self, z_t, t):
            seen.append((z_t.detach().clone(), t))
            return prior.predict(z_t, t)

    obs = _observation(16, 24)
    cfg = _cfg(steps=2, t_start=40 / 255, s=0.0, seed=5)
    smp = GuidedSampler(cfg, prior=Spy())
    smp.run(obs)
    t_s = start_timestep(prior.alphas_cumprod, 40 / 255)
    assert [t for _, t in seen] == [t_s, round(t_s / 2)]  # t_s from the pixel σ, then evenly down
    y0 = start_estimate(obs, smp.info.plan.mosaic, smp.info.plan.cast, cfg.demosaic)
    with torch.no_grad():
        z_enc = prior.encode(torch.from_numpy(y0).clamp(0, 1).permute(2, 0, 1)[None])
    noise = torch.randn(z_enc.shape, generator=torch.Generator().manual_seed(5))
    a = prior.alpha_bar(t_s)
    torch.testing.assert_close(seen[0][0], a**0.5 * z_enc + (1 - a) ** 0.5 * noise)


@needs_diffusers
def test_warm_start_uses_the_given_image(prior):
    # init (the previous result) replaces Y₀; at a low t_s the result must follow it
    obs = _observation(16, 24)
    smp = GuidedSampler(_cfg(steps=1, t_start=2 / 255, s=0.0), prior=prior)
    dark = smp.run(obs, init=np.zeros((16, 24, 3), np.float32))
    bright = smp.run(obs, init=np.ones((16, 24, 3), np.float32))
    assert np.abs(dark - bright).mean() > 1e-3
    with pytest.raises(ParameterError, match="init has shape"):
        smp.run(obs, init=np.zeros((8, 8, 3), np.float32))


@needs_diffusers
def test_monochrome_observation(prior):
    rule = LatentDPSGuidance(1.0, (H, W))
    previews = []
    out = GuidedSampler(_cfg(), prior=prior, guidance=rule).run(_observation(cfa=None), callback=lambda i, n, pv: previews.append(pv))
    assert out.shape == (H, W) and out.dtype == np.float32  # M is off: a gray frame (the RGB decode averaged)
    assert np.isfinite(out).all() and 0 <= out.min() and out.max() <= 1
    assert [pv.shape for pv in previews] == [(H, W)] * 3
    assert len(rule.losses) == 3 and all(math.isfinite(v) for v in rule.losses)


@needs_diffusers
def test_divergence_is_one_sentence(prior):
    rule = LatentDPSGuidance(math.inf, (H, W))  # a step no latent survives
    with pytest.raises(ParameterError) as err:
        GuidedSampler(_cfg(), prior=prior, guidance=rule).run(_observation())
    msg = str(err.value)
    assert "diverged" in msg and "step 1 of 3" in msg
    assert msg.endswith(".") and ". " not in msg and "\n" not in msg


@needs_diffusers
def test_hqs_and_t_start_zero_are_rejected_with_the_sd_prior(prior):
    obs = _observation()
    with pytest.raises(ParameterError, match='set guidance = "dps"'):
        GuidedSampler(_cfg(guidance="hqs"), prior=prior).run(obs)
    with pytest.raises(ParameterError, match='set guidance = "dps"'):
        GuidedSampler.guidance_for(_cfg(guidance="hqs"), prior, (H, W))
    assert isinstance(GuidedSampler.guidance_for(_cfg(), prior, (H, W)), LatentDPSGuidance)
    calls = []
    with pytest.raises(ParameterError, match="t_s above 0"):
        GuidedSampler(_cfg(t_start=0.0), prior=prior).run(obs, callback=lambda *a: calls.append(a))
    assert calls == []


@needs_diffusers
def test_run_loads_the_model_from_a_guided_config(model_dir):
    g = _cfg(model_path=str(model_dir), steps=2, device="cpu")
    smp = GuidedSampler(g)
    out = smp.run(_observation())
    assert out.shape == (H, W, 3) and np.isfinite(out).all()
    first = load_prior(g, 3)
    assert first.source == str(model_dir) and load_prior(g, 3) is first  # loaded once, then reused
    np.testing.assert_array_equal(GuidedSampler(g, prior=first).run(_observation()), out)
    with pytest.raises(ParameterError, match="needs its weights"):
        GuidedSampler(_cfg(model_path=None)).run(_observation())


@needs_diffusers
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("dtype", ["float16", "bfloat16"])
def test_cuda_mixed_precision_matches_float32(model_dir, dtype):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    obs = _observation(32, 48)
    cfg = _cfg(device="cuda")
    ref = GuidedSampler(cfg, prior=LatentDiffusionPrior.from_pretrained(model_dir, device="cuda")).run(obs)
    half = GuidedSampler(cfg.replace(dtype=dtype),
                         prior=LatentDiffusionPrior.from_pretrained(model_dir, device="cuda", dtype=dtype)).run(obs)
    assert np.isfinite(half).all()
    assert np.abs(half - ref).mean() < 0.02  # half precision changes pixels by ~1e-3 on these tiny nets
