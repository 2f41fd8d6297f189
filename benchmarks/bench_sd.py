"""Time the guided sampler with the latent-diffusion prior (:class:`spikeview.guided.sampler.GuidedSampler`, ``prior="sd"``).

Random weights at the real architecture's size: the SD 2.1 UNet (865 M parameters) and the SD VAE
(84 M), written out from their published configs (no weights are downloaded). Speed does not depend
on the weights' values, only on the shapes, so these figures hold for the real model.

Reported per configuration: median seconds per frame over ``--repeats`` frames after one warm-up
frame, per-step milliseconds, and peak GPU memory; plus, as baselines measured in the same process,
the cost of one UNet forward, one UNet forward+backward (input gradient only, frozen weights), one VAE
decode and one decode forward+backward, and the unguided sampler (``s = 0``: no backprop, i.e.
plain SDEdit-DDIM), so ``DPS / unguided`` is the price of the guidance.

Usage::

    python benchmarks/bench_sd.py --size 512 --steps 20 50 --dtype float16 bfloat16 float32
    python benchmarks/bench_sd.py --model tiny --size 64 --steps 4 --dtype float32   # CPU smoke run

Writes a JSON summary with ``--json PATH``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spikeview.errors import ParameterError  # noqa: E402
from spikeview.guided.config import GuidedConfig  # noqa: E402
from spikeview.guided.observation import Observation  # noqa: E402
from spikeview.guided.sampler import GuidedSampler  # noqa: E402
from spikeview.guided.priors.sd import LatentDiffusionPrior, import_diffusers  # noqa: E402
from spikeview.guided.priors.sd_arch import SD21_UNET, SD_VAE, TINY_UNET, TINY_VAE, random_modules  # noqa: E402


def build_prior(model: str, device: str, dtype: str, seed: int = 0) -> LatentDiffusionPrior:
    """A randomly initialised prior of the given architecture (``"sd21"`` or ``"tiny"``)."""
    unet_cfg, vae_cfg = (SD21_UNET, SD_VAE) if model == "sd21" else (TINY_UNET, TINY_VAE)
    dev = torch.device("cuda" if device == "auto" and torch.cuda.is_available() else ("cpu" if device == "auto" else device))
    unet, vae, sched = random_modules(unet_cfg, vae_cfg, seed=seed, device=dev)
    return LatentDiffusionPrior(unet, vae, sched, device=dev, dtype=dtype, source=f"random {model}")


def make_observation(size: int, seed: int = 0) -> Observation:
    """A 10-tick TFP observation of a smooth random scene (RGGB, η = 2, gray-world α)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    scene = np.stack([0.5 + 0.4 * np.sin(6 * xx + 2 * c) * np.cos(4 * yy - c) for c in range(3)], -1)
    scene = np.clip(scene + 0.05 * rng.standard_normal(scene.shape), 0, 1)
    cfa = np.zeros((size, size), dtype=np.int64)
    cfa[0::2, 1::2] = 1
    cfa[1::2, 0::2] = 1
    cfa[1::2, 1::2] = 2
    p = 0.5 * np.take_along_axis(scene, cfa[..., None], -1)[..., 0]
    y = (rng.binomial(10, p) / 10).astype(np.float32)
    alpha = np.array([1.0 / max(y[cfa == c].mean(), 1e-3) for c in range(3)])
    return Observation(y, "RGGB", 10, alpha, 2.0)


def _sync(dev: torch.device) -> None:
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)


