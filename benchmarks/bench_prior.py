"""The FFDNet prior's arithmetic on this CPU: speed of each path, and what each costs on the bench.

What it measures (one process, ``torch.set_num_threads(2)``; the machine is shared, so variants are
**interleaved** A, B, C, A, B, C … after a warm-up and the ratios are taken within the same run):

1. **one FFDNet pass** (RGB, σ = 25/255, no autograd) at 256² and 1000² for:
   ``eager float32`` (today's path: NCHW, the reference), ``channels-last float32`` (the float32
   path now: channels-last, strips), ``torch.compile`` (the channels-last body compiled with
   inductor; its warm-up reported separately; skipped without a C++ compiler), ``OpenVINO float32``
   (``float32-openvino``, the optional extra: what ``auto`` runs on its float32 steps where it is
   installed; left out with the reason otherwise), ``bf16 hidden layers`` (first/last layer float32)
   and ``bf16 all layers``;
2. **one guided frame** (the CLI's default recipe on a simulated demo capture of that size: gray-world
   α, white point, exposure, plan; ``GuidedSampler.run`` only, no start-up) for today's float32
   path, ``--precision float32`` and ``--precision auto`` (what this CPU resolves it to), and ``auto``
   with its float32 steps in torch (OpenVINO turned off) where OpenVINO is installed;
3. **quality** (``--quality``; ``--quality-json FILE`` reuses earlier rows): the held-out scenes of ``spikeview bench``
   (:mod:`spikeview.bench.data`, 256×256, 2 windows each) reconstructed with the default recipe under
   each mixed-precision candidate (which layers in bf16, how many final steps float32), PSNR/SSIM
   (gain-fitted, data_range 1, :func:`spikeview.bench.guided.score`) minus float32's on the same
   windows: mean and worst scene;
4. **peak memory** (``--memory``, on by default): ``ru_maxrss`` of a subprocess running
   ``spikeview reconstruct big.dat --method guided --at 100`` on a 1000×1000 capture (and 2000×2000
   with ``--big``), per precision.

**Fresh layer outputs**: float32 layer outputs over glibc's mmap threshold (32 MiB) were fresh mmapped pages
every layer (~270,000 page faults per 1000² pass). The first such pass in the main thread (as here and in
the CLI) now switches glibc's heap reuse on for the process (:mod:`spikeview.memory`); other threads (the
app's worker) write the fused path's outputs into two buffers per pass (``ffdnet.REUSE_BUFFERS``). Today's
eager baseline and the rows marked "fresh layer buffers (before)" run with both held off (``REUSE_BUFFERS``
False and :func:`spikeview.memory.glibc_default`: requests over 32 MiB are fresh mmaps again, as in a
process that never switched it on), so ``× today`` keeps its meaning and the gain is measured in the same
run; the memory section adds ``--precision float32`` with ``SPIKEVIEW_MALLOC_TUNE=0`` (no heap reuse: the
two buffers instead); the machine line records glibc's setting.

Also recorded: ``lscpu`` model name and the flags that matter (avx2, avx512f, avx512_bf16,
amx_bf16…), torch's CPU capability, the 1-minute load before and after, CPU seconds beside wall
seconds (wall ≫ CPU/2 means other processes took the cores).

Usage::

    python benchmarks/bench_prior.py              # speed and memory (~5 min quiet), writes benchmarks/results/prior.{md,json}
    python benchmarks/bench_prior.py --quality    # plus the PSNR/SSIM cost of each candidate (+ several minutes)
    python benchmarks/bench_prior.py --quick      # 256² frames, 1000² pass, 2–3 repeats, no writing (~1.5 min quiet)
    python benchmarks/bench_prior.py --quality-json benchmarks/results/prior.json --no-compile --repeats 3
                                                  # speed only, quality rows kept (~6 min quiet)

An **AVX2-only CPU** is played by this one in a child process with ``ONEDNN_MAX_CPU_ISA=AVX2
ATEN_CPU_CAPABILITY=avx2`` (set before torch loads; ``auto`` then resolves as on an AVX2 CPU): its
guided frames against today's path in the same child (``--no-avx2`` skips it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FLAGS = ("avx2", "avx512f", "avx512_bf16", "avx512_vnni", "avx512_fp16", "amx_tile", "amx_bf16", "amx_int8")
#: candidates measured for quality: name -> (guided.precision, layers in bf16, bf16 on steps with σ >= threshold);
#: the default 6 steps run at σ = 50, 31.5, 19.9, 12.6, 7.9, 5 /255; bf16 layers carry the bias correction
#: of their rounded weights (float32 bias, FFDNetDenoiser._layers)
CANDIDATES = {
    "float32-fast (NNPACK)": ("float32-fast", None, None),
    "bf16 hidden, σ ≥ 30/255 (2 of 6 steps)": ("bfloat16-mixed", "bfloat16", 30 / 255),
    "bf16 hidden, σ ≥ 18/255 (3 of 6 steps)": ("bfloat16-mixed", "bfloat16", 18 / 255),
    "bf16 hidden, σ ≥ 12/255 (4 of 6 steps)": ("bfloat16-mixed", "bfloat16", 12 / 255),
    "bf16 hidden, all but the last step": ("bfloat16-mixed", "bfloat16", 6 / 255),
    "bf16 hidden, every step": ("bfloat16-mixed", "bfloat16", 0.0),
    "bf16 all layers, σ ≥ 18/255 (3 of 6 steps; the default)": ("bfloat16-mixed", "bfloat16-all", 18 / 255),
    "bf16 all layers, σ ≥ 12/255 (4 of 6 steps)": ("bfloat16-mixed", "bfloat16-all", 12 / 255),
    "bf16 all layers, all but the last step": ("bfloat16-mixed", "bfloat16-all", 6 / 255),
}


# ------------------------------------------------------------------------------------ machine
def machine() -> dict:
    from spikeview.guided.precision import cpu_flags, cpu_summary

    model = platform.processor() or platform.machine()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except (OSError, subprocess.SubprocessError):
        pass
    import torch

    flags = cpu_flags()
    return {"model": model, "cpus": os.cpu_count(), "flags": [f for f in FLAGS if f in flags], "torch": torch.__version__,
            "capability": cpu_summary()["capability"], "onednn_bf16": cpu_summary()["onednn_bf16"],
            "openvino": cpu_summary().get("openvino", ""), "bf16_speedup": cpu_summary().get("bf16_speedup"),
            "compiler": shutil.which(os.environ.get("CXX", "g++")) or shutil.which("cc") or "", "load_before": os.getloadavg()[0]}


# ----------------------------------------------------------------------------- the reference
def reference_forward(net, x, sigma):
    """Today's FFDNet forward before this benchmark's changes: NCHW, float32, out-of-place ReLU."""
    import torch
    import torch.nn.functional as F

    h, w = x.shape[-2:]
    pad_h, pad_w = h % 2, w % 2
    xp = F.pad(x, (0, pad_w, 0, pad_h), mode="reflect") if (pad_h or pad_w) else x
    nmap = net._noise_map(sigma, x, (pad_h, pad_w))
    feats = torch.cat((nmap, F.pixel_unshuffle(xp, 2)), dim=1)
    last = len(net.weight) - 1
    for i, (weight, bias) in enumerate(zip(net.weight, net.bias, strict=True)):
        feats = F.conv2d(feats, weight.to(x.dtype), bias.to(x.dtype), padding=1)
        if i < last:
            feats = F.relu(feats)
    return (xp - F.pixel_shuffle(feats, 2))[..., :h, :w]


class ReferencePrior:
    """The FFDNet prior as it ran before (NCHW float32 eager) for the sampler: the 1.0× baseline."""

    def __init__(self, net):
        self.net, self.channels, self.sigma_max = net, net.channels, net.sigma_max

    def denoise(self, x, sigma):
        return reference_forward(self.net, x, sigma)


def interleaved(fns: dict, repeats: int, warmup: int = 1) -> dict:
    """Median wall and CPU seconds of each function, called A, B, C, A, B, C … after ``warmup`` rounds."""
    for _ in range(warmup):
        for f in fns.values():
            f()
    wall = {k: [] for k in fns}
    cpu = {k: [] for k in fns}
    for _ in range(repeats):
        for k, f in fns.items():
            c0, t0 = time.process_time(), time.perf_counter()
            f()
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.process_time() - c0)
    return {k: {"wall": statistics.median(wall[k]), "min": min(wall[k]), "cpu": statistics.median(cpu[k]),
                "n": repeats} for k in fns}


# ----------------------------------------------------------------------------------- 1. pass
def bench_pass(size: int, repeats: int, compile_ok: bool) -> dict:
    import torch

    from spikeview.guided.priors.ffdnet import FFDNetDenoiser

    net = FFDNetDenoiser(color=True)
    g = torch.Generator().manual_seed(size)
    x = torch.rand(1, 3, size, size, generator=g)
    s = 25.0 / 255.0
    ng = torch.inference_mode
    fns = {"eager float32 (today)": _glibc_default(lambda: _nog(ng, reference_forward, net, x, s)),
           "channels-last float32, unfused (before)": lambda: _unfused(ng, net, x, s, "float32"),
           "channels-last float32": lambda: _nog(ng, net, x, s, "float32"),
           "NNPACK float32 (float32-fast)": lambda: _nog(ng, net, x, s, "float32-fast"),
           "bf16 hidden layers": lambda: _nog(ng, net, x, s, "bfloat16"),
           "bf16 all layers": lambda: _nog(ng, net, x, s, "bfloat16-all")}
    extra = {}
    if _faults_matter(size, size):
        fns[f"channels-last float32, {BEFORE}"] = _glibc_default(fns["channels-last float32"])
    from spikeview.guided.priors import ov_backend

    if ov_backend.available():
        fns[OV_ROW] = lambda: _nog(ng, net, x, s, "float32-openvino")
    else:
        extra["openvino"] = "openvino not installed or not working here (pip install spikeview[openvino] to measure it)"
    if compile_ok:
        import torch.nn.functional as F

        layers = net._layers(torch.float32, "float32")
        body = torch.compile(lambda f: FFDNetDenoiser._body(f, layers, inplace=False), dynamic=False)

        def compiled():
            with torch.no_grad():
                nmap = net._noise_map(s, x, (0, 0))
                feats = torch.cat((nmap, F.pixel_unshuffle(x, 2)), dim=1).contiguous(memory_format=torch.channels_last)
                return x - F.pixel_shuffle(body(feats).contiguous(), 2)

        t0 = time.perf_counter()
        try:
            compiled()
            extra["compile_warmup_s"] = time.perf_counter() - t0
            fns["torch.compile float32 (channels-last)"] = compiled
        except Exception as e:  # noqa: BLE001 - inductor raises many kinds; the row is then left out with the reason
            extra["compile_error"] = f"{type(e).__name__}: {str(e).splitlines()[0][:160]}"
    ort_pass, why = onnx_pass(net, x, s)
    if ort_pass is not None:
        fns["ONNX Runtime float32 (optional, not used)"] = ort_pass
    else:
        extra["onnx"] = why
    with torch.inference_mode():
        ref = reference_forward(net, x, s)
        diffs = {"channels-last float32": float((net(x, s, "float32") - ref).abs().max()),
                 "NNPACK float32 (float32-fast)": float((net(x, s, "float32-fast") - ref).abs().max()),
                 "bf16 hidden layers": float((net(x, s, "bfloat16") - ref).abs().max()),
                 "bf16 all layers": float((net(x, s, "bfloat16-all") - ref).abs().max())}
        if OV_ROW in fns:
            diffs[OV_ROW] = float((net(x, s, "float32-openvino") - ref).abs().max())
        if ort_pass is not None:
            diffs["ONNX Runtime float32 (optional, not used)"] = float((ort_pass() - ref).abs().max())
        if "torch.compile float32 (channels-last)" in fns:
            diffs["torch.compile float32 (channels-last)"] = float((fns["torch.compile float32 (channels-last)"]() - ref).abs().max())
    res = interleaved(fns, repeats)
    return {"size": size, "rows": res, "max_abs_diff": diffs, **extra}


def onnx_pass(net, x, s):
    """One FFDNet pass with its conv stack in ONNX Runtime (CPU, float32, 2 threads), when the
    ``onnxruntime`` and ``onnx`` packages are installed (not a dependency): ``(callable, "")`` or
    ``(None, why not)``. The noise map, pixel (un)shuffle and ``x − residual`` stay in torch."""
    import importlib.util

    if importlib.util.find_spec("onnxruntime") is None or importlib.util.find_spec("onnx") is None:
        return None, "onnxruntime/onnx not installed (pip install onnxruntime onnx to measure it)"
    import torch
    import torch.nn.functional as F

    class Body(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.w = [w.detach() for w in net.weight]
            self.b = [b.detach() for b in net.bias]

        def forward(self, f):
            for i, (w, b) in enumerate(zip(self.w, self.b)):
                f = F.conv2d(f, w, b, padding=1)
                if i < len(self.w) - 1:
                    f = F.relu(f)
            return f

    try:
        import onnxruntime as ort

        with torch.no_grad():
            feats = torch.cat((net._noise_map(s, x, (0, 0)), F.pixel_unshuffle(x, 2)), dim=1)
        path = Path(tempfile.mkdtemp(prefix="bench_prior_onnx_")) / "ffdnet_body.onnx"
        torch.onnx.export(Body(), (feats,), str(path), input_names=["x"], output_names=["y"], opset_version=17, dynamo=False)
        so = ort.SessionOptions()
        so.intra_op_num_threads, so.inter_op_num_threads = 2, 1
        sess = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    except Exception as e:  # noqa: BLE001 - export/runtime raise many kinds; the row is left out with the reason
        return None, f"{type(e).__name__}: {str(e).splitlines()[0][:160] if str(e) else ''}"

    def run():
        with torch.no_grad():
            f = torch.cat((net._noise_map(s, x, (0, 0)), F.pixel_unshuffle(x, 2)), dim=1)
            r = torch.from_numpy(sess.run(None, {"x": f.numpy()})[0])
            return x - F.pixel_shuffle(r, 2)

    return run, ""


#: the pass row of OpenVINO's float32 conv stack (spikeview.guided.priors.ov_backend)
OV_ROW = "OpenVINO float32 (float32-openvino; auto's float32 steps)"
#: the frame row of auto with its float32 steps in torch (OpenVINO turned off)
TORCH_AUTO_ROW = "--precision auto, float32 steps in torch (no OpenVINO)"


def _torch_only(f):
    """``f`` with OpenVINO turned off (``ov_backend.available`` says no): torch runs every float32 step."""
    from spikeview.guided.priors import ov_backend

    def g():
        real = ov_backend.available
        ov_backend.available = lambda: False
        try:
            return f()
        finally:
            ov_backend.available = real
    return g


#: the rows measured with fresh layer outputs, as before (ffdnet.REUSE_BUFFERS off, spikeview.memory.glibc_default)
BEFORE = "fresh layer buffers (before)"


def _glibc_default(f):
    """``f`` with large float32 layer outputs fresh mmapped pages again (page-faulted every layer), as before:
    the fused path's two buffers off and glibc's heap reuse held off (:func:`spikeview.memory.glibc_default`)."""
    from spikeview import memory
    from spikeview.guided.priors import ffdnet

    def g():
        old = ffdnet.REUSE_BUFFERS
        ffdnet.REUSE_BUFFERS = False
        try:
            with memory.glibc_default():
                return f()
        finally:
            ffdnet.REUSE_BUFFERS = old
    return g


def _faults_matter(h: int, w: int) -> bool:
    """An ``h``×``w`` RGB frame's float32 layer strips outgrow glibc's dynamic mmap threshold (the heap reuse applies)."""
    from spikeview import memory
    from spikeview.guided.priors.ffdnet import strip_rows

    row = (w // 2) * 96 * 4
    return min(h // 2, strip_rows(row, 12) + 24) * row > memory.GLIBC_DYNAMIC_MAX


def _nog(ctx, f, *a):
    with ctx():
        return f(*a)


def _unfused(ctx, net, *a):
    """The pass with oneDNN's fused conv + ReLU on packed weights turned off (F.conv2d, then ReLU)."""
    from spikeview.guided.priors import ffdnet

    real = ffdnet.fused_ok
    ffdnet.fused_ok = lambda: False
    try:
        return _nog(ctx, net, *a)
    finally:
        ffdnet.fused_ok = real


