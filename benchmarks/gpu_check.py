"""The one-shot GPU check (issue 28): environment, CPU-vs-GPU agreement, timings, peak GPU memory.

Run by ``benchmarks/gpu_check.sh OUTDIR`` on a machine with a CUDA GPU (Python 3.12 and torch with CUDA
preinstalled, no package registry, no display): the project runs from the working tree (``PYTHONPATH``),
the pure-Python packages it lacks come along as wheels (``.whl/``, see the shell script).

Sections (each writes its rows to ``OUTDIR/gpu_check.json`` as it finishes, and the report
``OUTDIR/gpu_check.md`` at the end, so a run cut short keeps what it measured):

1. **environment**: GPU name and memory, torch / CUDA / cuDNN versions, CPU model and cores;
2. **agreement** on the held-out scenes of ``spikeview bench`` (256², 2 windows each, the user's path:
   gray-world α, white point, exposure, the default recipe with ±3 pooled windows): PSNR/SSIM against the
   truth (one global gain, data range 1: :func:`spikeview.bench.score.score`) of ``--device cpu
   --precision float32`` and of ``--device cuda`` (defaults), and their difference, mean and worst;
3. **FFDNet pass** (RGB, σ 25/255, no autograd) at 256², 1000², 2000² on the GPU: float32 (TF32) and
   bfloat16 layers; median of 10 after 3 warm-ups, CUDA-synchronised;
4. **guided frame** with CLI defaults on a simulated demo capture (``spikeview simulate --demo``) at 256²,
   1000², 2000²: the window's observation (counting + temporal pooling), its plan, the sampler, and the
   whole (what ``reconstruct --at`` spends per window after start-up); median of 3 after a warm-up;
5. **clip**: consecutive windows of a 1000² capture through :func:`spikeview.pipeline.reconstruct_windows`
   (the CLI's path for ``--range``), up to ``--clip-windows`` (300) or ``--clip-seconds``: frames/s and the
   estimate for one second of capture (2,000 windows);
6. **peak GPU memory** of each section (``torch.cuda.max_memory_allocated``).

Usage: ``python benchmarks/gpu_check.py --out OUTDIR [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def log(*a) -> None:
    print(*a, flush=True)


def sync() -> None:
    import torch

    if torch.cuda.is_available():
        torch.cuda.synchronize()


def timed(fn, repeats: int, warmup: int = 1) -> tuple[float, float, object]:
    out = None
    for _ in range(warmup):
        out = fn()
        sync()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        sync()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts), out


def environment() -> dict:
    import numpy as np
    import torch

    from spikeview.guided.device import describe_device, device_name

    env = {"python": platform.python_version(), "torch": torch.__version__, "cuda": torch.version.cuda,
           "cudnn": torch.backends.cudnn.version() if torch.backends.cudnn.is_available() else None,
           "numpy": np.__version__, "cpu": device_name("cpu"), "cpu_cores": os.cpu_count(),
           "gpus": torch.cuda.device_count() if torch.cuda.is_available() else 0,
           "tf32_conv": bool(torch.backends.cudnn.allow_tf32)}
    if env["gpus"]:
        p = torch.cuda.get_device_properties(0)
        env.update(gpu=p.name, gpu_memory_gib=round(p.total_memory / 2**30, 1), sm=p.multi_processor_count,
                   auto_device=describe_device("auto"))
    return env


def agreement(frames: int, quick: bool) -> dict:
    """Held-out scenes, the product's path on the CPU (float32) and on the GPU (defaults)."""
    import numpy as np
    import torch

    from spikeview.bench.data import SCENES, TUNE_SCENES, make_cases
    from spikeview.bench.score import score
    from spikeview.pipeline import exposure_mapping, prepare_sequence, reconstruct_windows, recipe_for_state
    from spikeview.recipe import Recipe

    names = [n for n in SCENES if n not in TUNE_SCENES]
    if quick:
        names = names[:2]
    cases = make_cases(names, size=256, frames=frames)
    rows = []
    torch.cuda.reset_peak_memory_stats()
    for c in cases:
        row = {"scene": c.scene, "group": c.group, "center": c.center}
        for dev, extra in (("cpu", {"guided.precision": "float32"}), ("cuda", {})):
            recipe = Recipe().with_values({"run.method": "guided", "guided.device": dev, **extra})
            state = prepare_sequence(c.source, recipe, warn=False)
            rec = recipe_for_state(recipe, state)
            t0 = time.perf_counter()
            frame = next(iter(reconstruct_windows(c.source, [c.center], recipe, state)))
            sync()
            row[f"{dev}_s"] = time.perf_counter() - t0
            _, mapping = exposure_mapping(rec, state, "x.npy")
            bounded = mapping(frame)
            row[f"{dev}_psnr"], row[f"{dev}_ssim"] = (float(v) for v in score(bounded, c.gt))
            row[f"{dev}_frame"] = bounded
        row["max_abs_diff"] = float(np.abs(row.pop("cpu_frame") - row.pop("cuda_frame")).max())
        row["d_psnr"] = row["cuda_psnr"] - row["cpu_psnr"]
        row["d_ssim"] = row["cuda_ssim"] - row["cpu_ssim"]
        log(f"  {c.scene:<22} t={c.center:<4} cpu {row['cpu_psnr']:.3f} dB {row['cpu_ssim']:.4f}  "
            f"gpu {row['cuda_psnr']:.3f} dB {row['cuda_ssim']:.4f}  Δ {row['d_psnr']:+.4f} dB {row['d_ssim']:+.5f}  "
            f"max|Δ| {row['max_abs_diff']:.4f}  ({row['cpu_s']:.2f} s / {row['cuda_s']:.2f} s)")
        rows.append(row)
    d_p = [r["d_psnr"] for r in rows]
    d_s = [r["d_ssim"] for r in rows]
    return {"rows": rows, "mean_d_psnr": statistics.mean(d_p), "worst_abs_d_psnr": max(abs(v) for v in d_p),
            "mean_d_ssim": statistics.mean(d_s), "worst_abs_d_ssim": max(abs(v) for v in d_s),
            "peak_gpu_mib": torch.cuda.max_memory_allocated() / 2**20}


