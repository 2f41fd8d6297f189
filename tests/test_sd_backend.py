"""The optional latent-diffusion backend (spikeview[sd]) on tiny randomly initialised models.

The models are built from configs (as diffusers' own tests do), saved with ``save_pretrained`` and
loaded back through :meth:`LatentDiffusionPrior.from_pretrained`; no weights are downloaded. The VAE
has four blocks like SD's, so its downsampling factor is SD's 8 and odd frame sizes get padded.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
import sys
import threading

import numpy as np
import pytest
import torch

from spikeview.errors import Cancelled, InputFileError, ParameterError
from spikeview.guided.latent import DDIMLadder, LatentConfig, LatentGuidedSampler
from spikeview.guided.observation import Observation
from spikeview.guided.priors.base import PriorUnavailableError

HAS_DIFFUSERS = importlib.util.find_spec("diffusers") is not None
needs_diffusers = pytest.mark.skipif(not HAS_DIFFUSERS, reason='needs the optional extra: pip install "spikeview[sd]"')

TINY_UNET = dict(
    sample_size=8, in_channels=4, out_channels=4, block_out_channels=(32, 64), layers_per_block=1,
    down_block_types=("DownBlock2D", "CrossAttnDownBlock2D"), up_block_types=("CrossAttnUpBlock2D", "UpBlock2D"),
    cross_attention_dim=32, attention_head_dim=(2, 4), use_linear_projection=True, norm_num_groups=32,
)
TINY_VAE = dict(
    in_channels=3, out_channels=3, down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4,
    block_out_channels=(32, 32, 32, 32), layers_per_block=1, latent_channels=4, norm_num_groups=32, sample_size=32,
)
# SD 2.1's schedule (scheduler/scheduler_config.json of stabilityai/stable-diffusion-2-1)
SD21_SCHEDULER = dict(
    num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear", clip_sample=False,
    set_alpha_to_one=False, steps_offset=1, prediction_type="v_prediction",
)
H, W = 13, 22  # not multiples of 8: padded to 16 x 24, latent 2 x 3
FAST = dict(steps=3, t_start=0.6, s=1.0, device="cpu")


def _tiny_modules(seed: int = 0, **unet_changes):
    import diffusers

    torch.manual_seed(seed)
    unet = diffusers.UNet2DConditionModel(**(TINY_UNET | unet_changes))
    vae = diffusers.AutoencoderKL(**TINY_VAE)
    return unet, vae, diffusers.DDIMScheduler(**SD21_SCHEDULER)


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

    p = LatentDiffusionPrior(prior.unet, prior.vae, SD21_SCHEDULER | {"prediction_type": prediction_type}, device="cpu")
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


def test_start_timestep_from_fraction_and_from_pixel_sigma():
    betas = torch.linspace(0.00085**0.5, 0.012**0.5, 1000, dtype=torch.float64) ** 2
    abar = torch.cumprod(1 - betas, 0)
    assert LatentConfig(t_start=0.5).start_timestep(abar) == 500  # round(0.5 * 999)
    assert LatentConfig(t_start=1.0).start_timestep(abar) == 999
    sigma = 50 / 255
    t = LatentConfig(sigma_start=sigma).start_timestep(abar)
    target = 1 / (1 + (2 * sigma) ** 2)  # √((1−ᾱ)/ᾱ) = 2σ
    assert abar[t] <= target < abar[t - 1]


def test_latent_config_validates_and_round_trips(tmp_path):
    cfg = LatentConfig(model_path="/models/sd21", steps=30, t_start=0.4, s=0.5, dtype="bfloat16", seed=7)
    path = cfg.save(tmp_path / "sd.toml")
    assert LatentConfig.load(path) == cfg
    with pytest.raises(ParameterError, match="t_start"):
        LatentConfig(t_start=0.0)
    with pytest.raises(ParameterError, match="dtype"):
        LatentConfig(dtype="float64")


def test_guided_config_maps_onto_the_latent_sampler():
    from spikeview.guided.config import GuidedConfig

    g = GuidedConfig(prior="sd", guidance="dps", model_path="/m", steps=12, t_start=40 / 255, s=0.7, zeta=0.25, seed=3, k=20.0,
                     levels=2, dense_gradient=False, use_cast=False)
    cfg = LatentConfig.coerce(g)
    # GuidedConfig.levels counts band-pass levels (L = 2 → 3 bands); LatentConfig.levels counts bands
    assert (cfg.model_path, cfg.steps, cfg.s, cfg.ddim_eta, cfg.seed, cfg.k, cfg.levels) == ("/m", 12, 0.7, 0.25, 3, 20.0, 3)
    assert cfg.sigma_start == pytest.approx(40 / 255)
    assert cfg.dense_gradient is False and cfg.cast is False
    with pytest.raises(ParameterError, match='guidance = "dps"'):
        LatentConfig.coerce(GuidedConfig(prior="sd", guidance="hqs"))
    with pytest.raises(ParameterError, match="t_start = 0"):
        LatentConfig.coerce(GuidedConfig(prior="sd", guidance="dps", t_start=0.0))


# ------------------------------------------------------------------------------------- sampling
@needs_diffusers
def test_run_shape_range_and_padding(prior):
    sampler = LatentGuidedSampler(prior)
    for h, w in ((H, W), (16, 24)):  # padded and not
        out = sampler.run(_observation(h, w), LatentConfig(**FAST))
        assert out.shape == (h, w, 3) and out.dtype == np.float32
        assert np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0
    assert len(sampler.losses) == 3 and all(math.isfinite(v) and v > 0 for v in sampler.losses)


@needs_diffusers
def test_run_is_deterministic_for_a_seed(prior):
    sampler = LatentGuidedSampler(prior)
    obs = _observation()
    cfg = LatentConfig(**FAST, ddim_eta=0.5)  # fresh noise every step too
    a = sampler.run(obs, cfg)
    b = sampler.run(obs, cfg)
    c = sampler.run(obs, cfg.replace(seed=1))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-4


@needs_diffusers
def test_callback_every_step_with_preview(prior):
    calls = []
    out = LatentGuidedSampler(prior).run(_observation(), LatentConfig(**FAST),
                                         callback=lambda i, n, pv: calls.append((i, n, pv)))
    assert [(i, n) for i, n, _ in calls] == [(1, 3), (2, 3), (3, 3)]
    for _, _, pv in calls:
        assert pv.shape == (H, W, 3) and pv.dtype == np.float32 and 0 <= pv.min() and pv.max() <= 1
    assert out.shape == (H, W, 3)


@needs_diffusers
def test_cancel_midway_and_before_start(prior):
    sampler = LatentGuidedSampler(prior)
    stop = threading.Event()
    calls = []

    def cb(i, n, pv):
        calls.append(i)
        if i == 2:
            stop.set()

    with pytest.raises(Cancelled):
        sampler.run(_observation(), LatentConfig(**FAST | {"steps": 5}), callback=cb, cancel=stop)
    assert calls == [1, 2]
    calls.clear()
    with pytest.raises(Cancelled):
        sampler.run(_observation(), LatentConfig(**FAST), callback=cb, cancel=lambda: True)
    assert calls == []


@needs_diffusers
def test_dps_gradient_reaches_the_latent_and_descends(prior):
    sampler = LatentGuidedSampler(prior)
    obs = _observation(16, 24)
    cfg = LatentConfig(**FAST)
    fm = sampler.forward_model(obs, cfg, 16, 24)
    y = torch.from_numpy(obs.y)[None, None]
    z = torch.randn(1, 4, 2, 3, generator=torch.Generator().manual_seed(0))
    g = sampler.guided_prediction(prior, z, 300, fm, y, (16, 24))
    assert g.grad is not None and g.grad.shape == z.shape
    assert torch.isfinite(g.grad).all() and g.grad.norm() > 0
    # a small step against the gradient lowers the loss: the gradient is that of L w.r.t. Z_t
    step = 1e-2 * g.grad / g.grad.norm()
    lower = sampler.guided_prediction(prior, z - step, 300, fm, y, (16, 24)).loss
    higher = sampler.guided_prediction(prior, z + step, 300, fm, y, (16, 24)).loss
    assert lower < g.loss < higher
    # no guidance: no gradient, no loss, no decoder call needed
    g0 = sampler.guided_prediction(prior, z, 300, fm, y, (16, 24), guide=False, decode=False)
    assert g0.grad is None and g0.x0 is None


@needs_diffusers
def test_guidance_strength_changes_the_result(prior):
    sampler = LatentGuidedSampler(prior)
    obs = _observation()
    unguided = sampler.run(obs, LatentConfig(**FAST | {"s": 0.0}))
    assert sampler.losses == []
    guided = sampler.run(obs, LatentConfig(**FAST | {"s": 5.0}))
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

    y0 = np.full((16, 24, 3), 0.3, np.float32)
    LatentGuidedSampler(Spy()).run(_observation(16, 24), LatentConfig(steps=2, t_start=0.4, s=0.0, seed=5), y0=y0)
    assert [t for _, t in seen] == [400, 200]  # t_s = round(0.4 * 999), then evenly down
    with torch.no_grad():
        z_enc = prior.encode(torch.from_numpy(y0).permute(2, 0, 1)[None])
    noise = torch.randn(z_enc.shape, generator=torch.Generator().manual_seed(5))
    a = prior.alpha_bar(400)
    torch.testing.assert_close(seen[0][0], a**0.5 * z_enc + (1 - a) ** 0.5 * noise)


@needs_diffusers
def test_start_point_uses_the_given_estimate(prior):
    # t_s = 0 would be no noise at all; a one-step run from t_s ≈ 1 is dominated by noise, so compare
    # two start images at a low t_s instead: the result must follow Y₀.
    sampler = LatentGuidedSampler(prior)
    obs = _observation(16, 24)
    cfg = LatentConfig(steps=1, t_start=0.01, s=0.0, device="cpu")
    dark = sampler.run(obs, cfg, y0=np.zeros((16, 24, 3), np.float32))
    bright = sampler.run(obs, cfg, y0=torch.ones(16, 24, 3))
    assert np.abs(dark - bright).mean() > 1e-3
    with pytest.raises(ParameterError, match=r"y0 must be an \(H, W, 3\) image matching"):
        sampler.run(obs, cfg, y0=np.zeros((8, 8, 3), np.float32))


@needs_diffusers
def test_any_forward_model_with_a_loss_is_accepted(prior):
    class PlainL2:
        """A forward model with only ``loss``: the green channel against the observation."""

        def __init__(self):
            self.calls = 0

        def loss(self, x, y):
            self.calls += 1
            return torch.linalg.vector_norm(x[:, 1:2] - y)

    fm = PlainL2()
    obs = {"y": _observation().y}
    out = LatentGuidedSampler(prior).run(obs, LatentConfig(**FAST), forward=fm, y0=np.full((H, W, 3), 0.5, np.float32))
    assert out.shape == (H, W, 3) and fm.calls == 3
    with pytest.raises(ParameterError, match="no start estimate"):
        LatentGuidedSampler(prior).run(obs, LatentConfig(**FAST), forward=fm)


@needs_diffusers
def test_monochrome_observation(prior):
    out = LatentGuidedSampler(prior).run(_observation(cfa=None), LatentConfig(**FAST))
    assert out.shape == (H, W, 3) and np.isfinite(out).all()


@needs_diffusers
def test_run_loads_the_model_from_a_guided_config(model_dir):
    from spikeview.guided.config import GuidedConfig

    sampler = LatentGuidedSampler()
    g = GuidedConfig(prior="sd", guidance="dps", model_path=str(model_dir), steps=2, t_start=60 / 255)
    out = sampler.run(_observation(), g)
    first = sampler.prior
    sampler.run(_observation(), g)
    assert out.shape == (H, W, 3) and sampler.prior is first  # loaded once, then reused
    with pytest.raises(ParameterError, match="model_path is not set"):
        LatentGuidedSampler().run(_observation(), LatentConfig(steps=2))


@needs_diffusers
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("dtype", ["float16", "bfloat16"])
def test_cuda_mixed_precision_matches_float32(model_dir, dtype):
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    obs = _observation(32, 48)
    ref = LatentGuidedSampler(LatentDiffusionPrior.from_pretrained(model_dir, device="cuda")).run(obs, LatentConfig(**FAST))
    half = LatentGuidedSampler(LatentDiffusionPrior.from_pretrained(model_dir, device="cuda", dtype=dtype)).run(
        obs, LatentConfig(**FAST))
    assert np.isfinite(half).all()
    assert np.abs(half - ref).mean() < 0.02  # half precision changes pixels by ~1e-3 on these tiny nets

