"""The arithmetic of the FFDNet prior, chosen at run time from what the CPU offers.

``guided.precision`` (``--precision``, the app's "Prior precision", the preset) is one of:

* ``"float32"`` — every prior call in float32 with oneDNN's channels-last convolutions: the same
  sums as the reference NCHW path (max difference ~3e-6), i.e. today's pixels;
* ``"float32-fast"`` — float32 with NNPACK's fast convolution algorithms (built into torch's CPU
  wheels for x86-64 with AVX2; max difference ~1e-5 per pass, well below one 8-bit level); on a quiet
  AMD EPYC (AVX-512) it was no faster than oneDNN channels-last at 1000² and 1.5× slower at 256²
  (BENCHMARKS.md), so ``auto`` does not pick it; ``"float32"`` where torch lacks NNPACK;
* ``"bfloat16-mixed"`` — the hidden layers of FFDNet in bfloat16 on the steps whose noise level is
  at least :data:`MIXED_BF16_SIGMA`, ``float32`` (channels-last) below it; the first layer (which sees the
  image), the last layer (which produces the residual), ``x − residual`` and the data step stay float32;
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
from pathlib import Path

from spikeview.guided.config import PRECISIONS  # the values of ``guided.precision`` (one list: the config's)

__all__ = ["MIXED_BF16_SIGMA", "MIXED_LAYERS", "PRECISIONS", "at_precision", "cpu_summary", "resolve_precision", "step_precisions"]
#: ``bfloat16-mixed``: the FFDNet layers in bfloat16 on the high-noise steps (``"bfloat16"`` = the
#: hidden layers, first and last float32; ``"bfloat16-all"`` = every layer)
MIXED_LAYERS = "bfloat16"
#: ``bfloat16-mixed``: a step runs in bfloat16 when its noise level (smallest over channels) is at
#: least this (fraction of 1); below it the step runs ``float32`` (oneDNN channels-last). bfloat16's error in the
#: prior's output is about 1.5/255 mean, 7/255 max (hidden layers, measured on a natural image); a
#: step whose noise is far above it hides it, the later low-noise steps would keep it.
MIXED_BF16_SIGMA = 30.0 / 255.0
#: ``auto`` picks ``bfloat16-mixed`` on a CPU with native bfloat16 (set from the bench's numbers)
AUTO_BF16 = True


@functools.lru_cache(maxsize=1)
def cpu_flags() -> frozenset[str]:
    """The CPU feature flags of ``/proc/cpuinfo`` (empty where it cannot be read, e.g. not Linux)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="ascii", errors="replace")
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.split(":", 1)[1].split())
    return frozenset()


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
    return {
        "capability": str(torch.backends.cpu.get_cpu_capability()),
        "avx2": "avx2" in flags,
        "avx512f": "avx512f" in flags,
        "avx512_bf16": "avx512_bf16" in flags,
        "amx_bf16": "amx_bf16" in flags,
        "onednn_bf16": onednn_bf16,
        "nnpack": nnpack_ok(),
    }


def native_bf16(summary: dict[str, object] | None = None) -> bool:
    """The CPU computes bfloat16 dot products in hardware (AVX512-BF16 or AMX) and oneDNN uses them."""
    s = cpu_summary() if summary is None else summary
    return bool(s["onednn_bf16"]) and bool(s["avx512_bf16"] or s["amx_bf16"])


def describe(precision: str) -> str:
    """What a resolved precision does, in a few words."""
    return {"float32": "float32, oneDNN channels-last (reference pixels)",
            "float32-fast": "float32, NNPACK fast convolution",
            "bfloat16-mixed": (f"bfloat16 hidden layers on steps with noise >= {255 * MIXED_BF16_SIGMA:.0f}/255, "
                               "float32 below")}.get(precision, precision)


def _auto(s: dict[str, object]) -> tuple[str, str]:
    feats = ", ".join(k for k in ("amx_bf16", "avx512_bf16", "avx512f", "avx2") if s.get(k)) or "no AVX2"
    if AUTO_BF16 and native_bf16(s):
        return "bfloat16-mixed", f"native bfloat16 ({feats}); within 0.1 dB / 0.005 SSIM of float32 on the bench"
    # NNPACK (float32-fast) measured no faster than oneDNN channels-last on a quiet machine (1.0x at
    # 1000², 0.68x at 256²; BENCHMARKS.md): auto keeps the reference float32 path without native bf16
    return "float32", f"{feats}; no native bfloat16, and no faster float32 path than oneDNN channels-last was measured"


def resolve_precision(requested: str, summary: dict[str, object] | None = None) -> tuple[str, str]:
    """The precision a run uses for ``requested`` (one of :data:`PRECISIONS`), and why.

    ``summary`` is :func:`cpu_summary` (given in tests to play another CPU).
    """
    s = cpu_summary() if summary is None else summary
    auto, why = _auto(s)
    if requested == "auto":
        return auto, f"{describe(auto)}: auto on this CPU ({why})"
    if requested == "float32-fast" and not s.get("nnpack"):
        return "float32", f"{describe('float32')}: float32-fast was set but this torch has no NNPACK"
    note = "auto's choice on this CPU" if requested == auto else f"auto would pick {auto} here"
    return requested, f"{describe(requested)}: set by precision={requested} ({note})"


def step_precisions(precision: str, sigmas, layers: str | None = None, threshold: float | None = None) -> list[str]:
    """The FFDNet layer precision of each prior call (``"float32"``, ``"float32-fast"``, ``"bfloat16"``
    or ``"bfloat16-all"``).

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
        return [layers if s >= threshold else "float32" for s in sigmas]
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