# ------------------------------------------------------------------------------ 2. guided frame
def simulate(size: int, folder: Path) -> Path:
    """A demo capture of ``size``² (200 ticks) written by the CLI, as a user would."""
    out = folder / f"demo{size}.dat"
    if not out.exists():
        subprocess.run([sys.executable, "-m", "spikeview", "simulate", "--demo", "--size", str(size), "--ticks", "200",
                        "--out", str(out), "--overwrite"], check=True, capture_output=True)
    return out


def user_observation(path: Path, center: int = 100):
    """The observation and sampler settings ``spikeview reconstruct PATH --method guided --at CENTER`` uses."""
    from spikeview.guided.observation import Observation
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, sampler_params
    from spikeview.recipe import Recipe

    src = open_source(str(path))
    recipe = Recipe().with_values({"run.method": "guided"})
    state = prepare_sequence(src, recipe)
    params = sampler_params(recipe, state)
    return Observation.from_source(src, center, params.window, alpha=state.alpha, eta=params.eta, radius=0), params


def bench_frame(path: Path, repeats: int, variants: tuple[str, ...] = ("float32", "float32-fast", "bfloat16-mixed")) -> dict:
    import numpy as np

    from spikeview.guided.precision import resolve_precision
    from spikeview.guided.sampler import GuidedSampler, load_prior

    obs, params = user_observation(path)
    net = load_prior(params, 3)
    ref = GuidedSampler(params, prior=ReferencePrior(net))
    smp = GuidedSampler(params, prior=net)
    auto = resolve_precision("auto")[0]
    outs = {}

    def run(name, sampler, p):
        def f():
            outs[name] = sampler.run(obs, p)
        return f

    from spikeview.guided.priors import ov_backend

    fns = {"eager float32 (today)": _glibc_default(run("ref", ref, params.replace(precision="float32")))}
    for v in variants:
        fns[f"--precision {v}" + (" (auto)" if v == auto else "")] = run(v, smp, params.replace(precision=v))
    big = _faults_matter(*obs.shape[:2])
    for v in (("float32", auto) if big else ()):  # the float32 torch paths with and without the heap reuse
        if v in variants and v in ("float32", "float32-fast") and f"--precision {v}, {BEFORE}" not in fns:
            fns[f"--precision {v}, {BEFORE}"] = _glibc_default(run(f"{v} before", smp, params.replace(precision=v)))
    if auto == "bfloat16-mixed" and auto in variants and ov_backend.available():
        fns[TORCH_AUTO_ROW] = _torch_only(run("torch-auto", smp, params.replace(precision=auto)))
        if big:
            fns[f"{TORCH_AUTO_ROW}, {BEFORE}"] = _glibc_default(_torch_only(run("torch-auto before", smp, params.replace(precision=auto))))
    res = interleaved(fns, repeats)
    diff = {f"{k} vs today": float(np.abs(outs[k] - outs["ref"]).max()) for k in variants}
    if "torch-auto" in outs:
        diff["auto with OpenVINO vs auto in torch"] = float(np.abs(outs[auto] - outs["torch-auto"]).max())
    for k in [k for k in outs if k.endswith(" before")]:  # the heap reuse changes no pixel
        diff[f"{k.removesuffix(' before')} with vs without heap reuse"] = float(np.abs(outs[k] - outs[k.removesuffix(" before")]).max())
    return {"size": obs.shape[0], "rows": res, "max_abs_diff": diff, "auto": auto, "steps": params.steps,
            "mode": smp.info.mode}


