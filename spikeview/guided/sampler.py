"""The guided sampler (SpikeDiff): a small driver over prior, schedule, guidance and forward model.

Parts (diffusers style, each swappable):

* **prior**: a :class:`~spikeview.guided.priors.base.DenoiserPrior` (``denoise(x, σ)``), FFDNet by default;
* **schedule**: :class:`~spikeview.guided.schedule.VESchedule` (``set_timesteps`` then ``step``);
* **guidance**: :class:`~spikeview.guided.guidance.DPSGuidance` or :class:`~spikeview.guided.guidance.HQSGuidance`;
* **forward model**: :class:`spikeview.ops.forward.ForwardModel` (A = Q∘C∘M) inside a
  :class:`~spikeview.guided.likelihood.DataTerm` (noise weights + multiscale loss).

:meth:`GuidedSampler.run` reconstructs one window:

1. plan the window (:func:`~spikeview.guided.plan.make_plan`); a window that needs no diffusion
   returns the one-pass baseline or TFP, one whose counts did not change returns the previous result;
2. ``Y₀`` = demosaicked (``params.demosaic``), colour-corrected TFP; σ_obs,c = its data-derived noise per
   channel (× ``sigma_scale``);
3. start: ``Z = Y₀ + σ_add·z`` with ``σ_add = t_start`` (or the top-up ``sqrt(t_start² − σ_obs²)``),
   the prior told the total ``σ'_c = sqrt(σ_obs,c² + σ_add,c²)`` (capped at the prior's
   ``sigma_max``). A warm start replaces ``Y₀`` by the previous result and σ_obs by 0;
4. ``steps`` guided steps down a geometric per-channel σ ladder from σ' to ``sigma_end``, then 0;
   after every step ``callback(step, total, preview)`` gets x̂₀ as an image, and the cancel flag is
   checked before every step (:class:`spikeview.errors.Cancelled`);
5. the last x̂₀, clamped to [0, 1], is the frame (with gray-world gains and Q on, its channel means are kept at
   the data's: :mod:`spikeview.guided.balance`).

Everything random comes from one ``torch.Generator`` seeded by ``params.seed``: a run is
deterministic for a seed. Graphs live for one step only (inputs are detached between steps).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from spikeview.errors import Cancelled, ParameterError, cancel_scope, is_cancelled
from spikeview.guided.baseline import baseline, start_estimate, to_image, to_tensor
from spikeview.guided.config import GuidedConfig
from spikeview.guided.device import module_device
from spikeview.guided.guidance import DPSGuidance, GuidanceRule, HQSGuidance
from spikeview.guided.likelihood import DataTerm
from spikeview.guided.observation import Observation
from spikeview.guided import precision as prec
from spikeview.guided.plan import Plan, make_plan
from spikeview.guided.priors.base import DenoiserPrior
from spikeview.guided.schedule import ve_ladder
from spikeview.ops.forward import ForwardModel

SD_NEEDS_DPS = ('the sd prior is guided by gradients through the model: set guidance = "dps" '
                "(--guidance dps; in the app: Guidance rule ▸ DPS).")

#: ``callback(step, total, preview)``: step in 1..total, preview an (H, W, 3)/(H, W) float32 image of x̂₀
Callback = Callable[[int, int, np.ndarray], Any]


@functools.lru_cache(maxsize=4)
def _load_ffdnet(color: bool, path: str | None, device: str = "cpu") -> DenoiserPrior:
    from spikeview.guided.priors.ffdnet import FFDNetDenoiser

    net = FFDNetDenoiser(color=color, weights=path)
    return net if device == "cpu" else net.to(device)


@functools.lru_cache(maxsize=2)
def _load_sd(path: str, device: str, dtype: str) -> Any:
    from spikeview.guided.priors.sd import LatentDiffusionPrior

    return LatentDiffusionPrior.from_pretrained(path, device=device, dtype=dtype)


def load_prior(params: GuidedConfig, channels: int) -> Any:
    """The prior of ``params`` (the one place that picks it), loaded once and cached.

    ``"ffdnet"``: the pixel-space denoiser for ``channels`` (3 RGB, 1 gray), the packaged weights or
    ``params.model_path``, on ``params.device`` (:func:`spikeview.guided.device.resolve_device`). ``"sd"``: the latent model in the diffusers folder ``params.model_path``
    on ``params.device`` in ``params.dtype``.

    Raises:
        PriorUnavailableError: the weights are missing.
        ParameterError: ``prior = "sd"`` without a model folder, or a device that is not there.
    """
    from spikeview.guided.device import resolve_device

    if params.prior == "sd":
        if not params.model_path:
            raise ParameterError(
                "the sd prior needs its weights: pass --model (in the app: Model weights) pointing to a local "
                "diffusers-format Stable Diffusion 2.x folder (unet/, vae/, scheduler/)."
            )
        return _load_sd(str(params.model_path), params.device, params.dtype)
    return _load_ffdnet(channels == 3, params.model_path, str(resolve_device(params.device)))


def is_latent(prior: Any) -> bool:
    """A latent-diffusion prior (it has a VAE) rather than a pixel-space denoiser."""
    return getattr(prior, "vae_factor", None) is not None


@dataclass
class RunInfo:
    """What the last :meth:`GuidedSampler.run` did (for logs, benchmarks and the GUI).

    Attributes:
        plan: the window's plan.
        mode: ``"diffusion"``, ``"baseline"``, ``"tfp"`` or ``"reused"``.
        steps: prior calls made by the sampler.
        sigma_start: per-channel σ' of the first prior call (fractions of 1).
        seconds: wall-clock time of the run.
        precision: the prior's arithmetic (``guided.precision`` resolved for this CPU or GPU).
        device: where the window ran (``"cpu"``, ``"cuda:0"``).
    """

    plan: Plan | None = None
    mode: str = ""
    steps: int = 0
    sigma_start: list[float] = field(default_factory=list)
    seconds: float = 0.0
    precision: str = ""
    device: str = ""


class GuidedSampler:
    """Driver of the guided reconstruction (see the module docstring).

    Args:
        params: settings; the guidance rule and the prior follow from them unless given.
        prior: a denoiser to use instead of loading ``params.prior`` (e.g. a stand-in in tests);
            it must have as many channels as the frames (3 for Bayer, 1 for monochrome).
        guidance: a guidance rule to use instead of the one ``params`` names.
    """

    def __init__(self, params: GuidedConfig | None = None, *, prior: DenoiserPrior | None = None,
                 guidance: GuidanceRule | None = None):
        self.params = params if params is not None else GuidedConfig()
        self._prior = prior
        self._guidance = guidance
        self.info = RunInfo()

    # -------------------------------------------------------------------------------- parts
    def prior_for(self, channels: int, params: GuidedConfig) -> Any:
        if self._prior is not None:
            if not is_latent(self._prior) and getattr(self._prior, "channels", channels) != channels:
                raise ParameterError(
                    f"the given prior works on {self._prior.channels} channel(s) but these frames have {channels}; "
                    "pass a matching prior (RGB for Bayer streams, gray for monochrome)."
                )
            return self._prior
        return load_prior(params, channels)

    @staticmethod
    def guidance_for(params: GuidedConfig, prior: Any = None, size: tuple[int, int] = (0, 0)) -> Any:
        """The guidance rule: DPS or HQS for a pixel prior, latent DPS for a latent prior."""
        if is_latent(prior):
            if params.guidance != "dps":
                raise ParameterError(SD_NEEDS_DPS)
            from spikeview.guided.latent import LatentDPSGuidance

            return LatentDPSGuidance(params.s, size)
        if params.guidance == "dps":
            return DPSGuidance(params.s)
        return HQSGuidance(params.lam, params.data_steps, params.renoise, params.s)

    @classmethod
    def forward_model(cls, obs: Observation, plan: Plan, params: GuidedConfig) -> ForwardModel:
        """A = Q∘C∘M for the plan (M off = gray frame, C off = no cast, Q as the plan decided)."""
        alpha = obs.alpha if (plan.cast and obs.alpha is not None) else None
        fm = ForwardModel(obs.cfa if plan.mosaic else None, obs.window, alpha=alpha,
                          eta=obs.eta if alpha is not None else 1.0, k=params.k if plan.quantise else None,
                          dense_grad=params.dense_gradient, cast=alpha is not None, bands=plan.levels + 1, norm="l2",
                          quantise_window=obs.quantise_window())
        # a pooled observation's value is its spikes over Δτ_eff ticks, so Q rounds to its 1/Δτ_eff steps
        # (Observation.quantise_window says why); Δτ_eff also enters the noise weights (obs.variance)
        return fm

    @classmethod
    def data_term(cls, obs: Observation, plan: Plan, params: GuidedConfig, device: Any = None) -> DataTerm:
        """The weighted multiscale data term of one window (forward model, noise weights, pyramid), on
        ``device`` (default: the CPU)."""
        fm = cls.forward_model(obs, plan, params)
        y = torch.from_numpy(obs.y)[None, None]
        var = obs.variance()
        if not params.noise_weights:
            var = np.full(obs.shape, float(var.mean()), dtype=np.float32)
        data = DataTerm(fm, y, torch.from_numpy(var)[None, None], plan.levels)  # σ_n² measured here, on the CPU
        if device is not None and torch.device(device).type != "cpu":
            _to_device(data, device)
        return data

    # ---------------------------------------------------------------------------------- run
    def run(self, observation: Observation, params: GuidedConfig | None = None, callback: Callback | None = None,
            cancel: Any = None, *, init: np.ndarray | None = None, previous: np.ndarray | None = None,
            plan: Plan | None = None, noise: torch.Tensor | None = None) -> np.ndarray:
        """Reconstruct the frame of one window.

        Args:
            observation: the window (:meth:`Observation.from_source`).
            params: settings for this run (default: the sampler's ``params``).
            callback: ``callback(step, total, preview)`` after every step (preview = x̂₀ image).
            cancel: a ``threading.Event``-like object (``is_set()``), a callable returning True to
                stop, or a bool; checked before every step.
            init: warm start: a previous result ``(H, W, 3)``/``(H, W)`` in [0, 1] to re-noise to
                ``t_start`` instead of Y₀.
            previous: the previous window's result, returned as is when the plan finds that the
                counts did not change.
            plan: a precomputed plan (default: :func:`make_plan`).
            noise: the start noise ``(1, C, H, W)`` (default: drawn from the seed); a tile of a tiled
                run gets its cut of the whole frame's field (:mod:`spikeview.guided.tiles`).

        Returns:
            ``(H, W, 3)`` float32 RGB in [0, 1] for a Bayer stream (``(H, W)`` when M is off).

        Raises:
            Cancelled: the cancel flag was set (checked before every step and, through
                :func:`~spikeview.errors.cancel_scope`, between the layers and strips of every
                prior pass, so a 1000×1000 run stops within one layer).
            ParameterError: inconsistent settings (e.g. a prior with the wrong channels).
        """
        with cancel_scope(cancel):
            return self._run(observation, params, callback, cancel, init=init, previous=previous, plan=plan, noise=noise)

    def _run(self, observation: Observation, params: GuidedConfig | None, callback: Callback | None, cancel: Any, *,
             init: np.ndarray | None, previous: np.ndarray | None, plan: Plan | None,
             noise: torch.Tensor | None) -> np.ndarray:
        """:meth:`run` inside its cancel scope."""
        p = params if params is not None else self.params
        if (p.prior == "sd" or is_latent(self._prior)) and p.guidance != "dps" and self._guidance is None:
            raise ParameterError(SD_NEEDS_DPS)
        t0 = time.perf_counter()
        plan = plan if plan is not None else make_plan(observation, p)
        info = RunInfo(plan=plan)
        self.info = info
        if is_cancelled(cancel):
            raise Cancelled("guided reconstruction cancelled before the first step")
        channels = 3 if plan.mosaic else 1
        if plan.reuse and previous is not None and (previous.ndim == 3) == (channels == 3):
            info.mode, info.seconds = "reused", time.perf_counter() - t0
            return previous.astype(np.float32, copy=True)
        if not plan.diffusion:
            if plan.fallback == "tfp":
                out = start_estimate(observation, plan.mosaic, plan.cast, p.demosaic)
            else:
                # the one-pass baseline needs a denoiser: with a latent prior it is the packaged FFDNet
                latent = p.prior == "sd" or is_latent(self._prior)
                denoiser = load_prior(p.replace(prior="ffdnet", model_path=None), channels) if latent else self.prior_for(channels, p)
                out = baseline(observation, denoiser, sigma_scale=p.sigma_scale,
                               use_mosaic=plan.mosaic, use_cast=plan.cast, demosaic=p.demosaic, sigma_map=True)
            info.mode, info.seconds = plan.fallback, time.perf_counter() - t0
            info.precision = "float32" if plan.fallback == "baseline" else ""
            if callback is not None:
                callback(1, 1, out)
            return out
        tm = getattr(plan, "tile_map", None)
        if tm is not None and tm.pays() and init is None and not (p.prior == "sd" or is_latent(self._prior)):
            from spikeview.guided.tiles import run_tiled

            out = run_tiled(self, observation, p, plan, callback, cancel)  # sets info.steps (the frame's steps)
            self.info = info
            info.mode, info.seconds = "tiled", time.perf_counter() - t0
            info.precision = plan.precision
            return self._balanced(out, observation, p, plan)
        out = self._sample(observation, p, plan, channels, callback, cancel, init, noise)
        info.mode, info.seconds = "diffusion", time.perf_counter() - t0
        return self._balanced(out, observation, p, plan)

    @staticmethod
    def _balanced(out: np.ndarray, obs: Observation, p: GuidedConfig, plan: Plan) -> np.ndarray:
        """``out`` with gray-world's colour balance kept where Q is on (:mod:`spikeview.guided.balance`)."""
        if not plan.balance:  # the plan's decision (spikeview.guided.plan: the gains, Q, a profile's correction)
            return out
        from spikeview.guided.balance import keep_balance

        return keep_balance(out, obs)

    def _sample(self, obs: Observation, p: GuidedConfig, plan: Plan, channels: int, callback: Callback | None,
                cancel: Any, init: np.ndarray | None, noise: torch.Tensor | None = None) -> np.ndarray:
        """The one sampling loop, for a pixel-space denoiser (VE schedule) and a latent model (DDIM) alike: what
        differs between the two is one strategy object (:class:`PixelSpace`, :class:`LatentSpaceStrategy`)."""
        prior = self.prior_for(channels, p)
        space: SampleSpace = LatentSpaceStrategy(prior) if is_latent(prior) else PixelSpace(prior)
        self.info.device = space.device_label
        self.info.precision = space.precision(plan, p)
        rule = self._guidance if self._guidance is not None else self.guidance_for(p, prior, obs.shape)
        gen = torch.Generator().manual_seed(int(p.seed))  # on the CPU: the same numbers on every device
        data = self.data_term(obs, plan, p, space.dev)

        sigma_obs = np.asarray(plan.sigma, dtype=np.float64) * p.sigma_scale
        if sigma_obs.size != channels:
            sigma_obs = np.full(channels, float(np.sqrt(np.mean(sigma_obs ** 2))))
        if init is not None:
            x_start = np.asarray(init, dtype=np.float32)
            if x_start.shape != (obs.shape if channels == 1 else obs.shape + (3,)):
                raise ParameterError(f"init has shape {x_start.shape}, expected that of the frame; pass the previous result of the same stream.")
            sigma_obs = np.zeros(channels)
            t_s = max(p.t_start, p.sigma_end)
        else:
            x_start = start_estimate(obs, plan.mosaic, plan.cast, p.demosaic)
            t_s = p.t_start
        if p.top_up:
            sigma_add = np.sqrt(np.maximum(t_s ** 2 - sigma_obs ** 2, 0.0))
        else:
            sigma_add = np.full(channels, t_s)
        start = to_tensor(x_start).to(space.dev, non_blocking=True)
        schedule = space.setup(data, start, obs.shape, channels, p, t_s, sigma_obs, sigma_add)
        self.info.sigma_start = space.sigma_start
        # the prior's arithmetic per step (bfloat16 only at high noise levels: spikeview.guided.precision)
        layer_prec = prec.step_precisions(self.info.precision, space.step_levels(schedule, p))
        total = p.steps * p.chains
        acc = torch.zeros_like(start)
        for chain in range(p.chains):
            # chains differ in their start noise and in the order of the dihedral transforms
            x = space.start(start, schedule, gen, noise if chain == 0 else None)
            for i in range(p.steps):
                done = chain * p.steps + i
                if is_cancelled(cancel):
                    raise Cancelled(f"guided reconstruction cancelled at step {done + 1} of {total}")
                sigma = schedule.sigma(i, x)
                x, x0 = rule.step(prec.at_precision(prior, layer_prec[i]), schedule, data, x, i, sigma, zeta=p.zeta,
                                  generator=gen, transform=space.transform(p, i, chain))
                if not (bool(torch.isfinite(x).all()) and bool(torch.isfinite(x0).all())):
                    raise ParameterError(_diverged(p, done + 1, total))
                x0 = space.estimate(x0)
                self.info.steps = done + 1
                if callback is not None:
                    callback(done + 1, total, to_image((acc + x0) / (chain + 1)))
            acc = acc + space.finish(x, x0)
        return to_image(acc / p.chains)


class SampleSpace:
    """Where the sampler's loop runs: what a pixel-space denoiser and a latent model do differently (the
    schedule, the start, the dihedral self-ensemble, where estimates accumulate and what a chain returns)."""

    dev: Any
    device_label: str
    sigma_start: list[float]

    def precision(self, plan: Plan, p: GuidedConfig) -> str: ...
    def setup(self, data: DataTerm, start: torch.Tensor, shape: tuple[int, int], channels: int, p: GuidedConfig,
              t_s: float, sigma_obs: np.ndarray, sigma_add: np.ndarray) -> Any: ...
    def step_levels(self, schedule: Any, p: GuidedConfig) -> Any: ...
    def start(self, start: torch.Tensor, schedule: Any, gen: torch.Generator, noise: torch.Tensor | None) -> torch.Tensor: ...
    def transform(self, p: GuidedConfig, i: int, chain: int) -> int | None: ...
    def estimate(self, x0: torch.Tensor) -> torch.Tensor: ...
    def finish(self, x: torch.Tensor, x0: torch.Tensor) -> torch.Tensor: ...


class PixelSpace(SampleSpace):
    """A pixel-space denoiser (FFDNet): the VE σ ladder, start ``Y₀ + σ_add·z``, the dihedral self-ensemble, on
    the prior's device (``guided.device``)."""

    def __init__(self, prior: Any):
        self.prior = prior
        self.dev = module_device(prior)
        self.device_label = str(self.dev)
        self.sigma_start: list[float] = []
        self.add: torch.Tensor | None = None

    def precision(self, plan: Plan, p: GuidedConfig) -> str:
        return plan.precision or prec.resolve_precision(p.precision, device=self.dev)[0]

    def setup(self, data, start, shape, channels, p, t_s, sigma_obs, sigma_add):
        schedule = ve_ladder(sigma_obs, sigma_add, getattr(self.prior, "sigma_max", math.inf), p.sigma_end, p.steps)
        self.sigma_start = schedule.sigmas[0].tolist()
        self.add = torch.as_tensor(sigma_add, dtype=start.dtype, device=self.dev).view(1, -1, 1, 1)
        return schedule

    def step_levels(self, schedule, p):
        return schedule.sigmas[:p.steps].min(axis=1)

    def start(self, start, schedule, gen, noise):
        if noise is not None:  # a tile's cut of the whole frame's start noise
            return start + self.add * noise.to(self.dev, start.dtype)
        return schedule.add_noise(start, self.add, gen)

    def transform(self, p, i, chain):
        return ((i + 3 * chain) % 8) if p.self_ensemble else None

    def estimate(self, x0):
        return x0.float()

    def finish(self, x, x0):
        return x0


class LatentSpaceStrategy(SampleSpace):
    """A latent model (the optional Stable Diffusion prior): its DDIM ladder and VAE, on its own device; estimates
    accumulate on the CPU, no dihedral transforms (the VAE's latents are not equivariant)."""

    def __init__(self, prior: Any):
        self.prior = prior
        self.dev = torch.device("cpu")  # the data term and the start stay on the CPU; the model moves its own tensors
        self.device_label = str(getattr(prior, "device", self.dev))
        self.sigma_start: list[float] = []
        self.space: Any = None

    def precision(self, plan, p):
        return "float32"

    def setup(self, data, start, shape, channels, p, t_s, sigma_obs, sigma_add):
        from spikeview.guided.latent import LatentSpace, make_ladder

        self.space = LatentSpace(self.prior, shape, channels)
        self.sigma_start = [float(t_s)] * channels
        _to_device(data, self.prior.device)
        return make_ladder(self.prior, p.steps, t_s)

    def step_levels(self, schedule, p):
        return p.steps

    def start(self, start, schedule, gen, noise):
        return self.space.start(start, schedule, gen)

    def transform(self, p, i, chain):
        return None

    def estimate(self, x0):
        return x0.float().cpu()

    def finish(self, x, x0):
        return self.space.finish(x)


def _to_device(data: DataTerm, device: Any) -> None:
    """Move a data term to the prior's device (guided.device; a latent model's)."""
    data.forward = data.forward.to(device)
    data.y, data.w = data.y.to(device, non_blocking=True), data.w.to(device, non_blocking=True)
    data.sqrt_w = data.sqrt_w.to(device, non_blocking=True)


def _diverged(p: GuidedConfig, step: int, total: int) -> str:
    """The one sentence of a diverged pixel-space run (non-finite sample at ``step`` of ``total``)."""
    how = f"lower s (now {p.s:g}) or use more steps" if p.guidance == "dps" else f"raise lam (now {p.lam:g}) or use fewer data_steps"
    return (f"the guided sample diverged (non-finite values at step {step} of {total}, guidance = {p.guidance}); "
            f"{how}, or use method tfp for this stream.")

