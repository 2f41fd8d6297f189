"""Where the guided reconstruction runs: ``guided.device`` (``--device``, the app's "Device") resolved once.

``"auto"`` (default) is the first CUDA GPU torch sees, else the CPU; ``"cpu"``; ``"cuda"`` or
``"cuda:N"`` (the N-th GPU). The device governs the whole guided path of a window: the prior (FFDNet
or the optional latent model), the start estimate's tensor, the data term and its operators, the
per-tile plan's step-synchronous sampling and the temporal pooling's alignment
(:mod:`spikeview.guided.temporal`). Counting spikes stays on the CPU (numba), and the random
numbers are drawn from the run's seeded CPU generator and moved, so a run on a GPU draws the same
noise as on the CPU and differs only by the arithmetic (TF32 convolutions; BENCHMARKS.md "GPU").

A device that is not there is refused in one sentence (:func:`resolve_device`); the plan prints the
device and its name (:func:`describe_device`) and every output's metadata records it.
"""

from __future__ import annotations

import functools
import platform
from pathlib import Path
from typing import Any

from spikeview.errors import ParameterError

#: the values ``guided.device`` takes (``cuda:N`` for any N)
DEVICES = ("auto", "cpu", "cuda")


def check_device_name(value: str, name: str = "guided.device") -> str:
    """``value`` if it is a device name this project takes (auto, cpu, cuda, cuda:N), else one sentence.

    Checked without importing torch (the recipe is validated before torch loads)."""
    text = str(value).strip().lower()
    if text in DEVICES:
        return text
    head, sep, tail = text.partition(":")
    if head == "cuda" and sep and tail.isdigit():
        return text
    raise ParameterError(f"{name} = {value!r} is not a device: use auto, cpu, cuda or cuda:N (N = the GPU's index, from 0).")


def resolve_device(device: Any = "auto") -> Any:
    """The ``torch.device`` of ``device`` (a ``guided.device`` value or a ``torch.device``).

    Raises:
        ParameterError: not a device name, CUDA asked for where torch sees none, or a GPU index past the
            last GPU (one sentence naming the flag and the fix).
    """
    import torch

    if isinstance(device, torch.device):
        spec = str(device)
    else:
        spec = check_device_name("auto" if device is None else device)
    if spec == "auto":
        return torch.device("cuda:0") if cuda_count() > 0 else torch.device("cpu")
    if spec == "cpu":
        return torch.device("cpu")
    if cuda_count() == 0:
        build = torch.__version__ + (" (a CPU-only build)" if torch.version.cuda is None else "")
        raise ParameterError(
            f"--device {spec} (guided.device) asks for a CUDA GPU but torch {build} sees none on this machine: "
            "use --device auto or cpu, or install a CUDA build of torch where there is a GPU."
        )
    dev = torch.device(spec)
    index = 0 if dev.index is None else dev.index
    if index >= cuda_count():
        raise ParameterError(
            f"--device {spec} (guided.device) names GPU {index} but torch sees {cuda_count()} GPU(s) (cuda:0 to "
            f"cuda:{cuda_count() - 1}): use one of those or auto."
        )
    return torch.device("cuda", index)


def cuda_count() -> int:
    """GPUs torch can use here (0 without a CUDA build, a driver or a GPU)."""
    import torch

    try:
        return int(torch.cuda.device_count()) if torch.cuda.is_available() else 0
    except (AssertionError, RuntimeError):  # a build or driver that cannot answer: no GPU
        return 0


@functools.lru_cache(maxsize=8)
def device_name(device: str) -> str:
    """A person's name for ``device`` (``"NVIDIA H100 80GB HBM3"``, or the CPU's model)."""
    import torch

    dev = torch.device(device)
    if dev.type == "cuda":
        return str(torch.cuda.get_device_name(dev))
    return cpu_model()


@functools.lru_cache(maxsize=4)
def cpuinfo_field(name: str) -> str:
    """The first ``name : value`` of ``/proc/cpuinfo`` (``""`` where it cannot be read, e.g. not Linux)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="ascii", errors="replace")
    except OSError:
        return ""
    for line in text.splitlines():
        if line.startswith(name):
            return line.split(":", 1)[1].strip()
    return ""


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; the platform's words, or ``"CPU"``, elsewhere)."""
    return cpuinfo_field("model name") or platform.processor() or platform.machine() or "CPU"


def device_label(device: Any) -> str:
    """``"cuda:0"`` or ``"cpu"`` for ``device`` (resolved)."""
    dev = resolve_device(device)
    return f"{dev.type}:{dev.index}" if dev.type == "cuda" else "cpu"


def describe_device(device: Any) -> str:
    """What the plan's ``device`` row says beside the label: ``"NVIDIA H100 80GB HBM3, guided.device = auto"``."""
    dev = resolve_device(device)
    how = "" if isinstance(device, str) is False else f", guided.device = {device}"
    return f"{device_name(str(dev))}{how}"


def is_cuda(device: Any) -> bool:
    """``device`` (a torch.device or tensor) is a CUDA device."""
    return getattr(device, "type", getattr(getattr(device, "device", None), "type", "cpu")) == "cuda"


def module_device(module: Any) -> Any:
    """The device a prior runs on: its first parameter's, its ``device`` attribute's, else the CPU."""
    import torch

    dev = getattr(module, "device", None)
    if isinstance(dev, torch.device):
        return dev
    params = getattr(module, "parameters", None)
    if callable(params):
        for p in params():
            return p.device
    inner = getattr(module, "prior", None)  # wrappers (AtPrecision, a tile's per-pixel noise map)
    if inner is not None and inner is not module:
        return module_device(inner)
    return torch.device("cpu")


def randn(shape: Any, generator: Any, dtype: Any, device: Any) -> Any:
    """Normal noise of ``shape`` from ``generator`` (the run's seeded CPU generator) on ``device``: the same
    numbers on every device, so a GPU run draws the noise a CPU run draws."""
    import torch

    gen_dev = generator.device if generator is not None else torch.device("cpu")
    z = torch.randn(tuple(shape), generator=generator, dtype=dtype, device=gen_dev)
    return z if z.device == torch.device(device) else z.to(device, non_blocking=True)
