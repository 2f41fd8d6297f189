"""The arithmetic of the FFDNet prior, chosen at run time from what the CPU offers.

``guided.precision`` (``--precision``, the app's "Prior precision", the preset) is one of:

* ``"float32"`` — every prior call in float32 with oneDNN's channels-last convolutions: the same
  sums as the reference NCHW path (max difference ~3e-6), i.e. today's pixels;
* ``"float32-fast"`` — float32 with NNPACK's fast convolution algorithms (built into torch's CPU
  wheels for x86-64 with AVX2; max difference ~1e-5 per pass, well below one 8-bit level); on a quiet
  AMD EPYC (AVX-512) it was no faster than oneDNN channels-last at 1000² and 1.5× slower at 256²
  (BENCHMARKS.md), but on the same CPU capped at AVX2 it took half the time of oneDNN's AVX2 kernels:
  ``auto`` picks it on CPUs without AVX-512; ``"float32"`` where torch lacks NNPACK;
* ``"bfloat16-mixed"`` — every FFDNet layer in bfloat16 (oneDNN's fused convolution + ReLU, float32
  accumulation, float32 biases that absorb the mean error of the rounded weights) on the steps whose
  noise level is at least :data:`MIXED_BF16_SIGMA`, ``float32`` below it — in OpenVINO's float32 CPU
  runtime where the optional extra ``openvino`` is installed and works (:func:`float_backend`; the same
  oneDNN sums as torch's path, measured identical, and 1.2–1.5× less time per pass at 1000², from
  reusing its buffers where torch page-faults fresh ones: :mod:`spikeview.guided.priors.ov_backend`),
  torch's fused oneDNN channels-last path otherwise; ``x − residual`` and the data step stay float32 in torch;
* ``"auto"`` (default) — the fastest of these that stays within 0.1 dB PSNR and 0.005 SSIM of
  float32 on the held-out scenes of ``spikeview bench``, for what this CPU offers
  (:func:`resolve_precision`).

The candidates and their cost on the bench: ``benchmarks/bench_prior.py`` (BENCHMARKS.md, "Prior
precision and backend"). The choice is resolved once per run, printed in the plan and written into
the recipe that every output's metadata and preset record (``recipe_for_state``), so a preset re-runs
with the same arithmetic on any machine.
"""

from __future__ import annotations

import functools
import os

from spikeview.guided.config import PRECISIONS  # the values of ``guided.precision`` (one list: the config's)

__all__ = ["BF16_MIN_SPEEDUP", "MIXED_BF16_SIGMA", "MIXED_LAYERS", "PRECISIONS", "at_precision", "bf16_speedup",
           "cpu_summary", "float_backend", "resolve_precision", "step_precisions"]
#: ``bfloat16-mixed``: the FFDNet layers in bfloat16 on the high-noise steps (``"bfloat16-all"`` = every
#: layer, ``"bfloat16"`` = the hidden layers, first and last float32). With the bias correction of the
#: rounded weights (:meth:`FFDNetDenoiser._layers`) the two cost the same on the bench (worst scene
#: −0.002 / −0.005 dB at σ ≥ 18/255), and every layer in bf16 is the faster pass
MIXED_LAYERS = "bfloat16-all"
#: ``bfloat16-mixed``: a step runs in bfloat16 when its noise level (smallest over channels) is at
#: least this (fraction of 1); below it the step runs ``float32`` (oneDNN channels-last). bfloat16's
#: error in the prior's output is about 0.85–1.05/255 RMS (the activations' rounding; the weights'
#: mean error is corrected), measured on two natural images at 5–40/255: a step whose noise is far above
#: it hides it, the last low-noise steps would keep it. 18/255 = the first 3 of the default 6 steps
#: (50 → 5/255): worst held-out scene −0.002 dB / −0.0023 SSIM; 4 steps (σ ≥ 12/255, hidden layers) cost
#: −0.0080 SSIM on colorwheel, over the 0.005 budget (``benchmarks/bench_prior.py --quality``)
MIXED_BF16_SIGMA = 18.0 / 255.0
#: ``auto`` picks ``bfloat16-mixed`` on a CPU with native bfloat16 (set from the bench's numbers) where
#: bfloat16 is measured faster (:func:`bf16_speedup`)
AUTO_BF16 = True
#: ``auto`` spends bfloat16 only where a bfloat16 convolution takes at least this many times less time than
#: float32 on this CPU (:func:`bf16_speedup`). The flags alone do not tell: an AMD EPYC (Zen 4) with
#: AVX512_BF16 ran a 1000² pass 1.9x faster in bfloat16, an Intel Xeon with AVX512_BF16 and AVX10.1 but no
#: AMX (hidden by its hypervisor) 1.7x *slower* (2.58 vs 1.53 s; its VDPBF16PS has the float32 FMA's
#: throughput, and the conversions cost on top), so ``auto`` there ran 1.3x slower than ``float32``
BF16_MIN_SPEEDUP = 1.2