def prior_pass(sizes: list[int]) -> list[dict]:
    import torch

    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import load_prior

    net = load_prior(GuidedConfig(device="cuda"), 3)
    rows = []
    for size in sizes:
        g = torch.Generator().manual_seed(0)
        x = torch.rand(1, 3, size, size, generator=g).cuda()
        for prec in ("float32", "bfloat16-all"):
            torch.cuda.reset_peak_memory_stats()
            with torch.no_grad():
                med, mn, _ = timed(lambda: net(x, 25 / 255, prec), repeats=10, warmup=3)
            rows.append({"size": size, "precision": prec + (" (TF32)" if prec == "float32" else ""), "median_s": med,
                         "min_s": mn, "peak_gpu_mib": torch.cuda.max_memory_allocated() / 2**20})
            log(f"  FFDNet pass {size}² {prec}: {1000 * med:.2f} ms (min {1000 * mn:.2f})")
    return rows


def simulate(size: int, ticks: int, folder: Path) -> Path:
    out = folder / f"demo{size}_{ticks}.dat"
    if not out.exists():
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "spikeview", "simulate", "--demo", "--size", str(size), "--ticks", str(ticks),
                        "--gt-every", "1000", "--out", str(out), "--overwrite"], check=True, capture_output=True)
        log(f"  simulated {out.name} in {time.perf_counter() - t0:.1f} s")
    return out


