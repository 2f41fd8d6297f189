"""OpenVINO's CPU runtime for the FFDNet conv stack in float32 (the optional extra ``openvino``).

The 3×3 conv + ReLU stack of :class:`~spikeview.guided.priors.ffdnet.FFDNetDenoiser` (BatchNorm
folded, the same float32 weights and biases) is built directly as an OpenVINO graph (``opset13``
convolution + add + relu, no tracing, no file, no network) with dynamic batch, height and width, and
compiled once per weights for the CPU with ``INFERENCE_PRECISION_HINT=f32``, the latency hint and
torch's thread count. The rest of the pass (noise map, pixel (un)shuffle, ``x − residual``, strips)
stays in torch.

Why: on a 2-core AMD EPYC (AVX-512, AVX512-BF16, no AMX) one float32 RGB pass at 1000² took
1.2–1.5× less time (and 1.2–1.3× less CPU) than torch's fused oneDNN channels-last path, interleaved
in one process, with the same numbers (max difference 0 at 256² and 1000², RGB and gray: OpenVINO's
CPU plugin runs the same oneDNN ``brgconv`` kernels); no gain at 256². The gain is memory, not
arithmetic: torch allocates every layer's output afresh, and glibc serves a 51 MB strip by ``mmap``,
so a torch pass takes ~270,000 page faults; OpenVINO reuses its buffers. With glibc's mmap threshold
raised (``MALLOC_MMAP_THRESHOLD_``) torch's pass is as fast (0.99 vs 1.00 s). OpenVINO's own
bfloat16 was not faster than torch's on that CPU and its error was larger (1.3–1.8/255 RMS against
1.0/255 with the bias-corrected torch layers), so only float32 goes here. Figures:
``benchmarks/bench_prior.py`` (the OpenVINO rows).

:func:`available` probes once (import, compile a tiny stack, compare with ``F.conv2d``); where
it fails the prior keeps torch's path (:mod:`spikeview.guided.precision` decides which steps use
this). A pass runs asynchronously and polls the job's cancel flag every few milliseconds, so Cancel
still takes effect inside a pass.

OpenVINO is imported through :func:`_openvino`: ``import openvino`` also imports its model converter, whose telemetry
sends an event over the network on import (and on Ctrl-C printed a child process's traceback); spikeview uses the
runtime only, and imports it with the telemetry package blocked, so the converter takes its own no-op stub.
"""

from __future__ import annotations

import functools
import sys
import threading

import torch

from spikeview.errors import check_cancelled

__all__ = ["OVStack", "OpenVINOFallbackWarning", "available", "give_up", "stack_for", "version"]

_IMPORT_LOCK = threading.Lock()
_OV = None


def _openvino():
    """The ``openvino`` module, imported (once) with ``openvino_telemetry`` unimportable: its model converter then
    takes its no-op telemetry stub instead of sending an event over the network (see the module docstring). The
    import runs under a lock and the module is handed out only once it has finished (another thread had taken a
    half-imported module from ``sys.modules``)."""
    global _OV
    if _OV is not None and sys.modules.get("openvino") is _OV:
        return _OV
    with _IMPORT_LOCK:
        if _OV is None or sys.modules.get("openvino") is not _OV:
            block = "openvino_telemetry" not in sys.modules
            if block:
                sys.modules["openvino_telemetry"] = None  # type: ignore[assignment]  # an ImportError for whoever imports it
            try:
                import openvino
            finally:
                if block and sys.modules.get("openvino_telemetry", 0) is None:
                    del sys.modules["openvino_telemetry"]
            _OV = openvino
    return _OV


#: how often (ms) a running pass looks at the cancel flag
POLL_MS = 20


@functools.lru_cache(maxsize=1)
def version() -> str:
    """OpenVINO's version (``""`` where it is not installed or does not import)."""
    try:
        ov = _openvino()

        return str(ov.__version__).split("-")[0]
    except Exception:  # noqa: BLE001 - a broken install raises anything from ImportError to OSError
        return ""


def _build(weights: list[torch.Tensor], biases: list[torch.Tensor]):
    """The conv stack as an OpenVINO model: input ``(N, Cin, H, W)`` float32 (all dynamic but Cin)."""
    import numpy as np

    ov = _openvino()
    import openvino.opset13 as ops

    x = ops.parameter([-1, int(weights[0].shape[1]), -1, -1], np.float32, name="feats")
    y = x
    last = len(weights) - 1
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        wc = ops.constant(w.detach().to(torch.float32).contiguous().numpy())
        bc = ops.constant(b.detach().to(torch.float32).reshape(1, -1, 1, 1).contiguous().numpy())
        y = ops.add(ops.convolution(y, wc, [1, 1], [1, 1], [1, 1], [1, 1]), bc)
        if i < last:
            y = ops.relu(y)
    return ov.Model([y], [x], "ffdnet_stack")