def cpu_flags() -> frozenset[str]:
    """The CPU feature flags of ``/proc/cpuinfo`` (empty where it cannot be read, e.g. not Linux)."""
    from spikeview.guided.device import cpuinfo_field

    return frozenset(cpuinfo_field("flags").split())


def max_isa(environ=None) -> str:
    """oneDNN's instruction-set cap from the environment (``ONEDNN_MAX_CPU_ISA``, older ``DNNL_MAX_CPU_ISA``;
    ``"ALL"`` when unset), upper-case: ``ONEDNN_MAX_CPU_ISA=AVX2`` makes this CPU run as an AVX2-only one."""
    env = os.environ if environ is None else environ
    return (env.get("ONEDNN_MAX_CPU_ISA") or env.get("DNNL_MAX_CPU_ISA") or "ALL").strip().upper() or "ALL"


def isa_has_bf16(isa: str) -> bool:
    """oneDNN capped at ``isa`` (a :func:`max_isa` value) still runs bfloat16 natively (AVX512_CORE_BF16 and up)."""
    return isa == "ALL" or any(t in isa for t in ("BF16", "FP16", "AMX", "AVX10"))


@functools.lru_cache(maxsize=1)
def cpu_summary() -> dict[str, object]:
    """What the prior's speed depends on: torch's CPU capability, the SIMD/bf16/AMX flags and
    whether oneDNN runs bfloat16 natively."""
    import torch

    from spikeview.guided.priors.ffdnet import nnpack_ok

    flags = cpu_flags()
    try:
        onednn_bf16 = bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):
        onednn_bf16 = False
    # oneDNN's instruction set capped by the environment (ONEDNN_MAX_CPU_ISA=AVX2 plays an AVX2-only CPU):
    # torch's bf16 check reads the CPU, not the cap, so a cap below AVX512_CORE_BF16 means no native bf16
    isa = max_isa()
    onednn_bf16 = onednn_bf16 and isa_has_bf16(isa)
    from spikeview.guided.priors import ov_backend

    s: dict[str, object] = {
        "capability": str(torch.backends.cpu.get_cpu_capability()),
        "avx2": "avx2" in flags,
        "avx512f": "avx512f" in flags,
        "avx512_bf16": "avx512_bf16" in flags,
        "amx_bf16": "amx_bf16" in flags,
        "onednn_bf16": onednn_bf16,
        "onednn_max_isa": isa,
        "nnpack": nnpack_ok(),
        "openvino": ov_backend.version(),  # installed (float_backend says whether it is used)
    }
    # measured only where bfloat16 is native (otherwise None): whether it pays here (auto's rule)
    s["bf16_speedup"] = bf16_speedup() if native_bf16(s) else None
    return s


@functools.lru_cache(maxsize=1)
def bf16_speedup() -> float:
    """float32 time over bfloat16 time of one FFDNet hidden layer (96 → 96 features, 3×3, fused ReLU,
    channels-last) on a 96×128×256 volume, measured once per process on this CPU as torch runs it now
    (its threads, ``ONEDNN_MAX_CPU_ISA``): the best of 3 alternating runs each after a warm-up, ~0.2 s.
    ``0.0`` where bfloat16 convolutions do not run."""
    import time

    import torch
    import torch.nn.functional as F

    from spikeview.guided.priors.ffdnet import _conv_fused, _pack, fused_ok

    g = torch.Generator().manual_seed(0)
    x32 = torch.rand(1, 96, 128, 256, generator=g).contiguous(memory_format=torch.channels_last)
    w32 = torch.randn(96, 96, 3, 3, generator=g) * 0.03
    b32 = torch.randn(96, generator=g) * 0.01
    fused = fused_ok()
    runs = {}
    try:
        for dt in (torch.float32, torch.bfloat16):
            x, w = x32.to(dt), w32.to(dt).contiguous(memory_format=torch.channels_last)
            if fused:  # the prior's own call: packed weights, float32 bias beside bfloat16 weights
                runs[dt] = functools.partial(_conv_fused, x, _pack(w), b32, True)
            else:
                runs[dt] = functools.partial(lambda x, w, b: F.relu(F.conv2d(x, w, b, padding=1)), x, w, b32.to(dt))
        best = {dt: float("inf") for dt in runs}
        with torch.no_grad():
            for f in runs.values():
                f()
            for _ in range(3):
                for dt, f in runs.items():
                    t0 = time.perf_counter()
                    f()
                    best[dt] = min(best[dt], time.perf_counter() - t0)
    except (RuntimeError, TypeError):  # no bfloat16 convolution in this torch/CPU
        return 0.0
    return speedup_of(best[torch.float32], best[torch.bfloat16])


