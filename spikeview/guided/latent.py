"""Posterior sampling with a latent diffusion prior (SpikeDiff with Stable Diffusion, METHOD.md).

The driver wires four separate parts: the prior (:class:`~spikeview.guided.priors.sd.LatentDiffusionPrior`:
UNet, VAE, β schedule), the schedule (:class:`DDIMLadder`: DDIM over ``[0, t_s]``), the guidance
rule (DPS: gradient of the data loss through the decoder and the UNet) and the forward model
(:class:`~spikeview.ops.ForwardModel`, ``A = Q∘C∘M`` with its multiscale loss, or any object with
``loss(x, y)``).

One run, for an observation ``y`` (``(H, W)`` mosaicked TFP) and its start estimate ``Y₀``
(``(H, W, 3)``, demosaicked and colour-corrected):

1. Pad ``Y₀`` (edge replication) to multiples of the VAE factor ``f`` (8 for SD); everything below
   works on the padded grid and the data loss only sees the top-left ``H × W`` crop.
2. ``Z_ts = √ᾱ_ts · E(Y₀) + √(1 − ᾱ_ts) · z`` with ``E`` the VAE encoder's posterior mean (scaled
   by the VAE's ``scaling_factor``, 0.18215 for SD) and ``z ~ N(0, I)`` from the seeded generator.
3. For each DDIM timestep ``t`` (``steps`` of them, evenly spaced from ``t_s`` down to ~0):
   ``ε̂, ẑ₀ = Tweedie(UNet(Z_t, t))``; ``X̂₀ = clamp(D(ẑ₀), 0, 1)`` cropped;
   ``L = ‖P(Y) − P(A(X̂₀))‖`` (non-squared, the DPS reference convention);
   ``Z_{t−1} = DDIM(Z_t; ẑ₀, ε̂) − s · ∇_{Z_t} L``. The gradient runs through the VAE decoder and
   the UNet; the graph is freed every step.
4. The result is ``clamp(D(Z_0), 0, 1)`` cropped to ``H × W``: ``(H, W, 3)`` float32 in [0, 1].

Noise is drawn from a CPU ``torch.Generator`` seeded with ``seed``, so a seed gives the same noise on
every device; on CPU the result is bitwise reproducible, on CUDA up to cuDNN's non-deterministic
kernels.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from spikeview.config import Config, check_range
from spikeview.errors import Cancelled, ParameterError
from spikeview.guided.schedule import StepOutput

#: callback(step, total, preview): ``step`` = steps done (1 … total), ``preview`` = current X̂₀,
#: ``(H, W, 3)`` float32 in [0, 1]
Callback = Callable[[int, int, np.ndarray], None]


def _check_range(name: str, value: float, lo: float, hi: float, *, lo_open: bool = False) -> None:
    check_range(f"LatentConfig.{name}", value, lo, hi, lo_open=lo_open)


@dataclasses.dataclass
class LatentConfig(Config):
    """Settings of one latent-diffusion guided reconstruction (saves to TOML and loads back unchanged).

    Attributes:
        model_path: local diffusers folder of the SD 2.x-family model (see
            :mod:`spikeview.guided.priors.sd`); needed unless the sampler was given a prior.
        steps: DDIM steps (UNet calls) from ``t_s`` down to 0, >= 1.
        t_start: start timestep ``t_s`` as a fraction of the training schedule, in (0, 1]:
            ``t_s = round(t_start · (T − 1))`` (diffusers' img2img "strength").
        sigma_start: alternative to ``t_start`` (used when set): the pixel-space noise level σ
            (fraction of 1, as ``GuidedConfig.t_start``); ``t_s`` is the first timestep whose
            noise-to-signal ratio ``√((1 − ᾱ_t)/ᾱ_t)`` reaches ``2σ`` (σ in the VAE's [−1, 1] range).
        s: DPS step strength: ``Z_{t−1} = DDIM(…) − s · ∇L``, >= 0 (0 = no guidance, plain SDEdit).
        ddim_eta: DDIM stochasticity in [0, 1] (0 = deterministic DDIM, 1 = DDPM-like).
        seed: seed of the sampler's CPU ``torch.Generator``.
        k: soft-quantisation sharpness of Q (>= 0).
        levels: Laplacian-pyramid bands of the loss (0 or 1 = single scale); capped by the frame
            size (at most ``max_pyramid_levels(H, W)``).
        dense_gradient: bilinear dense-gradient variant of the mosaic M.
        cast: apply the colour cast C when the observation has gray-world gains α.
        device: ``"auto"`` (CUDA when available), ``"cpu"`` or ``"cuda"`` (used when the sampler
            loads the model itself).
        dtype: network precision: ``"float32"``, or ``"float16"``/``"bfloat16"`` (CUDA only,
            weights cast + autocast; latents and the loss stay float32).
    """

    model_path: str | None = None
    steps: int = 20
    t_start: float = 0.5
    sigma_start: float | None = None
    s: float = 1.0
    ddim_eta: float = 0.0
    seed: int = 0
    k: float = 50.0
    levels: int = 3
    dense_gradient: bool = True
    cast: bool = True
    device: str = "auto"
    dtype: str = "float32"

    def __post_init__(self) -> None:
        for name in ("steps", "seed", "levels"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ParameterError(f"LatentConfig.{name} = {v!r} must be a whole number.")
        if self.steps < 1:
            raise ParameterError(f"LatentConfig.steps = {self.steps} is out of range: use at least 1 step.")
        if self.levels < 0:
            raise ParameterError(f"LatentConfig.levels = {self.levels} is out of range: use 0 (single scale) or more.")
        _check_range("t_start", self.t_start, 0.0, 1.0, lo_open=True)
        if self.sigma_start is not None:
            _check_range("sigma_start", self.sigma_start, 0.0, math.inf, lo_open=True)
        _check_range("s", self.s, 0.0, math.inf)
        _check_range("ddim_eta", self.ddim_eta, 0.0, 1.0)
        _check_range("k", self.k, 0.0, math.inf)
        if self.dtype not in ("float32", "float16", "bfloat16"):
            raise ParameterError(f"LatentConfig.dtype = {self.dtype!r} is not valid: use float32, float16 or bfloat16.")
        if self.device != "auto" and self.device.split(":")[0] not in ("cpu", "cuda"):
            raise ParameterError(f"LatentConfig.device = {self.device!r} is not valid: use auto, cpu or cuda.")

    @classmethod
    def from_guided(cls, cfg: Any) -> LatentConfig:
        """Map a :class:`~spikeview.guided.config.GuidedConfig` (``prior="sd"``) onto the latent sampler.

        Shared fields carry over (``model_path``, ``steps``, ``s``, ``seed``, ``k``, ``levels``,
        ``dense_gradient``); ``t_start`` (a pixel noise level there) becomes ``sigma_start``; ``zeta``
        becomes ``ddim_eta``; ``use_cast=False`` turns C off.

        Raises:
            ParameterError: ``guidance`` is not ``"dps"``, ``t_start`` is 0, or ``use_mosaic`` is
                ``False`` (the latent sampler has DPS guidance, starts from a noised latent and always
                applies M).
        """
        if cfg.guidance != "dps":
            raise ParameterError(
                f"GuidedConfig.guidance = {cfg.guidance!r} is not available with prior = 'sd': the latent sampler uses DPS; set guidance = \"dps\"."
            )
        if not cfg.t_start > 0:
            raise ParameterError(
                "GuidedConfig.t_start = 0 (start from Y₀ without noise) is not available with prior = 'sd': use a start noise level > 0."
            )
        if getattr(cfg, "use_mosaic", None) is False:
            raise ParameterError("GuidedConfig.use_mosaic = false is not available with prior = 'sd'; leave it unset.")
        return cls(
            model_path=cfg.model_path,
            steps=cfg.steps,
            sigma_start=cfg.t_start,
            s=cfg.s,
            ddim_eta=cfg.zeta,
            seed=cfg.seed,
            k=cfg.k,
            levels=cfg.levels + 1,  # GuidedConfig counts band-pass levels; here bands (L + 1)
            dense_gradient=cfg.dense_gradient,
            cast=getattr(cfg, "use_cast", None) is not False,
        )

    @classmethod
    def coerce(cls, params: Any) -> LatentConfig:
        """A :class:`LatentConfig` from itself, a ``GuidedConfig`` or a dict of its fields."""
        if isinstance(params, LatentConfig):
            return params
        if isinstance(params, Mapping):
            return cls.from_dict(dict(params))
        if hasattr(params, "guidance") and hasattr(params, "prior"):
            return cls.from_guided(params)
        raise ParameterError(f"params must be a LatentConfig, a GuidedConfig or a dict, got {type(params).__name__}.")

    def start_timestep(self, alphas_cumprod: torch.Tensor) -> int:
        """``t_s`` for a schedule with cumulative products ``alphas_cumprod`` (``(T,)``, decreasing)."""
        abar = torch.as_tensor(alphas_cumprod, dtype=torch.float64)
        n = int(abar.numel())
        if self.sigma_start is None:
            return round(self.t_start * (n - 1))
        target = 1.0 / (1.0 + (2.0 * self.sigma_start) ** 2)  # ᾱ with √((1−ᾱ)/ᾱ) = 2σ
        below = torch.nonzero(abar <= target)
        return int(below[0]) if below.numel() else n - 1


class DDIMLadder:
    """DDIM (Song et al. 2021) over ``steps`` timesteps evenly spaced from ``t_start`` down to ~0.

    diffusers' shape: :meth:`set_timesteps` fixes the ladder, :meth:`step` goes from ``z_t`` to
    ``z_{t−1}`` given ``ẑ₀`` and ``ε̂`` and returns both the new sample and ``ẑ₀``. The last step
    lands on the clean latent (``ᾱ = 1``).

    Args:
        alphas_cumprod: ``(T,)`` ``ᾱ_t`` of the model's training schedule.
    """

    def __init__(self, alphas_cumprod: torch.Tensor):
        self.alphas_cumprod = torch.as_tensor(alphas_cumprod, dtype=torch.float64).cpu()
        self.timesteps = np.zeros(0, dtype=np.int64)
        self._abar = np.zeros(0)
        self._abar_prev = np.zeros(0)

    def set_timesteps(self, steps: int, t_start: int) -> np.ndarray:
        """Fix the ladder: ``steps`` distinct integer timesteps, the first ``t_start``.

        Returns:
            ``(steps,)`` int64 descending timesteps (also ``self.timesteps``).
        """
        n = int(self.alphas_cumprod.numel())
        if not 0 <= t_start < n:
            raise ParameterError(f"start timestep {t_start} is outside the model's schedule [0, {n}).")
        ts = np.rint(np.linspace(t_start, 0, steps + 1)[:-1]).astype(np.int64)
        if steps > 1 and np.any(np.diff(ts) >= 0):
            raise ParameterError(
                f"steps = {steps} is more than the start timestep t_s = {t_start} allows: use at most {max(t_start, 1)} steps or a larger t_start."
            )
        abar = self.alphas_cumprod.numpy()
        self.timesteps = ts
        self._abar = abar[ts]
        self._abar_prev = np.concatenate([abar[ts[1:]], [1.0]])
        return ts

    def alpha_bar(self, index: int) -> tuple[float, float]:
        """``(ᾱ_t, ᾱ_{t−1})`` of step ``index`` (``ᾱ_{t−1} = 1`` after the last step)."""
        return float(self._abar[index]), float(self._abar_prev[index])

    def step(self, z0: torch.Tensor, eps: torch.Tensor, index: int, eta: float = 0.0,
             noise: torch.Tensor | None = None) -> StepOutput:
        """``z_{t−1} = √ᾱ_{t−1}·ẑ₀ + √(1 − ᾱ_{t−1} − σ²)·ε̂ + σ·z`` with DDIM's
        ``σ = η·√((1 − ᾱ_{t−1})/(1 − ᾱ_t))·√(1 − ᾱ_t/ᾱ_{t−1})``.

        Args:
            z0: predicted clean latent ẑ₀.
            eps: predicted unit noise ε̂.
            index: step index in ``[0, steps)``.
            eta: DDIM η in [0, 1]; ``noise`` (N(0, I), ``z0``'s shape) is needed when > 0.
            noise: fresh noise.
        """
        if not 0 <= index < len(self.timesteps):
            raise ParameterError(f"step index {index} is outside [0, {len(self.timesteps)}); call set_timesteps first.")
        a, a_prev = self.alpha_bar(index)
        sigma = 0.0
        if eta > 0 and a_prev < 1.0:
            sigma = eta * math.sqrt((1 - a_prev) / (1 - a)) * math.sqrt(max(1 - a / a_prev, 0.0))
        out = math.sqrt(a_prev) * z0 + math.sqrt(max(1 - a_prev - sigma * sigma, 0.0)) * eps
        if sigma > 0:
            if noise is None:
                raise ParameterError("DDIM with eta > 0 needs fresh noise; pass noise=.")
            out = out + sigma * noise
        return StepOutput(out, z0)


class GuidanceOutput(NamedTuple):
    """One DPS evaluation at ``Z_t`` (all detached): ``eps``/``z0`` the Tweedie split, ``x0`` the
    clamped, cropped decoded estimate ``(1, 3, H, W)``, ``grad`` ``∇_{Z_t} L`` (``None`` without
    guidance) and ``loss`` (0-d tensor, ``None`` without guidance)."""

    eps: torch.Tensor
    z0: torch.Tensor
    x0: torch.Tensor | None
    grad: torch.Tensor | None
    loss: torch.Tensor | None


def _get(obs: Any, *names: str) -> Any:
    for name in names:
        if isinstance(obs, Mapping):
            if name in obs:
                return obs[name]
        elif hasattr(obs, name):
            return getattr(obs, name)
    return None


def _is_cancelled(cancel: Any) -> bool:
    if cancel is None:
        return False
    if hasattr(cancel, "is_set"):
        return bool(cancel.is_set())
    return bool(cancel())


class LatentGuidedSampler:
    """DPS posterior sampling in the latent space of an SD 2.x-family model (see the module docstring).

    Args:
        prior: the model (a :class:`~spikeview.guided.priors.sd.LatentDiffusionPrior`); when given,
            the config's ``model_path``, ``device`` and ``dtype`` are not used. ``None`` loads
            ``params.model_path`` on the first :meth:`run` and keeps it while path, device and
            dtype stay the same.
    """

    def __init__(self, prior: Any = None):
        self.prior = prior
        self._loaded_key: tuple[str, str, str] | None = None
        #: data loss ``L`` of each step of the last run (floats)
        self.losses: list[float] = []

    # ------------------------------------------------------------------------------ set-up
    def load_prior(self, cfg: LatentConfig) -> Any:
        """The prior for ``cfg``: the one given at construction, else loaded from ``cfg.model_path``."""
        if self.prior is not None and self._loaded_key is None:
            return self.prior
        if cfg.model_path is None:
            raise ParameterError(
                "model_path is not set: prior = 'sd' needs a local diffusers-format Stable Diffusion 2.x folder (unet/, vae/, scheduler/)."
            )
        key = (str(cfg.model_path), cfg.device, cfg.dtype)
        if self.prior is None or self._loaded_key != key:
            from spikeview.guided.priors.sd import LatentDiffusionPrior

            self.prior = LatentDiffusionPrior.from_pretrained(cfg.model_path, device=cfg.device, dtype=cfg.dtype)
            self._loaded_key = key
        return self.prior

    def forward_model(self, observation: Any, cfg: LatentConfig, height: int, width: int) -> Any:
        """``A`` with its multiscale loss for ``observation`` (its CFA, Δτ, α, η) and ``cfg`` (k, levels, M's gradient)."""
        from spikeview.ops import ForwardModel, max_pyramid_levels

        cfa = _get(observation, "cfa")
        window = _get(observation, "window")
        alpha = _get(observation, "alpha")
        eta = _get(observation, "eta")
        levels = min(max(cfg.levels, 1), max_pyramid_levels(height, width))
        use_cast = cfg.cast and alpha is not None
        return ForwardModel(
            cfa,
            10 if window is None else int(window),
            alpha=None if alpha is None else torch.as_tensor(np.asarray(alpha, dtype=np.float32)),
            eta=1.0 if eta is None else float(eta),
            k=cfg.k,
            dense_grad=cfg.dense_gradient,
            cast=use_cast,
            levels=levels,
            norm="l2",
        )

    # ------------------------------------------------------------------------------- a step
    def guided_prediction(self, prior: Any, z_t: torch.Tensor, t: int, forward: Any, y: torch.Tensor,
                          size: tuple[int, int], guide: bool = True, decode: bool = True) -> GuidanceOutput:
        """Tweedie split at ``Z_t`` and, with ``guide``, ``∇_{Z_t} ‖P(Y) − P(A(X̂₀))‖`` through decoder and UNet.

        Args:
            prior: the latent model.
            z_t: ``(1, C, h, w)`` float32 latent at timestep ``t``.
            forward: the forward model (``loss(x, y)``; ``channels`` 1 makes ``x`` gray).
            y: ``(1, 1, H, W)`` float32 observation on the prior's device.
            size: ``(H, W)`` crop of the decoded image that the observation covers.
            guide: compute the gradient (and the loss).
            decode: decode ``X̂₀`` even without guidance (for previews).
        """
        h, w = size
        with torch.enable_grad() if guide else torch.no_grad():
            z_in = z_t.detach().requires_grad_(guide)
            eps, z0 = prior.predict(z_in, t)
            x0 = grad = loss = None
            if guide or decode:
                x0 = prior.decode(z0)[..., :h, :w].clamp(0.0, 1.0)
            if guide:
                assert x0 is not None
                xin = x0.mean(dim=1, keepdim=True) if getattr(forward, "channels", 3) == 1 else x0
                loss = forward.loss(xin, y)
                (grad,) = torch.autograd.grad(loss, z_in)
        return GuidanceOutput(
            eps.detach(), z0.detach(), None if x0 is None else x0.detach(), grad, None if loss is None else loss.detach()
        )

    # --------------------------------------------------------------------------------- run
    def run(self, observation: Any, params: Any, callback: Callback | None = None, cancel: Any = None, *,
            y0: np.ndarray | torch.Tensor | None = None, forward: Any = None) -> np.ndarray:
        """Sample the colour frame of one observation.

        Args:
            observation: a :class:`~spikeview.guided.observation.Observation` or any object/dict with
                ``y`` (``(H, W)`` float32 mosaicked TFP in [0, 1]), ``cfa``, ``window``, ``alpha``,
                ``eta``; optionally ``y0`` (the start estimate) and ``forward`` (a forward model).
            params: :class:`LatentConfig`, a ``GuidedConfig`` with ``prior="sd"``,
                ``guidance="dps"`` (see :meth:`LatentConfig.from_guided`), or a dict.
            callback: called after every step as ``callback(step, total, preview)`` (see :data:`Callback`).
            cancel: a ``threading.Event`` (or a callable returning ``True``) checked before every step.
            y0: the start estimate Y₀, ``(H, W, 3)`` (or ``(H, W)`` gray) float array/tensor in [0, 1];
                default the observation's ``y0``, else ``forward.initial_estimate(y)`` (bilinear
                demosaic + colour correction).
            forward: the forward model: any object with ``loss(x, y)`` taking ``x`` ``(1, 3, H, W)``
                and ``y`` ``(1, 1, H, W)``; default the observation's, else a
                :class:`~spikeview.ops.ForwardModel` built from the observation and ``params``.

        Returns:
            ``(H, W, 3)`` float32 in [0, 1].

        Raises:
            Cancelled: ``cancel`` was set.
            ParameterError: bad settings or inputs, or the sample diverged (``s`` too large).
        """
        cfg = LatentConfig.coerce(params)
        prior = self.load_prior(cfg)
        dev = prior.device

        y_np = _get(observation, "y")
        if y_np is None:
            raise ParameterError("the observation has no 'y' (the (H, W) mosaicked TFP frame).")
        y_t = torch.as_tensor(np.asarray(y_np.detach().cpu() if isinstance(y_np, torch.Tensor) else y_np, dtype=np.float32))
        if y_t.ndim == 4 and y_t.shape[:2] == (1, 1):
            y_t = y_t[0, 0]
        if y_t.ndim != 2 or min(y_t.shape) < 2:
            raise ParameterError(f"observation y must be an (H, W) mosaicked TFP frame of at least 2x2, got shape {tuple(y_t.shape)}.")
        height, width = (int(v) for v in y_t.shape)
        y_t = y_t.view(1, 1, height, width)

        fm = forward if forward is not None else _get(observation, "forward", "forward_model")
        if fm is None:
            fm = self.forward_model(observation, cfg, height, width)
        if isinstance(fm, torch.nn.Module):
            fm = fm.to(dev)

        start = y0 if y0 is not None else _get(observation, "y0")
        x_start = self._start_image(start, fm, y_t, height, width).to(dev)
        y_dev = y_t.to(dev)

        f = prior.vae_factor
        pad_h, pad_w = (-height) % f, (-width) % f
        if pad_h or pad_w:
            x_start = F.pad(x_start, (0, pad_w, 0, pad_h), mode="replicate")

        ladder = DDIMLadder(prior.alphas_cumprod)
        t_s = cfg.start_timestep(prior.alphas_cumprod)
        timesteps = ladder.set_timesteps(cfg.steps, t_s)
        gen = torch.Generator(device="cpu").manual_seed(cfg.seed)

        with torch.no_grad():
            z_enc = prior.encode(x_start)
        a_s = prior.alpha_bar(int(timesteps[0]))
        noise = torch.randn(z_enc.shape, generator=gen, dtype=torch.float32).to(dev)
        z = math.sqrt(a_s) * z_enc + math.sqrt(1.0 - a_s) * noise

        total = len(timesteps)
        losses: list[torch.Tensor] = []
        guide = cfg.s > 0
        for i, t in enumerate(timesteps):
            if _is_cancelled(cancel):
                raise Cancelled(f"latent sampling cancelled before step {i + 1} of {total}")
            g = self.guided_prediction(prior, z, int(t), fm, y_dev, (height, width), guide=guide, decode=callback is not None)
            fresh = None
            if cfg.ddim_eta > 0:
                fresh = torch.randn(z.shape, generator=gen, dtype=torch.float32).to(dev)
            z = ladder.step(g.z0, g.eps, i, cfg.ddim_eta, fresh).prev_sample
            if g.grad is not None:
                z = z - cfg.s * g.grad
                assert g.loss is not None
                losses.append(g.loss)
            if callback is not None:
                assert g.x0 is not None
                callback(i + 1, total, _to_hwc(g.x0))
        self.losses = [float(v) for v in losses]
        if not bool(torch.isfinite(z).all()):
            raise ParameterError(
                f"the guided sample diverged (non-finite latent) with s = {cfg.s:g} at {total} steps; lower s or use more steps."
            )
        with torch.no_grad():
            x = prior.decode(z)[..., :height, :width].clamp(0.0, 1.0)
        return _to_hwc(x)

    @staticmethod
    def _start_image(start: Any, fm: Any, y: torch.Tensor, height: int, width: int) -> torch.Tensor:
        """Y₀ as ``(1, 3, H, W)`` float32 in [0, 1] (gray is repeated to 3 channels)."""
        if start is None:
            if not hasattr(fm, "initial_estimate"):
                raise ParameterError("no start estimate: pass y0 (the demosaicked, colour-corrected TFP, (H, W, 3)) to run().")
            with torch.no_grad():
                x = fm.initial_estimate(y.to(_device_of(fm))).detach().float().cpu()
        else:
            arr = start.detach().cpu().float() if isinstance(start, torch.Tensor) else torch.as_tensor(np.asarray(start, dtype=np.float32))
            if arr.ndim == 2:
                arr = arr[..., None]
            if arr.ndim != 3 or tuple(arr.shape[:2]) != (height, width) or arr.shape[2] not in (1, 3):
                raise ParameterError(
                    f"y0 must be an (H, W, 3) image matching the observation's {height}x{width}, got shape {tuple(arr.shape)}."
                )
            x = arr.permute(2, 0, 1).unsqueeze(0)
        if x.shape[1] == 1:
            x = x.expand(-1, 3, -1, -1)
        return torch.nan_to_num(x.contiguous(), nan=0.0).clamp(0.0, 1.0)


def _device_of(module: Any) -> torch.device:
    if isinstance(module, torch.nn.Module):
        for b in module.buffers():
            return b.device
        for p in module.parameters():
            return p.device
    return torch.device("cpu")


def _to_hwc(x: torch.Tensor) -> np.ndarray:
    """``(1, 3, H, W)`` tensor → ``(H, W, 3)`` float32 numpy."""
    return np.ascontiguousarray(x[0].detach().float().permute(1, 2, 0).cpu().numpy(), dtype=np.float32)