class OVStack:
    """One compiled float32 conv stack (any batch/height/width); ``run`` is thread-safe (one infer
    request, one pass at a time: a request kept per thread in ``threading.local`` was destroyed while
    its thread's Python state was torn down, and the app crashed on quitting after a guided run)."""

    def __init__(self, weights: list[torch.Tensor], biases: list[torch.Tensor], threads: int | None = None):
        ov = _openvino()
        self.threads = int(threads or torch.get_num_threads())
        core = ov.Core()
        self.compiled = core.compile_model(_build(weights, biases), "CPU", {
            "INFERENCE_PRECISION_HINT": "f32", "PERFORMANCE_HINT": "LATENCY", "INFERENCE_NUM_THREADS": self.threads})
        self._lock = threading.Lock()
        self._req = None

    def _request(self):
        if self._req is None:
            self._req = self.compiled.create_infer_request()
        return self._req

    def run(self, feats: torch.Tensor) -> torch.Tensor:
        """The stack on ``feats`` ``(N, Cin, h, w)`` float32 (any memory format) → ``(N, Cout, h, w)``
        (a new tensor). Raises :class:`~spikeview.errors.Cancelled` within :data:`POLL_MS` of the
        job's Cancel."""
        import numpy as np

        ov = _openvino()
        # the request reads this memory without owning it: ``x`` stays referenced until the pass is over
        x = feats.detach().to(torch.float32).contiguous().numpy()
        with self._lock:
            req = self._request()
            req.set_input_tensor(0, ov.Tensor(x, shared_memory=True))
            req.start_async()
            try:
                while not req.wait_for(POLL_MS):
                    check_cancelled("inside a prior pass (OpenVINO)")
            except BaseException:
                req.cancel()
                try:
                    req.wait()
                except Exception:  # noqa: BLE001 - a cancelled request may report its cancellation
                    pass
                raise
            out = torch.from_numpy(np.array(req.get_output_tensor(0).data, copy=True))
        del x
        return out


class OpenVINOFallbackWarning(RuntimeWarning):
    """OpenVINO failed during a run: the prior's float32 steps run in torch from then on (the same numbers)."""


#: why OpenVINO was given up in this process (``None``: it was not)
_gave_up: str | None = None


def give_up(error: BaseException) -> None:
    """OpenVINO failed while compiling the real weights or running a pass (out of memory, an unusual
    CPU…): warn once and let torch run every later float32 step of the process (the numbers are the
    same, only the time differs; the pass that failed is recomputed in torch by the caller)."""
    global _gave_up
    if _gave_up is None:
        _gave_up = f"{type(error).__name__}: {error}"
        import warnings

        warnings.warn(f"OpenVINO failed ({_gave_up}); the prior's float32 steps run in torch from now on "
                      "(the same numbers, more time).", OpenVINOFallbackWarning, stacklevel=3)


def stack_for(model) -> OVStack | None:
    """The compiled stack of ``model`` (an :class:`FFDNetDenoiser`; cached on it per weights
    version and thread count), or None where OpenVINO is not :func:`available` (or failed to compile it)."""
    if not available():
        return None
    key = (tuple((w.data_ptr(), w._version) for w in model.weight), torch.get_num_threads())
    cached = model.__dict__.get("_ov_stack")
    if cached is None or cached[0] != key:
        try:
            cached = (key, OVStack(list(model.weight), list(model.bias)))
        except Exception as e:  # noqa: BLE001 - whatever OpenVINO raises, torch computes the same numbers
            give_up(e)
            return None
        model.__dict__["_ov_stack"] = cached
    return cached[1]


def available() -> bool:
    """OpenVINO is installed, compiles a small conv stack for this CPU and gives ``F.conv2d``'s
    numbers (within 1e-5; checked once per process), and has not failed since (:func:`give_up`)."""
    if _gave_up is not None:
        return False
    with _PROBE_LOCK:  # one probe per process, also when a start-up thread asks at the same time
        return _probe()


_PROBE_LOCK = threading.Lock()


@functools.lru_cache(maxsize=1)
def _probe() -> bool:
    if not version():
        return False
    try:
        import torch.nn.functional as F

        g = torch.Generator().manual_seed(0)
        ws = [torch.randn(6, 5, 3, 3, generator=g) * 0.3, torch.randn(4, 6, 3, 3, generator=g) * 0.3]
        bs = [torch.randn(6, generator=g), torch.randn(4, generator=g)]
        x = torch.rand(1, 5, 7, 9, generator=g)
        ref = F.conv2d(F.relu(F.conv2d(x, ws[0], bs[0], padding=1)), ws[1], bs[1], padding=1)
        got = OVStack(ws, bs, threads=1).run(x)
        return tuple(got.shape) == tuple(ref.shape) and bool(torch.allclose(got, ref, atol=1e-5, rtol=1e-5))
    except Exception:  # noqa: BLE001 - any failure to build/compile/run means: use torch
        return False
