"""A Stable Diffusion 2.x-family latent diffusion model as prior (optional extra ``spikeview[sd]``).

The model is read from a **local** folder in diffusers format (nothing is ever downloaded)::

    MODEL/
      unet/       config.json + diffusion_pytorch_model.safetensors   (UNet2DConditionModel)
      vae/        config.json + diffusion_pytorch_model.safetensors   (AutoencoderKL)
      scheduler/  scheduler_config.json                                (any diffusers scheduler;
                                                                        only its β schedule and
                                                                        prediction type are used)
      prompt_embeds.safetensors                                        (optional, see below)

``.bin`` weights and the ``fp16`` variant (``diffusion_pytorch_model.fp16.safetensors``) are accepted
too; ``model_index.json``, ``text_encoder/`` and ``tokenizer/`` are not needed.

Conventions:

* Images are ``(N, 3, H, W)`` float tensors in [0, 1] (the VAE itself works in [−1, 1]); ``H`` and
  ``W`` must be multiples of :attr:`LatentDiffusionPrior.vae_factor` (8 for SD), the caller pads.
* Latents are **scaled**: ``z = (E(x) − shift) · scaling_factor`` (SD: ``scaling_factor = 0.18215``,
  no shift), ``(N, C, H / 8, W / 8)`` float32, so that the diffusion model sees unit-variance latents.
* Timesteps are integer indices ``0 … T − 1`` of the training schedule (``T = 1000`` for SD);
  ``ᾱ_t`` is :attr:`LatentDiffusionPrior.alphas_cumprod` ``[t]``.
* Text conditioning: spikeview runs no text encoder. The UNet's ``encoder_hidden_states`` is the
  tensor in ``MODEL/prompt_embeds.safetensors`` (key ``prompt_embeds``, shape ``(L, D)`` or
  ``(1, L, D)``: the text encoder's output for the empty prompt, saved once wherever
  ``transformers`` is installed) when that file exists, else a single token of zeros of the
  UNet's ``cross_attention_dim`` ``D``. (With zeros every cross-attention key is zero, so the
  attention is uniform over identical zero values and the token count does not matter.)

The weights are frozen (``requires_grad=False``); every method is differentiable in its input, so
DPS can backpropagate through the decoder and the UNet to the latent.
"""

from __future__ import annotations

import contextlib
import importlib.util
import inspect
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch

from spikeview.errors import InputFileError, ParameterError
from spikeview.guided.priors.base import PriorUnavailableError