def speedup_of(float32_seconds: float, bf16_seconds: float) -> float:
    """How many times faster bfloat16 ran: float32's time over bfloat16's (2.0 = bfloat16 took half the time)."""
    return float(float32_seconds) / max(float(bf16_seconds), 1e-9)


def native_bf16(summary: dict[str, object] | None = None) -> bool:
    """The CPU computes bfloat16 dot products in hardware (AVX512-BF16 or AMX) and oneDNN uses them."""
    s = cpu_summary() if summary is None else summary
    return bool(s["onednn_bf16"]) and bool(s["avx512_bf16"] or s["amx_bf16"])


def float_backend() -> str:
    """Where ``bfloat16-mixed`` runs its float32 steps: ``"openvino"`` (OpenVINO's float32 CPU runtime,
    the optional extra, where it imports, compiles and gives ``F.conv2d``'s numbers:
    :func:`spikeview.guided.priors.ov_backend.available`, probed once) or ``"torch"`` (oneDNN's fused
    channels-last path). ``float32`` itself always runs in torch: it is the reference pixels."""
    from spikeview.guided.priors import ov_backend

    return "openvino" if ov_backend.available() else "torch"


def backend_label(backend: str | None = None) -> str:
    """The float32 steps' backend as the plan prints it (``"OpenVINO 2026.4.1 from ~600×600, torch below"``
    or ``"torch oneDNN"``)."""
    from spikeview.guided.priors import ov_backend

    backend = float_backend() if backend is None else backend
    # OpenVINO serves frames whose layers outgrow the allocator's reuse (ffdnet.OV_MIN_LAYER_BYTES)
    return f"OpenVINO {ov_backend.version()} from ~600×600, torch below" if backend == "openvino" else "torch oneDNN"


def describe(precision: str) -> str:
    """What a resolved precision does, in a few words (with the backend of the float32 steps)."""
    return {"float32": "float32, oneDNN channels-last (reference pixels)",
            "float32-fast": "float32, NNPACK fast convolution",
            "bfloat16-mixed": (f"bfloat16 {'layers' if MIXED_LAYERS == 'bfloat16-all' else 'hidden layers'} on steps "
                               f"with noise >= {255 * MIXED_BF16_SIGMA:.0f}/255, float32 below "
                               f"({backend_label()})")}.get(precision, precision)


def avx512_usable(s: dict[str, object]) -> bool:
    """oneDNN runs AVX-512 here: the CPU has AVX512F and no ``ONEDNN_MAX_CPU_ISA`` cap holds it below."""
    isa = str(s.get("onednn_max_isa", "ALL"))
    return bool(s.get("avx512f")) and (isa == "ALL" or any(t in isa for t in ("AVX512", "AMX", "AVX10")))


def _auto(s: dict[str, object]) -> tuple[str, str]:
    feats = ", ".join(k for k in ("amx_bf16", "avx512_bf16", "avx512f", "avx2") if s.get(k)) or "no AVX2"
    speedup = s.get("bf16_speedup")  # None: not measured (a summary given by hand): the flags decide
    if AUTO_BF16 and native_bf16(s) and (speedup is None or speedup >= BF16_MIN_SPEEDUP):
        measured = "" if speedup is None else f", a bfloat16 layer {speedup:.1f}x as fast as float32 here"
        return "bfloat16-mixed", (f"native bfloat16 ({feats}{measured}); within 0.1 dB / 0.005 SSIM of float32 "
                                  "on the bench")
    if AUTO_BF16 and native_bf16(s):
        # native bfloat16 that does not pay (Intel without AMX: VDPBF16PS has the float32 FMA's throughput)
        return "float32", (f"{feats}; native bfloat16 but a bfloat16 layer measured {speedup:.2f}x as fast as "
                           f"float32 here (below {BF16_MIN_SPEEDUP}x): float32 with oneDNN's fused "
                           "channels-last convolutions")
    if s.get("nnpack") and not avx512_usable(s):
        # an AVX2-only CPU: NNPACK's fast (Winograd/FFT) float32 convolutions took 1.6-2.0x less time per
        # 1000² pass than oneDNN's AVX2 kernels (this EPYC capped with ONEDNN_MAX_CPU_ISA=AVX2; NNPACK has
        # AVX2 kernels only, so the cap does not touch it), the same numbers within 1e-5 and 0.000 dB on
        # the bench (benchmarks/bench_prior.py, AVX2 section)
        return "float32-fast", f"{feats}; no AVX-512 and no native bfloat16: NNPACK's fast float32 convolutions"
    # with AVX-512, NNPACK (float32-fast, AVX2 kernels) measured no faster than oneDNN channels-last on a
    # quiet machine (1.0x at 1000², 0.68x at 256²; BENCHMARKS.md): auto keeps the reference float32 path
    # (ONNX Runtime's float32 conv stack measured 1.26-1.32x less time than the fused oneDNN path at 1000²,
    # 0.9-1.1x at 256-512² under load: not a dependency; benchmarks/bench_prior.py measures it when installed;
    # OpenVINO's float32 serves bfloat16-mixed's float32 steps, but ``float32`` stays torch's reference path)
    return "float32", f"{feats}; no native bfloat16: float32 with oneDNN's fused channels-last convolutions"