def _median_time(fn, dev: torch.device, repeats: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    _sync(dev)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        _sync(dev)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def component_times(prior: LatentDiffusionPrior, size: int, repeats: int) -> dict[str, float]:
    """Median seconds of one UNet forward, UNet fwd+bwd, VAE decode, decode fwd+bwd at ``size``."""
    dev = prior.device
    h = size // prior.vae_factor
    z = torch.randn(1, prior.latent_channels, h, h, device=dev)

    def unet_fwd():
        with torch.no_grad():
            prior.model_output(z, 500)

    def unet_bwd():
        zz = z.clone().requires_grad_(True)
        prior.model_output(zz, 500).square().mean().backward()

    def dec_fwd():
        with torch.no_grad():
            prior.decode(z)

    def dec_bwd():
        zz = z.clone().requires_grad_(True)
        prior.decode(zz).square().mean().backward()

    return {name: _median_time(fn, dev, repeats) for name, fn in
            (("unet_fwd", unet_fwd), ("unet_fwd_bwd", unet_bwd), ("decode_fwd", dec_fwd), ("decode_fwd_bwd", dec_bwd))}


def time_sampler(prior: LatentDiffusionPrior, obs: Observation, cfg: GuidedConfig, repeats: int) -> dict:
    """Median seconds per frame of ``GuidedSampler.run`` with the latent prior (one warm-up frame first)."""
    dev = prior.device
    sampler = GuidedSampler(cfg, prior=prior)
    out: dict = {}

    def frame():
        try:
            out["x"] = sampler.run(obs, cfg)
            out["finite"] = True
        except ParameterError as e:  # random weights in half precision may overflow; the timing still counts
            out["finite"] = False
            out["error"] = str(e)

    if dev.type == "cuda":
        torch.cuda.reset_peak_memory_stats(dev)
    sec = _median_time(frame, dev, repeats)
    peak = torch.cuda.max_memory_allocated(dev) / 2**30 if dev.type == "cuda" else None
    return {"s_per_frame": sec, "ms_per_step": 1000 * sec / cfg.steps, "peak_gib": peak, "finite": out.get("finite"),
            "error": out.get("error"), "x": out.get("x")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", choices=("sd21", "tiny"), default="sd21")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--steps", type=int, nargs="+", default=[20, 50])
    ap.add_argument("--dtype", nargs="+", default=["float16"], choices=("float32", "float16", "bfloat16"))
    ap.add_argument("--device", default="auto")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--t-start", type=float, default=50 / 255, help="start noise level t_s, fraction of full scale (as everywhere)")
    ap.add_argument("--s", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    ap.add_argument("--no-components", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)

    if args.threads:
        torch.set_num_threads(args.threads)
    obs = make_observation(args.size)
    machine = {"python": platform.python_version(), "torch": torch.__version__, "diffusers": import_diffusers().__version__,
               "cpu": platform.processor() or platform.machine(), "threads": torch.get_num_threads(),
               "load_avg": [round(v, 2) for v in os.getloadavg()]}
    if torch.cuda.is_available() and args.device != "cpu":
        machine["gpu"] = torch.cuda.get_device_name(0)
    print(json.dumps(machine), flush=True)
    rows = []
    results = {}
    for dtype in args.dtype:
        t0 = time.perf_counter()
        prior = build_prior(args.model, args.device, dtype)
        print(f"built {prior} in {time.perf_counter() - t0:.1f} s", flush=True)
        if not args.no_components:
            comp = component_times(prior, args.size, args.repeats)
            print(f"[{dtype}] components (ms): " + ", ".join(f"{k} {1000 * v:.1f}" for k, v in comp.items()), flush=True)
            rows.append({"dtype": dtype, "what": "components", **{k: 1000 * v for k, v in comp.items()}})
        for steps in args.steps:
            base = GuidedConfig(prior="sd", guidance="dps", diffusion="always", steps=steps, t_start=args.t_start, s=0.0,
                                dtype=dtype, device=args.device)
            dps = base.replace(s=args.s)
            r0 = time_sampler(prior, obs, base, args.repeats)
            r1 = time_sampler(prior, obs, dps, args.repeats)
            results[(dtype, steps)] = r1.pop("x")
            r0.pop("x")
            row = {"dtype": dtype, "steps": steps, "size": args.size, "unguided_s": r0["s_per_frame"],
                   "dps_s": r1["s_per_frame"], "dps_ms_per_step": r1["ms_per_step"], "ratio": r1["s_per_frame"] / r0["s_per_frame"],
                   "peak_gib": r1["peak_gib"], "finite": r1["finite"], "error": r1["error"]}
            rows.append(row)
            print(json.dumps(row), flush=True)
        del prior
        if torch.cuda.is_available():
            torch.cuda.empty_cache()
    ref = results.get(("float32", args.steps[0]))
    for (dtype, steps), x in results.items():
        if ref is not None and x is not None and dtype != "float32" and steps == args.steps[0]:
            print(f"{dtype} vs float32 at {steps} steps: mean |diff| = {float(np.abs(x - ref).mean()):.4f}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"machine": machine, "args": vars(args) | {"json": str(args.json)}, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