def guided_frame(sizes: list[int], folder: Path, repeats: int) -> list[dict]:
    import torch

    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import make_plan
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, sampler_params
    from spikeview.recipe import Recipe

    rows = []
    for size in sizes:
        src = open_source(str(simulate(size, 200, folder)))
        recipe = Recipe().with_values({"run.method": "guided"})
        state = prepare_sequence(src, recipe, warn=False)
        p = sampler_params(recipe, state)
        smp = GuidedSampler(p)
        parts: dict[str, list[float]] = {"observation": [], "plan": [], "sampler": [], "whole": []}

        def once(record: bool):
            t0 = time.perf_counter()
            obs = Observation.from_source(src, 100, p.window, alpha=state.alpha, eta=p.eta, radius=p.temporal_radius,
                                          device=p.device)
            t1 = time.perf_counter()
            plan = make_plan(obs, p)
            t2 = time.perf_counter()
            smp.run(obs, p, plan=plan)
            sync()
            t3 = time.perf_counter()
            if record:
                for k, v in zip(parts, (t1 - t0, t2 - t1, t3 - t2, t3 - t0), strict=True):
                    parts[k].append(v)

        once(False)
        torch.cuda.reset_peak_memory_stats()
        for _ in range(repeats):
            once(True)
        row = {"size": size, "mode": smp.info.mode, "device": smp.info.device, "precision": smp.info.precision,
               "steps": smp.info.steps, **{f"{k}_s": statistics.median(v) for k, v in parts.items()},
               "peak_gpu_mib": torch.cuda.max_memory_allocated() / 2**20}
        rows.append(row)
        log(f"  guided frame {size}²: sampler {row['sampler_s']:.3f} s, observation {row['observation_s']:.3f} s, "
            f"plan {row['plan_s']:.3f} s, whole {row['whole_s']:.3f} s ({row['mode']}, {row['device']}, {row['precision']})")
    return rows


def clip(folder: Path, windows: int, seconds: float) -> dict:
    import torch

    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, reconstruct_windows
    from spikeview.recipe import Recipe

    ticks = 10 * windows + 80
    src = open_source(str(simulate(1000, ticks, folder)))
    recipe = Recipe().with_values({"run.method": "guided"})
    state = prepare_sequence(src, recipe, warn=False)
    centres = list(range(40 + 5, 40 + 10 * windows, 10))[:windows]
    infos: list = []
    torch.cuda.reset_peak_memory_stats()
    t0 = time.perf_counter()
    done = 0
    first = None
    for _ in reconstruct_windows(src, centres, recipe, state, infos=infos):
        done += 1
        if first is None:
            first = time.perf_counter() - t0
        if time.perf_counter() - t0 > seconds:
            break
    sync()
    wall = time.perf_counter() - t0
    modes: dict[str, int] = {}
    for i in infos:
        modes[i.mode] = modes.get(i.mode, 0) + 1
    fps = done / wall
    row = {"windows": done, "asked": windows, "wall_s": wall, "first_window_s": first, "fps": fps,
           "second_of_capture_min": 2000 / fps / 60, "modes": modes,
           "peak_gpu_mib": torch.cuda.max_memory_allocated() / 2**20}
    log(f"  clip 1000²: {done} windows in {wall:.1f} s = {fps:.2f} frames/s; one second of capture (2,000 windows) "
        f"{row['second_of_capture_min']:.1f} min; modes {modes}")
    return row