# ----------------------------------------------------------------------------- 2b. AVX2-only
AVX2_ENV = {"ONEDNN_MAX_CPU_ISA": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"}


def run_avx2(repeats: int, quick: bool) -> dict:
    """The guided frames again in a child process whose oneDNN and ATen are capped at AVX2 (this CPU
    playing an AVX2-only one): today's eager float32 path against what ``auto`` resolves to there."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "avx2.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--isa-child", str(out), "--repeats", str(repeats)] + (["--quick"] if quick else [])
        r = subprocess.run(cmd, env={**os.environ, **AVX2_ENV}, capture_output=True, text=True)
        if r.returncode != 0 or not out.exists():
            return {"error": (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]}
        return json.loads(out.read_text(encoding="utf-8"))


def isa_child(out: Path, repeats: int, quick: bool) -> int:
    import torch

    from spikeview.guided.precision import cpu_summary, resolve_precision

    torch.set_num_threads(2)
    auto, why = resolve_precision("auto")
    res = {"env": {k: os.environ.get(k, "") for k in AVX2_ENV}, "capability": cpu_summary()["capability"],
           "onednn_bf16": cpu_summary()["onednn_bf16"], "auto": auto, "auto_reason": why, "load_before": os.getloadavg()[0],
           "frames": []}
    work = Path(tempfile.mkdtemp(prefix="bench_prior_avx2_"))
    try:
        for size in ((256,) if quick else (256, 1000)):
            res["frames"].append(bench_frame(simulate(size, work), 3 * repeats if size <= 256 else repeats, variants=(auto,)))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    res["load_after"] = os.getloadavg()[0]
    from spikeview import memory

    res["malloc"] = memory.state()
    out.write_text(json.dumps(res, indent=1), encoding="utf-8")
    return 0


# --------------------------------------------------------------------------------- 3. quality
def bench_quality(frames: int, size: int, scenes: list[str] | None) -> dict:
    import numpy as np

    from spikeview.bench.data import SCENES, TUNE_SCENES, make_cases
    from spikeview.bench.guided import Sequence, score
    from spikeview.guided import precision as prec
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import GuidedSampler, load_prior

    held = scenes or [n for n in SCENES if n not in TUNE_SCENES]
    prior = load_prior(GuidedConfig(), 3)
    smp = GuidedSampler(GuidedConfig(), prior=prior)
    rows: dict[str, dict[str, list]] = {}
    t0 = time.perf_counter()
    for case in make_cases(held, size=size, frames=frames):
        seq = Sequence(case.source)
        obs = seq.observation(case.center)
        f32 = score(smp.run(obs, GuidedConfig(precision="float32")), case.gt)
        for name, (precision, layers, threshold) in CANDIDATES.items():
            old = prec.MIXED_LAYERS, prec.MIXED_BF16_SIGMA
            prec.MIXED_LAYERS = layers or old[0]
            prec.MIXED_BF16_SIGMA = old[1] if threshold is None else threshold
            try:
                q = score(smp.run(obs, GuidedConfig(precision=precision)), case.gt)
            finally:
                prec.MIXED_LAYERS, prec.MIXED_BF16_SIGMA = old
            rows.setdefault(name, {}).setdefault(case.scene, []).append((q[0] - f32[0], q[1] - f32[1]))
    out = {}
    for name, per in rows.items():
        d = {sc: (float(np.mean([a for a, _ in v])), float(np.mean([b for _, b in v]))) for sc, v in per.items()}
        worst = min(d, key=lambda sc: d[sc][0])
        out[name] = {"dpsnr_mean": float(np.mean([a for a, _ in d.values()])), "dssim_mean": float(np.mean([b for _, b in d.values()])),
                     "dpsnr_worst": min(a for a, _ in d.values()), "dssim_worst": min(b for _, b in d.values()),
                     "worst_scene": worst, "per_scene": d}
    return {"scenes": held, "size": size, "frames": frames, "rows": out, "seconds": time.perf_counter() - t0}


def bench_quality_mono(size: int, scenes: list[str] | None) -> dict:
    """The default (``auto``) against ``float32`` on **monochrome** captures of the held-out scenes (the
    gray FFDNet, 15 layers of 64 features): Δ PSNR/SSIM per scene (2 windows), against the scene's
    ground truth averaged over colour (both paths are scored against the same image)."""
    import numpy as np

    from spikeview.bench.data import SCENES, TUNE_SCENES, make_capture
    from spikeview.bench.guided import Sequence, score
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.precision import resolve_precision
    from spikeview.guided.sampler import GuidedSampler

    held = scenes or [n for n in SCENES if n not in TUNE_SCENES]
    smp = GuidedSampler(GuidedConfig())
    auto = resolve_precision("auto")[0]
    per: dict[str, list] = {}
    t0 = time.perf_counter()
    for k, name in enumerate(held):
        cap = make_capture(name, size, n_ticks=200, seed=k, window=10, cfa="none")
        seq = Sequence(cap)
        for c in (65, 135):
            gt = cap.gt_at(c)
            gt = gt if gt.ndim == 2 else gt.mean(axis=-1)
            obs = seq.observation(c)
            a = score(smp.run(obs, GuidedConfig(precision="float32")), gt)
            q = score(smp.run(obs, GuidedConfig(precision=auto)), gt)
            per.setdefault(name, []).append((q[0] - a[0], q[1] - a[1]))
    d = {sc: (float(np.mean([x for x, _ in v])), float(np.mean([y for _, y in v]))) for sc, v in per.items()}
    return {"precision": auto, "scenes": held, "size": size, "per_scene": d,
            "dpsnr_mean": float(np.mean([x for x, _ in d.values()])), "dssim_mean": float(np.mean([y for _, y in d.values()])),
            "dpsnr_worst": min(x for x, _ in d.values()), "dssim_worst": min(y for _, y in d.values()),
            "worst_scene": min(d, key=lambda sc: d[sc][0]), "seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------- 4. memory
def run_cli(path: Path, extra: list[str], row: str, env: dict | None = None) -> dict:
    """``spikeview reconstruct PATH --method guided --at 100 EXTRA`` in a child process: its peak RSS (MB),
    wall seconds and exit status, and the plan's row starting with ``row`` (as printed)."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "frame.npy"
        code = ("import resource, subprocess, sys, time; t = time.perf_counter(); "
                "r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
                "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, time.perf_counter() - t, r.returncode); "
                "sys.stderr.write(r.stderr[-3000:])")
        cmd = [sys.executable, "-c", code, sys.executable, "-m", "spikeview", "reconstruct", str(path), "--method", "guided",
               "--at", "100", "--out", str(out), "--overwrite", *extra]
        r = subprocess.run(cmd, capture_output=True, text=True, env=None if env is None else {**os.environ, **env})
        kb, wall, rc = r.stdout.split()
        line = next((ln.strip() for ln in r.stderr.splitlines() if ln.strip().startswith(row)), "")
        return {"peak_mb": int(kb) / 1024, "wall_s": float(wall), "rc": int(rc), "row": line}


def peak_rss(path: Path, precision: str, env: dict | None = None) -> dict:
    """Peak RSS (MB) and wall seconds of ``spikeview reconstruct PATH --method guided --at 100`` in a child
    (``env``: extra environment variables, named in the row's precision column)."""
    r = run_cli(path, ["--precision", precision], "precision", env)
    label = precision + "".join(f" ({k}={v})" for k, v in (env or {}).items())
    return {"precision": label, "peak_mb": r["peak_mb"], "wall_s": r["wall_s"], "rc": r["rc"], "plan": r["row"]}


#: the CLI with glibc's heap reuse held off (spikeview.memory): the float32 path's memory before it
MALLOC_OFF = {"SPIKEVIEW_MALLOC_TUNE": "0"}


# ---------------------------------------------------------------------------------- report
def write_report(res: dict, out: Path) -> None:
    m = res["machine"]
    L = ["# FFDNet prior: precision and backend (benchmarks/bench_prior.py)", "",
         f"Machine: {m['model']}, {m['cpus']} CPUs, flags {' '.join(m['flags']) or '(none of ' + ', '.join(FLAGS) + ')'}; "
         f"torch {m['torch']} (CPU capability {m['capability']}, oneDNN bf16 {m['onednn_bf16']}; auto's probe: a bfloat16 "
         f"layer {'not measured' if m.get('bf16_speedup') is None else format(m['bf16_speedup'], '.2f') + 'x'} as fast as "
         f"float32); "
         f"OpenVINO {m.get('openvino') or 'not installed'}; 2 threads; glibc heap reuse for large float32 passes "
         f"(spikeview.memory): {m.get('malloc', 'not recorded')}. "
         f"1-min load {m['load_before']:.1f} before, {res['load_after']:.1f} after. Command: `{res['command']}`; "
         f"{res['minutes']:.1f} min.", "",
         "Medians of interleaved repeats after a warm-up; × = eager float32 (today) / this, in the same run. "
         "CPU s is the process's CPU time (2 threads): wall ≫ CPU/2 means other jobs held the cores.", ""]
    for p in res["passes"]:
        base = p["rows"]["eager float32 (today)"]["wall"]
        L += [f"## One FFDNet pass, {p['size']}×{p['size']} RGB", "", "| path | median wall s | min s | CPU s | × today | max abs diff vs today |",
              "|---|---|---|---|---|---|"]
        for k, v in p["rows"].items():
            d = p["max_abs_diff"].get(k)
            L.append(f"| {k} | {v['wall']:.3f} | {v['min']:.3f} | {v['cpu']:.3f} | {base / v['wall']:.2f}× | {'—' if d is None else f'{d:.2g}'} |")
        if "compile_warmup_s" in p:
            L.append(f"\ntorch.compile warm-up (first call, compiling): {p['compile_warmup_s']:.1f} s.")
        if "compile_error" in p:
            L.append(f"\ntorch.compile unavailable: {p['compile_error']}.")
        if "onnx" in p:
            L.append(f"\nONNX Runtime not measured in this run: {p['onnx']}.")
        if "openvino" in p:
            L.append(f"\nOpenVINO not measured in this run: {p['openvino']}.")
        L.append("")
    for f in res["frames"]:
        base = f["rows"]["eager float32 (today)"]["wall"]
        L += [f"## One guided frame, {f['size']}×{f['size']} (CLI default recipe, {f['steps']} steps, sampler only)", "",
              "| path | median wall s | min s | CPU s | × today |", "|---|---|---|---|---|"]
        for k, v in f["rows"].items():
            L.append(f"| {k} | {v['wall']:.2f} | {v['min']:.2f} | {v['cpu']:.2f} | {base / v['wall']:.2f}× |")
        L += ["", "Max abs pixel difference vs today: " + ", ".join(f"{k} {v:.2g}" for k, v in f["max_abs_diff"].items()) + ".", ""]
    av = res.get("avx2")
    if av:
        L += ["## AVX2-only: the same CPU capped at AVX2 (child process, `ONEDNN_MAX_CPU_ISA=AVX2 ATEN_CPU_CAPABILITY=avx2`)", ""]
        if "error" in av:
            L += [f"Not measured: {av['error']}.", ""]
        else:
            L += [f"torch CPU capability {av['capability']}, oneDNN bf16 {av['onednn_bf16']}: `auto` resolves to **{av['auto']}** "
                  f"({av['auto_reason']}). 1-min load {av['load_before']:.1f} before, {av['load_after']:.1f} after; × in the same child run; "
                  f"glibc heap reuse: {av.get('malloc', 'not recorded')}.", ""]
            for f in av["frames"]:
                base = f["rows"]["eager float32 (today)"]["wall"]
                L += [f"| {f['size']}×{f['size']} guided frame | median wall s | min s | CPU s | × today |", "|---|---|---|---|---|"]
                for k, v in f["rows"].items():
                    L.append(f"| {k} | {v['wall']:.2f} | {v['min']:.2f} | {v['cpu']:.2f} | {base / v['wall']:.2f}× |")
                L.append("")
    q = res.get("quality")
    if q:
        L += [f"## Quality of the mixed-precision candidates (held-out bench scenes, {q['size']}×{q['size']}, {q['frames']} windows each)", "",
              f"Scenes: {', '.join(q['scenes'])}. Δ = candidate − float32 on the same windows (gain-fitted PSNR/SSIM, data_range 1). "
              f"Budget: ≥ −0.1 dB and ≥ −0.005 SSIM on every scene (worst scene shown).{' ' + q['note'] + '.' if q.get('note') else ''}", "",
              "| candidate | ΔPSNR mean | ΔSSIM mean | ΔPSNR worst scene | ΔSSIM worst | worst scene | within budget |", "|---|---|---|---|---|---|---|"]
        for k, v in q["rows"].items():
            ok = v["dpsnr_worst"] >= -0.1 and v["dssim_worst"] >= -0.005
            L.append(f"| {k} | {v['dpsnr_mean']:+.3f} | {v['dssim_mean']:+.4f} | {v['dpsnr_worst']:+.3f} | {v['dssim_worst']:+.4f} | "
                     f"{v['worst_scene']} | {'yes' if ok else 'no'} |")
        L.append("")
    qm = res.get("quality_mono")
    if qm:
        L += [f"### The default on monochrome captures (gray FFDNet; held-out scenes, {qm['size']}×{qm['size']}, 2 windows each)", "",
              f"`--precision {qm['precision']}` (auto) − float32 on the same windows, against the ground truth averaged over colour: "
              f"ΔPSNR mean {qm['dpsnr_mean']:+.3f}, worst {qm['dpsnr_worst']:+.3f} dB ({qm['worst_scene']}); ΔSSIM mean "
              f"{qm['dssim_mean']:+.4f}, worst {qm['dssim_worst']:+.4f}. Per scene: "
              + ", ".join(f"{sc} {v[0]:+.3f} dB / {v[1]:+.4f}" for sc, v in qm["per_scene"].items()) + ".", ""]
    big = [f for f in res["frames"] if f["size"] >= 1000]
    if big:
        f = big[0]
        L += ["## Worked estimate: 1 s of 1000×1000 capture (2,000 windows of 10 ticks)", "",
              "One 2-core machine runs a window with 2 threads (median wall s above); a Dask worker is a single-threaded "
              "process, so its cost per window is taken as the process CPU seconds of the same run (2 threads' CPU time ≈ one "
              "thread's work; Dask's own overhead, 0.4 ms a window (BENCHMARKS.md, Dask section), is negligible). Every window "
              "pays the full sampler (no reuse), the CLI's defaults otherwise.", "",
              "| path | s per window (2 threads) | CPU s per window | one 2-core machine | 1 worker | 8 workers | 64 workers |",
              "|---|---|---|---|---|---|---|"]
        for k, v in f["rows"].items():
            w, c = v["wall"], v["cpu"]
            L.append(f"| {k} | {w:.2f} | {c:.2f} | {_hours(2000 * w)} | {_hours(2000 * c)} | {_hours(2000 * c / 8)} | {_hours(2000 * c / 64)} |")
        L.append("")
    mem = res.get("memory") or []
    if mem:
        L += ["## Peak memory of `spikeview reconstruct big.dat --method guided --at 100` (child process ru_maxrss)", "",
              "| capture | --precision | peak MB | wall s (incl. start-up) | plan line |", "|---|---|---|---|---|"]
        for r in mem:
            L.append(f"| {r['capture']} | {r['precision']} | {r['peak_mb']:.0f} | {r['wall_s']:.1f} | {r['plan']} |")
        L.append("")
    out.write_text("\n".join(L), encoding="utf-8")


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h" if seconds >= 3600 else f"{seconds / 60:.0f} min"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256² frames, one 1000² pass, 3 repeats, 3 held-out scenes x 1 window")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--quality", action="store_true", help="also the PSNR/SSIM cost of each candidate on the held-out bench "
                    "scenes (256², 2 windows each: ~20 model runs per scene, several minutes)")
    ap.add_argument("--quality-json", type=Path, default=None, help="include quality rows measured before (prior.json or "
                    "the JSON of bench_quality) instead of measuring them")
    ap.add_argument("--no-memory", dest="memory", action="store_false")
    ap.add_argument("--no-compile", dest="compile", action="store_false")
    ap.add_argument("--big", action="store_true", help="also the peak memory of a 2000x2000 frame")
    ap.add_argument("--out", type=Path, default=None, help="folder for prior.md/prior.json (default benchmarks/results; "
                    "--quick writes nothing unless given)")
    ap.add_argument("--report-only", type=Path, default=None, help="re-write prior.md from a prior.json")
    ap.add_argument("--no-avx2", dest="avx2", action="store_false", help="skip the AVX2-only run (this CPU capped by "
                    "ONEDNN_MAX_CPU_ISA=AVX2 ATEN_CPU_CAPABILITY=avx2 in a child process)")
    ap.add_argument("--isa-child", type=Path, default=None, help=argparse.SUPPRESS)  # the AVX2 child: JSON out
    a = ap.parse_args(argv)
    if a.isa_child is not None:
        return isa_child(a.isa_child, a.repeats or 3, quick=a.quick)
    if a.report_only is not None:
        write_report(json.loads(a.report_only.read_text(encoding="utf-8")), a.report_only.with_suffix(".md"))
        print(f"wrote {a.report_only.with_suffix('.md')}")
        return 0
    import torch

    torch.set_num_threads(2)
    t_start = time.time()
    res: dict = {"machine": machine(), "command": "python benchmarks/bench_prior.py" + (" " + " ".join(argv or sys.argv[1:])).rstrip()}
    print(f"{res['machine']['model']}: flags {res['machine']['flags']}, load {res['machine']['load_before']:.1f}", flush=True)
    rep = a.repeats or 3
    compile_ok = a.compile and bool(res["machine"]["compiler"])
    res["passes"] = []
    for size in ((256, 1000)):
        r = bench_pass(size, rep if size <= 256 or not a.quick else 2, compile_ok and size <= (256 if a.quick else 1000))
        res["passes"].append(r)
        print(f"pass {size}: " + ", ".join(f"{k} {v['wall']:.3f}s" for k, v in r["rows"].items()), flush=True)
    work = Path(tempfile.mkdtemp(prefix="bench_prior_"))
    try:
        res["frames"] = []
        for size in ((256,) if a.quick else (256, 1000)):
            r = bench_frame(simulate(size, work), 3 * rep if size <= 256 else rep)  # 256²: < 0.5 s a run, noisy
            res["frames"].append(r)
            print(f"frame {size}: " + ", ".join(f"{k} {v['wall']:.2f}s" for k, v in r["rows"].items()), flush=True)
        if a.avx2:
            res["avx2"] = run_avx2(a.repeats or 3, a.quick)
            for f in res["avx2"].get("frames", []):
                print(f"AVX2 frame {f['size']}: " + ", ".join(f"{k} {v['wall']:.2f}s" for k, v in f["rows"].items()), flush=True)
        if a.quality_json is not None:
            q = json.loads(a.quality_json.read_text(encoding="utf-8"))
            res["quality"] = q.get("quality", q)
            res["quality"]["note"] = f"measured earlier, read from {a.quality_json.name}"
        elif a.quality:
            res["quality"] = bench_quality(1 if a.quick else 2, 128 if a.quick else 256,
                                           ["rocket", "colorwheel", "page_bright"] if a.quick else None)
        if res.get("quality"):
            for k, v in res["quality"]["rows"].items():
                print(f"quality {k}: ΔPSNR mean {v['dpsnr_mean']:+.3f} worst {v['dpsnr_worst']:+.3f} ({v['worst_scene']}), "
                      f"ΔSSIM mean {v['dssim_mean']:+.4f} worst {v['dssim_worst']:+.4f}", flush=True)
        res["quality_mono"] = bench_quality_mono(128 if a.quick else 256, ["rocket", "page_bright"] if a.quick else None)
        qm = res["quality_mono"]
        print(f"quality mono ({qm['precision']}): ΔPSNR mean {qm['dpsnr_mean']:+.3f} worst {qm['dpsnr_worst']:+.3f} "
              f"({qm['worst_scene']}), ΔSSIM mean {qm['dssim_mean']:+.4f} worst {qm['dssim_worst']:+.4f}", flush=True)
        if a.memory:
            res["memory"] = []
            sizes = (256,) if a.quick else ((1000, 2000) if a.big else (1000,))
            for size in sizes:
                path = simulate(size, work)
                for precision, env in (("float32", None), ("auto", None), ("float32", MALLOC_OFF)):
                    r = peak_rss(path, precision, env)
                    r["capture"] = f"{size}×{size}"
                    res["memory"].append(r)
                    print(f"memory {size} {precision}: {r['peak_mb']:.0f} MB, {r['wall_s']:.1f} s, {r['plan']}", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    from spikeview import memory

    res["machine"]["malloc"] = memory.state()
    out = a.out if a.out is not None else (None if a.quick else ROOT / "benchmarks" / "results")
    return save_results(res, out, "prior", write_report, t_start)


def save_results(res: dict, out: Path | None, name: str, write: Any, t_start: float) -> int:
    """Note the load and minutes in ``res``, write ``out/<name>.json`` and ``write(res, out/<name>.md)``
    (nothing when ``out`` is None), print the load line; returns the exit status 0."""
    res["load_after"] = os.getloadavg()[0]
    res["minutes"] = (time.time() - t_start) / 60
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{name}.json").write_text(json.dumps(res, indent=1), encoding="utf-8")
        write(res, out / f"{name}.md")
        print(f"wrote {out / f'{name}.md'}")
    print(f"load {res['machine']['load_before']:.1f} -> {res['load_after']:.1f}, {res['minutes']:.1f} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