INSTALL_HINT = 'pip install "spikeview[sd]"'
EXPECTED_LAYOUT = (
    "a diffusers-format Stable Diffusion 2.x folder with unet/ and vae/ (each config.json + "
    "diffusion_pytorch_model.safetensors) and scheduler/ (scheduler_config.json)"
)
#: the SD 1.x/2.x VAE latent scale, used when the VAE config has no ``scaling_factor``
SD_SCALING_FACTOR = 0.18215
PROMPT_EMBEDS_FILE = "prompt_embeds.safetensors"
DTYPES = {"float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
PREDICTION_TYPES = ("epsilon", "v_prediction", "sample")

_WEIGHT_NAMES = (
    # (file name, diffusers variant, use_safetensors)
    ("diffusion_pytorch_model.safetensors", None, True),
    ("diffusion_pytorch_model.safetensors.index.json", None, True),
    ("diffusion_pytorch_model.bin", None, False),
    ("diffusion_pytorch_model.fp16.safetensors", "fp16", True),
    ("diffusion_pytorch_model.fp16.bin", "fp16", False),
)


def import_diffusers() -> Any:
    """The ``diffusers`` module, imported on first use.

    Raises:
        PriorUnavailableError: diffusers is not installed (the message says how to install it).
    """
    try:
        import diffusers
    except ImportError:
        raise PriorUnavailableError(
            f"The latent-diffusion prior (prior='sd') needs the diffusers package, which is not installed: {INSTALL_HINT}."
        ) from None
    return diffusers


def resolve_dtype(dtype: str | torch.dtype | None) -> torch.dtype:
    """``"float32"``/``"float16"``/``"bfloat16"`` (or the torch dtype, or ``None`` = float32) → torch dtype."""
    if dtype is None:
        return torch.float32
    if isinstance(dtype, torch.dtype):
        if dtype in DTYPES.values():
            return dtype
    elif dtype in DTYPES:
        return DTYPES[dtype]
    raise ParameterError(f"dtype = {dtype!r} is not supported: use one of {', '.join(DTYPES)}.")


def resolve_device(device: str | torch.device | None) -> torch.device:
    """``None``/``"auto"`` → CUDA when available, else CPU (:func:`spikeview.guided.device.resolve_device`)."""
    from spikeview.guided.device import resolve_device as _resolve

    return _resolve(device)


def _check_subfolder(root: Path, sub: str, config_name: str, weights: bool) -> tuple[str | None, bool | None]:
    """Raise a readable error when ``root/sub`` is incomplete; return ``(variant, use_safetensors)``."""
    folder = root / sub
    if not folder.is_dir():
        raise InputFileError(f"{root}: the subfolder {sub}/ is missing; the model must be {EXPECTED_LAYOUT}.")
    if not (folder / config_name).is_file():
        raise InputFileError(f"{folder}: the file {config_name} is missing; the model must be {EXPECTED_LAYOUT}.")
    if not weights:
        return None, None
    for name, variant, safe in _WEIGHT_NAMES:
        if (folder / name).is_file():
            return variant, safe
    raise InputFileError(
        f"{folder}: no weights file (diffusion_pytorch_model.safetensors, .bin, or their .fp16 variants); "
        f"the model must be {EXPECTED_LAYOUT}."
    )


def _read_json(path: Path) -> dict[str, Any]:
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputFileError(f"{path}: not a readable JSON config ({e}); re-export the model with save_pretrained.") from None
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: not a diffusers config (expected a JSON object); re-export the model with save_pretrained.")
    return data


def _load_prompt_embeds(path: Path) -> torch.Tensor:
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        tensors = load_file(str(path))
    except (OSError, SafetensorError) as e:
        raise InputFileError(f"{path}: not a readable safetensors file ({e}); delete it to use zero conditioning.") from None
    if "prompt_embeds" not in tensors:
        raise InputFileError(f"{path}: has no tensor named 'prompt_embeds' (found {', '.join(tensors) or 'none'}).")
    return tensors["prompt_embeds"]


class LatentDiffusionPrior:
    """UNet (ε-, v- or x₀-prediction), VAE and β schedule of a latent diffusion model, frozen.

    Build it with :meth:`from_pretrained` (a local diffusers folder) or directly from diffusers
    modules (tests use tiny random ones). See the module docstring for the conventions.

    Args:
        unet: a diffusers ``UNet2DConditionModel`` (plain text-to-image: its input and output
            channels equal the VAE's latent channels, no class or added embeddings).
        vae: a diffusers ``AutoencoderKL``.
        scheduler: a diffusers scheduler (or its config dict); only ``alphas_cumprod`` (through a
            ``DDIMScheduler`` built from the same config), ``num_train_timesteps`` and
            ``prediction_type`` are used.
        prompt_embeds: ``(L, D)`` or ``(1, L, D)`` conditioning, ``None`` = one token of zeros.
        device: ``"auto"`` (CUDA when available), ``"cpu"``, ``"cuda"``, …
        dtype: compute dtype of the networks: ``"float32"``, or ``"float16"``/``"bfloat16"``
            (CUDA only: the weights are cast and the networks run under ``torch.autocast``;
            latents, schedule arithmetic and the data loss stay float32).
        source: where the weights came from (for messages and ``repr``).
    """

    def __init__(
        self,
        unet: Any,
        vae: Any,
        scheduler: Any,
        prompt_embeds: torch.Tensor | None = None,
        device: str | torch.device | None = "auto",
        dtype: str | torch.dtype | None = "float32",
        source: str = "<modules>",
    ):
        diffusers = import_diffusers()
        self.source = source
        ucfg, vcfg = unet.config, vae.config
        latent_channels = int(vcfg.latent_channels)
        if int(ucfg.in_channels) != latent_channels or int(ucfg.out_channels) != latent_channels:
            raise ParameterError(
                f"{source}: the UNet maps {ucfg.in_channels} to {ucfg.out_channels} channels but the VAE latents have "
                f"{latent_channels}; use a plain text-to-image SD 2.x model (not an inpainting or upscaling one)."
            )
        if getattr(ucfg, "addition_embed_type", None) is not None or getattr(ucfg, "class_embed_type", None) is not None:
            raise ParameterError(
                f"{source}: the UNet needs extra conditioning (addition_embed_type={getattr(ucfg, 'addition_embed_type', None)!r}, "
                f"class_embed_type={getattr(ucfg, 'class_embed_type', None)!r}); only SD 2.x-family text-to-image UNets are supported."
            )
        cad = ucfg.cross_attention_dim
        if not isinstance(cad, int):
            raise ParameterError(f"{source}: cross_attention_dim = {cad!r} per block is not supported; use an SD 2.x-family UNet.")
        self.cross_attention_dim = int(cad)

        scfg = dict(scheduler if isinstance(scheduler, dict) else scheduler.config)
        self.prediction_type = str(scfg.get("prediction_type", "epsilon"))
        if self.prediction_type not in PREDICTION_TYPES:
            raise ParameterError(
                f"{source}: scheduler prediction_type = {self.prediction_type!r} is not supported: the UNet must predict one of {', '.join(PREDICTION_TYPES)}."
            )
        # A DDIMScheduler built from the same config computes ᾱ exactly as the model was trained
        # (β schedule, trained_betas, zero-SNR rescaling); its own stepping is not used.
        known = inspect.signature(diffusers.DDIMScheduler.__init__).parameters
        ddim = diffusers.DDIMScheduler.from_config({k: v for k, v in scfg.items() if k in known and k != "self"})
        self.alphas_cumprod = ddim.alphas_cumprod.detach().to(torch.float64).cpu()
        self.num_train_timesteps = int(self.alphas_cumprod.numel())

        self.scaling_factor = float(getattr(vcfg, "scaling_factor", None) or SD_SCALING_FACTOR)
        shift = getattr(vcfg, "shift_factor", None)
        self.shift_factor = float(shift) if shift is not None else 0.0
        self.vae_factor = 2 ** (len(vcfg.block_out_channels) - 1)
        self.latent_channels = latent_channels

        if prompt_embeds is None:
            cond = torch.zeros(1, 1, self.cross_attention_dim)
        else:
            cond = torch.as_tensor(prompt_embeds).detach().float()
            if cond.ndim == 2:
                cond = cond.unsqueeze(0)
            if cond.ndim != 3 or cond.shape[0] != 1 or cond.shape[2] != self.cross_attention_dim:
                raise ParameterError(
                    f"{source}: prompt_embeds must have shape (L, {self.cross_attention_dim}) or (1, L, {self.cross_attention_dim}), "
                    f"got {tuple(cond.shape)}."
                )
        self._cond = cond

        self.unet = unet.eval().requires_grad_(False)
        self.vae = vae.eval().requires_grad_(False)
        self.device = torch.device("cpu")
        self.dtype = torch.float32
        self.to(device, dtype)

    # ----------------------------------------------------------------------------- loading
    @classmethod
    def from_pretrained(
        cls,
        path: str | os.PathLike[str],
        *,
        device: str | torch.device | None = "auto",
        dtype: str | torch.dtype | None = "float32",
        prompt_embeds: torch.Tensor | None = None,
    ) -> LatentDiffusionPrior:
        """Load ``unet/``, ``vae/`` and ``scheduler/`` from a local diffusers folder (never downloads).

        Args:
            path: the model folder (see the module docstring for the layout).
            device, dtype: see the class.
            prompt_embeds: conditioning; ``None`` reads ``path/prompt_embeds.safetensors`` when it
                exists, else uses zeros.

        Raises:
            PriorUnavailableError: diffusers is not installed.
            InputFileError: the folder, a subfolder, a config or a weights file is missing or unreadable
                (the message names it and the expected layout).
            ParameterError: the model is not an SD 2.x-family text-to-image model.
        """
        diffusers = import_diffusers()
        root = Path(path).expanduser()
        if not root.is_dir():
            raise InputFileError(f"{root}: model folder not found; point model_path to {EXPECTED_LAYOUT}.")
        unet_variant, unet_safe = _check_subfolder(root, "unet", "config.json", weights=True)
        vae_variant, vae_safe = _check_subfolder(root, "vae", "config.json", weights=True)
        _check_subfolder(root, "scheduler", "scheduler_config.json", weights=False)
        dtype_t = resolve_dtype(dtype)
        dev = resolve_device(device)

        sched_cfg = _read_json(root / "scheduler" / "scheduler_config.json")
        for sub in ("unet", "vae"):
            _read_json(root / sub / "config.json")
        # low_cpu_mem_usage needs accelerate; asking for it without accelerate only logs a warning.
        low_mem = importlib.util.find_spec("accelerate") is not None
        modules = {}
        for sub, klass, variant, safe in (
            ("unet", diffusers.UNet2DConditionModel, unet_variant, unet_safe),
            ("vae", diffusers.AutoencoderKL, vae_variant, vae_safe),
        ):
            try:
                modules[sub] = klass.from_pretrained(
                    str(root), subfolder=sub, local_files_only=True, variant=variant, use_safetensors=safe,
                    low_cpu_mem_usage=low_mem, torch_dtype=torch.float32,
                )
            except (OSError, ValueError, KeyError, RuntimeError, TypeError) as e:
                raise InputFileError(
                    f"{root / sub}: could not be loaded as a diffusers {klass.__name__} ({e}); the model must be {EXPECTED_LAYOUT}."
                ) from None
        if prompt_embeds is None and (root / PROMPT_EMBEDS_FILE).is_file():
            prompt_embeds = _load_prompt_embeds(root / PROMPT_EMBEDS_FILE)
        return cls(modules["unet"], modules["vae"], sched_cfg, prompt_embeds, device=dev, dtype=dtype_t, source=str(root))

    # ---------------------------------------------------------------------------- placement
    def to(self, device: str | torch.device | None = None, dtype: str | torch.dtype | None = None) -> LatentDiffusionPrior:
        """Move the networks to ``device`` and cast them to ``dtype`` (``None`` keeps the current one)."""
        dev = self.device if device is None else resolve_device(device)
        dt = self.dtype if dtype is None else resolve_dtype(dtype)
        if dt != torch.float32 and dev.type != "cuda":
            raise ParameterError(
                f"dtype = {str(dt).removeprefix('torch.')!r} needs a CUDA GPU (mixed precision); use dtype = 'float32' on {dev.type}."
            )
        fmt = torch.channels_last if dev.type == "cuda" else torch.contiguous_format
        for net in (self.unet, self.vae):
            # nn.Module.to itself: diffusers' override logs a fp32-modules notice on every cast, and SD
            # 2.x UNets/VAEs have no modules that must stay float32.
            torch.nn.Module.to(net, device=dev, dtype=dt, memory_format=fmt)
        self._cond = self._cond.to(device=dev)
        self.device, self.dtype = dev, dt
        return self

    @contextlib.contextmanager
    def _autocast(self) -> Iterator[None]:
        if self.dtype == torch.float32:
            yield
        else:
            with torch.autocast(device_type=self.device.type, dtype=self.dtype):
                yield

    # ------------------------------------------------------------------------------ schedule
    def alpha_bar(self, t: int) -> float:
        """``ᾱ_t`` of the training schedule for integer timestep ``t`` in ``[0, T)``."""
        t = int(t)
        if not 0 <= t < self.num_train_timesteps:
            raise ParameterError(f"timestep {t} is outside [0, {self.num_train_timesteps}).")
        return float(self.alphas_cumprod[t])

    # -------------------------------------------------------------------------------- networks
    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Scaled latent (posterior mean) of ``x`` ``(N, 3, H, W)`` in [0, 1]; ``H, W`` multiples of :attr:`vae_factor`.

        Returns:
            ``(N, C, H / f, W / f)`` float32 on :attr:`device`.
        """
        self._check_size(x)
        with self._autocast():
            dist = self.vae.encode((2.0 * x - 1.0).to(self.device, self.dtype)).latent_dist
        return (dist.mean.float() - self.shift_factor) * self.scaling_factor

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Image ``D(z)`` of a scaled latent, ``(N, 3, f·h, f·w)`` float32 in [0, 1] units (not clamped)."""
        with self._autocast():
            out = self.vae.decode((z / self.scaling_factor + self.shift_factor).to(self.dtype)).sample
        return (out.float() + 1.0) * 0.5

    def model_output(self, z_t: torch.Tensor, t: int) -> torch.Tensor:
        """The UNet's raw prediction (ε, v or x₀ per :attr:`prediction_type`) at timestep ``t``, float32."""
        n = z_t.shape[0]
        cond = self._cond.expand(n, -1, -1).to(self.dtype)
        timestep = torch.full((n,), int(t), device=self.device, dtype=torch.long)
        with self._autocast():
            out = self.unet(z_t.to(self.dtype), timestep, encoder_hidden_states=cond).sample
        return out.float()

    def predict(self, z_t: torch.Tensor, t: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Predicted unit noise ``ε̂`` and Tweedie's clean latent ``ẑ₀ = E[z₀ | z_t]`` at timestep ``t``.

        With ``z_t = √ᾱ·z₀ + √(1−ᾱ)·ε``: ε-prediction gives ``ẑ₀ = (z_t − √(1−ᾱ)·ε̂) / √ᾱ``;
        v-prediction (``v = √ᾱ·ε − √(1−ᾱ)·z₀``) gives ``ẑ₀ = √ᾱ·z_t − √(1−ᾱ)·v̂`` and
        ``ε̂ = √ᾱ·v̂ + √(1−ᾱ)·z_t``; x₀-prediction gives ``ẑ₀`` directly.

        Returns:
            ``(eps, z0)``, both float32 with ``z_t``'s shape, differentiable in ``z_t``.
        """
        return self.split_prediction(self.model_output(z_t, t), z_t, t)

    def split_prediction(self, out: torch.Tensor, z_t: torch.Tensor, t: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``(ε̂, ẑ₀)`` from a raw model output ``out`` at ``z_t`` (see :meth:`predict`)."""
        a = self.alpha_bar(t)
        sa, s1a = a ** 0.5, (1.0 - a) ** 0.5
        if self.prediction_type == "epsilon":
            return out, (z_t - s1a * out) / sa
        if self.prediction_type == "v_prediction":
            return sa * out + s1a * z_t, sa * z_t - s1a * out
        return (z_t - sa * out) / max(s1a, 1e-12), out

    def _check_size(self, x: torch.Tensor) -> None:
        if x.ndim != 4 or x.shape[1] != 3:
            raise ParameterError(f"image must have shape (N, 3, H, W), got {tuple(x.shape)}.")
        f = self.vae_factor
        if x.shape[-2] % f or x.shape[-1] % f:
            raise ParameterError(f"image size {tuple(x.shape[-2:])} must be a multiple of {f} (the VAE's downsampling); pad it first.")

    def __repr__(self) -> str:
        n_unet = sum(p.numel() for p in self.unet.parameters())
        n_vae = sum(p.numel() for p in self.vae.parameters())
        return (
            f"LatentDiffusionPrior(source={self.source!r}, prediction_type={self.prediction_type!r}, "
            f"T={self.num_train_timesteps}, unet={n_unet / 1e6:.1f}M, vae={n_vae / 1e6:.1f}M, "
            f"device={str(self.device)!r}, dtype={str(self.dtype).removeprefix('torch.')!r})"
        )