#: on a CUDA GPU the float32 convolutions run cuDNN's TF32 tensor-core paths (10-bit mantissa products,
#: float32 sums): measured on the bench's held-out scenes against the CPU's float32 (benchmarks/gpu_check.py)
CUDA_TF32 = True


def resolve_precision(requested: str, summary: dict[str, object] | None = None, device=None) -> tuple[str, str]:
    """The precision a run uses for ``requested`` (one of :data:`PRECISIONS`) on ``device`` (default: the
    CPU), and why.

    ``summary`` is :func:`cpu_summary` (given in tests to play another CPU). On a CUDA device ``auto`` is
    ``float32`` with TF32 convolutions: a 1000² FFDNet pass is milliseconds there, the prior is no longer
    what a window waits for, so bfloat16 would buy nothing worth its error (``bfloat16-mixed`` stays
    available: bfloat16 layers on the high-noise steps, cuDNN); ``float32-fast`` (NNPACK) is a CPU path.
    """
    if getattr(device, "type", str(device or "cpu").split(":")[0]) == "cuda":
        gpu = "float32, cuDNN with TF32 convolutions" if CUDA_TF32 else "float32, cuDNN"
        if requested in ("auto", "float32", "float32-fast"):
            why = {"auto": "auto on a CUDA GPU (the prior takes milliseconds there: no bfloat16)",
                   "float32": "set by precision=float32",
                   "float32-fast": "float32-fast (NNPACK) is a CPU path"}[requested]
            return "float32", f"{gpu}: {why}"
        return requested, (f"bfloat16 layers on steps with noise >= {255 * MIXED_BF16_SIGMA:.0f}/255, {gpu} below: "
                           f"set by precision={requested}")
    s = cpu_summary() if summary is None else summary
    auto, why = _auto(s)
    if requested == "auto":
        return auto, f"{describe(auto)}: auto on this CPU ({why})"
    if requested == "float32-fast" and not s.get("nnpack"):
        return "float32", f"{describe('float32')}: float32-fast was set but this torch has no NNPACK"
    note = "auto's choice on this CPU" if requested == auto else f"auto would pick {auto} here"
    return requested, f"{describe(requested)}: set by precision={requested} ({note})"


def step_precisions(precision: str, sigmas, layers: str | None = None, threshold: float | None = None) -> list[str]:
    """The FFDNet layer precision of each prior call (``"float32"``, ``"float32-fast"``,
    ``"float32-openvino"`` (``bfloat16-mixed``'s float32 steps where :func:`float_backend` is OpenVINO),
    ``"bfloat16"`` or ``"bfloat16-all"``).

    Args:
        precision: a resolved ``guided.precision`` (not ``"auto"``).
        sigmas: the steps' noise levels (smallest over channels; fractions of 1), or a step count
            (a latent prior: float32 throughout).
        layers, threshold: the mixed policy (default :data:`MIXED_LAYERS`, :data:`MIXED_BF16_SIGMA`;
            given by the benchmark that chose them).
    """
    import numpy as np

    if isinstance(sigmas, (int, np.integer)):
        return ["float32"] * int(sigmas)
    sigmas = np.asarray(sigmas, dtype=np.float64).reshape(-1)
    if precision == "bfloat16-mixed":
        layers = MIXED_LAYERS if layers is None else layers
        threshold = MIXED_BF16_SIGMA if threshold is None else threshold
        low = "float32-openvino" if float_backend() == "openvino" else "float32"
        return [layers if s >= threshold else low for s in sigmas]
    if precision == "float32-fast":
        return ["float32-fast"] * len(sigmas)
    return ["float32"] * len(sigmas)


class AtPrecision:
    """A view of a pixel-space prior whose ``denoise`` runs at one layer precision (FFDNet's
    ``precision`` argument); other priors are used as they are."""

    def __init__(self, prior, precision: str):
        self.prior = prior
        self.precision = precision
        self.channels = prior.channels
        self.sigma_max = prior.sigma_max

    def denoise(self, x, sigma):
        return self.prior.denoise(x, sigma, precision=self.precision)


def at_precision(prior, precision: str):
    """``prior`` at layer precision ``precision`` (the prior itself for float32 or when it has no precision)."""
    from spikeview.guided.priors.ffdnet import FFDNetDenoiser

    if precision == "float32" or not isinstance(prior, FFDNetDenoiser):
        return prior
    return AtPrecision(prior, precision)
