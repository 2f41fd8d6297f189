"""Architectures of the latent-diffusion prior, from published configs, and modules built from them with random weights.

For timing (``benchmarks/bench_sd.py``: speed depends on the shapes, not on the weights' values) and for
tests (a tiny model of the same families, saved with ``save_pretrained`` and loaded back). Nothing is
downloaded; building a module needs the optional extra ``spikeview[sd]`` (diffusers).
"""

from __future__ import annotations

from typing import Any

import torch

from spikeview.guided.priors.sd import import_diffusers

# SD 2.1 (stabilityai/stable-diffusion-2-1) unet/config.json, the entries that set the architecture
SD21_UNET = dict(
    sample_size=96, in_channels=4, out_channels=4,
    down_block_types=("CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"),
    up_block_types=("UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"),
    block_out_channels=(320, 640, 1280, 1280), layers_per_block=2, attention_head_dim=(5, 10, 20, 20),
    cross_attention_dim=1024, use_linear_projection=True, act_fn="silu", norm_num_groups=32, norm_eps=1e-5,
    downsample_padding=1, flip_sin_to_cos=True, freq_shift=0,
)
# SD 1.x/2.x vae/config.json
SD_VAE = dict(
    in_channels=3, out_channels=3, down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4,
    block_out_channels=(128, 256, 512, 512), layers_per_block=2, latent_channels=4, norm_num_groups=32, act_fn="silu",
    sample_size=768, scaling_factor=0.18215,
)
# SD 2.1 scheduler/scheduler_config.json (v-prediction)
SD21_SCHEDULER = dict(
    num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear", clip_sample=False,
    set_alpha_to_one=False, steps_offset=1, prediction_type="v_prediction",
)
# a tiny UNet and VAE of the same block types (the VAE has SD's four blocks, so its downsampling factor is 8)
TINY_UNET = dict(
    sample_size=8, in_channels=4, out_channels=4, block_out_channels=(32, 64), layers_per_block=1,
    down_block_types=("DownBlock2D", "CrossAttnDownBlock2D"), up_block_types=("CrossAttnUpBlock2D", "UpBlock2D"),
    cross_attention_dim=32, attention_head_dim=(2, 4), use_linear_projection=True, norm_num_groups=32,
)
TINY_VAE = dict(
    in_channels=3, out_channels=3, down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4,
    block_out_channels=(32, 32, 64, 64), layers_per_block=1, latent_channels=4, norm_num_groups=32, sample_size=64,
)


def random_modules(unet: dict[str, Any], vae: dict[str, Any], *, seed: int = 0,
                   device: torch.device | str = "cpu") -> tuple[Any, Any, Any]:
    """``(UNet2DConditionModel, AutoencoderKL, DDIMScheduler)``: the given architectures, weights drawn after ``torch.manual_seed(seed)``.

    The modules are initialised on ``device`` directly (on a GPU ten times faster than on the CPU for
    SD's 865 M parameters); the scheduler is SD 2.1's.
    """
    diffusers = import_diffusers()
    torch.manual_seed(seed)
    with torch.device(device):
        u = diffusers.UNet2DConditionModel(**unet)
        v = diffusers.AutoencoderKL(**vae)
    return u, v, diffusers.DDIMScheduler(**SD21_SCHEDULER)