def report(res: dict, out: Path) -> None:
    env = res.get("environment", {})
    L = [f"# GPU check ({env.get('gpu', 'no GPU')})", "",
         f"Machine: {env.get('gpu')} ({env.get('gpu_memory_gib')} GiB, {env.get('sm')} SMs), CPU {env.get('cpu')} "
         f"({env.get('cpu_cores')} cores); Python {env.get('python')}, torch {env.get('torch')}, CUDA {env.get('cuda')}, "
         f"cuDNN {env.get('cudnn')}, TF32 convolutions {env.get('tf32_conv')}. Run {res.get('date')} "
         f"({res.get('total_s', 0):.0f} s in all).", ""]
    ag = res.get("agreement")
    if ag:
        L += ["## CPU float32 vs GPU (defaults) on the held-out scenes (256², the user's path)", "",
              "| scene | centre | CPU PSNR / SSIM | GPU PSNR / SSIM | ΔPSNR (dB) | ΔSSIM | max abs diff |",
              "|---|---:|---:|---:|---:|---:|---:|"]
        for r in ag["rows"]:
            L.append(f"| {r['scene']} | {r['center']} | {r['cpu_psnr']:.3f} / {r['cpu_ssim']:.4f} | {r['cuda_psnr']:.3f} / "
                     f"{r['cuda_ssim']:.4f} | {r['d_psnr']:+.4f} | {r['d_ssim']:+.5f} | {r['max_abs_diff']:.4f} |")
        L += ["", f"Mean ΔPSNR {ag['mean_d_psnr']:+.4f} dB (worst |Δ| {ag['worst_abs_d_psnr']:.4f}; target 0.05), "
                  f"mean ΔSSIM {ag['mean_d_ssim']:+.5f} (worst |Δ| {ag['worst_abs_d_ssim']:.5f}; target 0.002); "
                  f"peak GPU memory {ag['peak_gpu_mib']:.0f} MiB.", ""]
    if res.get("prior"):
        L += ["## One FFDNet pass on the GPU (RGB, σ 25/255, no autograd)", "",
              "| size | precision | median | min | peak GPU MiB |", "|---:|---|---:|---:|---:|"]
        L += [f"| {r['size']}² | {r['precision']} | {1000 * r['median_s']:.2f} ms | {1000 * r['min_s']:.2f} ms | "
              f"{r['peak_gpu_mib']:.0f} |" for r in res["prior"]]
        L.append("")
    if res.get("frames"):
        L += ["## One guided frame with CLI defaults (demo capture, centre tick 100)", "",
              "| size | mode | device | precision | observation (count + pool) | plan | sampler | whole window | "
              "peak GPU MiB |", "|---:|---|---|---|---:|---:|---:|---:|---:|"]
        L += [f"| {r['size']}² | {r['mode']} | {r['device']} | {r['precision']} | {r['observation_s']:.3f} s | "
              f"{r['plan_s']:.3f} s | {r['sampler_s']:.3f} s | {r['whole_s']:.3f} s | {r['peak_gpu_mib']:.0f} |"
              for r in res["frames"]]
        L.append("")
    c = res.get("clip")
    if c:
        L += ["## A 1000² clip through the CLI's path (reconstruct_windows, defaults)", "",
              f"{c['windows']} of {c['asked']} windows in {c['wall_s']:.1f} s (first {c['first_window_s']:.2f} s): "
              f"**{c['fps']:.2f} frames/s**; one second of capture (2,000 windows) ≈ **{c['second_of_capture_min']:.1f} min** "
              f"on this GPU; modes {c['modes']}; peak GPU memory {c['peak_gpu_mib']:.0f} MiB.", ""]
    if res.get("errors"):
        L += ["## Errors", ""] + [f"- {e}" for e in res["errors"]] + [""]
    out.write_text("\n".join(L), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true", help="fewer scenes, no 2000², a short clip")
    ap.add_argument("--clip-windows", type=int, default=300)
    ap.add_argument("--clip-seconds", type=float, default=150.0)
    ap.add_argument("--work", default="/tmp/spikeview_gpu_check", help="folder for the simulated captures")
    ap.add_argument("--skip", default="", help="comma-separated sections to skip: agreement,prior,frames,clip")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(a.work)  # captures stay out of OUTDIR (only the report comes back from a lent machine)
    work.mkdir(parents=True, exist_ok=True)
    skip = set(filter(None, a.skip.split(",")))
    t_start = time.perf_counter()
    res: dict = {"date": time.strftime("%Y-%m-%d %H:%M"), "errors": []}

    def save() -> None:
        res["total_s"] = time.perf_counter() - t_start
        (out / "gpu_check.json").write_text(json.dumps(res, indent=1, default=str), encoding="utf-8")
        report(res, out / "gpu_check.md")

    res["environment"] = environment()
    log("environment:", json.dumps(res["environment"]))
    save()
    if not res["environment"].get("gpus"):
        res["errors"].append("torch sees no CUDA GPU here: nothing to check")
        save()
        return 1
    sizes = [256, 1000] if a.quick else [256, 1000, 2000]
    sections = [("prior", lambda: prior_pass(sizes)),
                ("frames", lambda: guided_frame(sizes, work, 2 if a.quick else 3)),
                ("agreement", lambda: agreement(1 if a.quick else 2, a.quick)),
                ("clip", lambda: clip(work, 30 if a.quick else a.clip_windows, 40 if a.quick else a.clip_seconds))]
    for name, fn in sections:
        if name in skip:
            continue
        log(f"[{time.perf_counter() - t_start:.0f} s] {name}")
        try:
            res[name] = fn()
        except Exception as e:  # noqa: BLE001 - a check reports what broke and goes on with the next section
            import traceback

            traceback.print_exc()
            res["errors"].append(f"{name}: {type(e).__name__}: {e}")
        save()
    log(f"done in {time.perf_counter() - t_start:.0f} s; report {out / 'gpu_check.md'}")
    return 0 if not res["errors"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
