"""Error against run time of the guided reconstruction (SpikeDiff) and its baselines.

Usage::

    python benchmarks/bench_guided.py                 # full run: 256×256, 6 scenes, writes the results
    python benchmarks/bench_guided.py --quick         # 64×64, 2 scenes, a smoke run (not written by default)

or from Python (the CLI's ``spikeview bench`` calls this)::

    from spikeview.bench.guided import run_benchmark
    rows = run_benchmark("benchmarks/results", size=256)

The synthetic set (:mod:`spikeview.bench.data`): several ``skimage.data`` photographs under camera motion,
simulated with the realistic sensor model (all noise on), 10-tick windows, ground truth at the
window centre, known colour calibration. Metrics: PSNR and SSIM (``skimage.metrics``,
``data_range=1.0``, SSIM over the colour axis) and seconds per frame (median over frames after a
warm-up run, ``torch.set_num_threads(2)``). Methods: TFP and TFI with demosaicking, the strong
one-pass baseline at each noise scale of a sweep (its best is the reference), and the guided
sampler (HQS and DPS) at several step counts and start levels, plus ablations and sweeps of s and k.
Writes ``guided.md`` (tables) and ``guided_pareto.png`` (PSNR vs seconds, Pareto front marked).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np


from spikeview.bench.data import SCENES, TUNE_SCENES, make_capture, make_cases

BASELINE_SCALES = (1.0, 1.5, 2.0, 2.5, 3.0)
#: the table row that runs the sampler with GuidedConfig's defaults (HQS, 6 steps, t_s 50/255)
DEFAULT_ROW = "HQS 6 steps, t_s 50/255"


def _metrics(out: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    return (float(peak_signal_noise_ratio(gt, out, data_range=1.0)),
            float(structural_similarity(gt, out, data_range=1.0, channel_axis=-1)))


def _methods(quick: bool):
    """``(name, group, fn(obs, case) -> frame)`` for every method of the table."""
    from spikeview.classical.reconstruct import ClassicalConfig, reconstruct_frame
    from spikeview.guided.baseline import baseline, start_estimate
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import GuidedSampler, load_prior

    prior = load_prior(GuidedConfig(), 3)
    smp = GuidedSampler(GuidedConfig(), prior=prior)
    m = []
    m.append(("TFP + bilinear", "classical", lambda o, c: start_estimate(o, demosaic="bilinear")))
    m.append(("TFP + malvar2004", "classical", lambda o, c: start_estimate(o, demosaic="malvar2004")))

    def tfi(o, c):
        cfg = ClassicalConfig(method="tfi", tfi_half_window=5, demosaic="bilinear", eta=1.0, alpha=[float(a) for a in c.alpha])
        return reconstruct_frame(c.source, c.center, cfg)

    m.append(("TFI (10-tick span) + bilinear", "classical", tfi))
    for sc in BASELINE_SCALES:
        m.append((f"baseline σ×{sc:g}", "baseline", lambda o, c, sc=sc: baseline(o, prior, sigma_scale=sc)))

    def guided(name, group, **changes):
        cfg = GuidedConfig(eta=1.0, diffusion="always", **changes)
        m.append((name, group, lambda o, c, cfg=cfg: smp.run(o, cfg)))

    steps = (2, 4) if quick else (4, 6, 8, 12)
    for n in steps:
        for ts in (30, 50):
            guided(f"HQS {n} steps, t_s {ts}/255", "guided-hqs", steps=n, t_start=ts / 255)
    for n in ((2,) if quick else (4, 8)):
        for s in (0.0, 2.0):
            guided(f"DPS {n} steps, s {s:g}, t_s 50/255", "guided-dps", guidance="dps", steps=n, s=s, t_start=50 / 255)
    guided("DPS 8 steps, s 2, Q k50, L2", "guided-dps", guidance="dps", steps=2 if quick else 8, s=2.0, quantise=True, levels=2)
    # ablations of the default HQS sampler
    n = 2 if quick else GuidedConfig().steps
    guided("ablation: no noise weights", "ablation", steps=n, noise_weights=False)
    guided("ablation: + Q (k 50)", "ablation", steps=n, quantise=True, k=50.0)
    guided("ablation: + pyramid L 2", "ablation", steps=n, levels=2)
    guided("ablation: exact M gradient", "ablation", steps=n, dense_gradient=False)
    guided("ablation: no self-ensemble", "ablation", steps=n, self_ensemble=False)
    guided("ablation: DiffPIR re-noise ζ 0", "ablation", steps=n, renoise=True)
    guided("ablation: prior told σ×1 (not ×1.5)", "ablation", steps=n, sigma_scale=1.0)
    return m


def _sweeps(case_obs, quick: bool):
    """PSNR vs s (DPS) and vs k (HQS with Q) on one window: where quality breaks down."""
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import GuidedSampler, load_prior

    prior = load_prior(GuidedConfig(), 3)
    smp = GuidedSampler(GuidedConfig(), prior=prior)
    obs, case = case_obs
    n = 2 if quick else GuidedConfig().steps
    rows = []
    for s in (0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 1e3):
        out = smp.run(obs, GuidedConfig(eta=1.0, guidance="dps", steps=n, s=s, diffusion="always"))
        rows.append(("s (DPS)", s, *_metrics(out, case.gt)))
    for k in (1.0, 10.0, 20.0, 50.0, 200.0, 1e3):
        out = smp.run(obs, GuidedConfig(eta=1.0, steps=n, quantise=True, k=k, diffusion="always"))
        rows.append(("k (HQS + Q)", k, *_metrics(out, case.gt)))
    for lam in (0.3, 1.0, 3.0, 10.0):
        out = smp.run(obs, GuidedConfig(eta=1.0, steps=n, lam=lam, diffusion="always"))
        rows.append(("λ (HQS)", lam, *_metrics(out, case.gt)))
    return rows


#: camera pan of the warm-start scene: 6000 px/s = 3 px per 10-tick window at 20 kHz
WARM_PAN = (6000.0, 0.0)


def _warm_start(size: int, quick: bool):
    """Cold vs warm start on a fast-moving scene: PSNR of every window after the first, and time.

    Consecutive windows are 10 ticks apart, so the content moves 3 px between them; a warm start
    that smeared motion would carry the previous position into the next frame and lose PSNR
    against that frame's ground truth.
    """
    from spikeview.bench.data import calibration_alpha

    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.sampler import GuidedSampler, load_prior

    n_frames = 3 if quick else 7
    cap = make_capture("coins_rgb", size, n_ticks=10 * (n_frames + 2), seed=11, pan=WARM_PAN)
    alpha = calibration_alpha(cap)
    smp = GuidedSampler(GuidedConfig(), prior=load_prior(GuidedConfig(), 3))
    n = 2 if quick else GuidedConfig().steps
    w = max(1, n // 2)
    variants = {
        f"cold ({n} steps from the window's TFP, t_s 50/255)": GuidedConfig(eta=1.0, steps=n, diffusion="always"),
        f"warm ({w} steps from the previous result, t_s 20/255)": GuidedConfig(eta=1.0, steps=w, t_start=20 / 255,
                                                                            warm_start=True, diffusion="always"),
        f"warm ({w} steps from the previous result, t_s 40/255)": GuidedConfig(eta=1.0, steps=w, t_start=40 / 255,
                                                                            warm_start=True, diffusion="always"),
        f"cold ({w} steps from the window's TFP, t_s 50/255)": GuidedConfig(eta=1.0, steps=w, diffusion="always"),
    }
    out = {}
    for name, cfg in variants.items():
        prev, ps, ts = None, [], []
        for i in range(n_frames):
            c = 10 * (i + 1) + 5
            obs = Observation.from_source(cap, c, 10, alpha=alpha, eta=1.0)
            t0 = time.perf_counter()
            frame = smp.run(obs, cfg, init=prev if cfg.warm_start else None)
            dt = time.perf_counter() - t0
            if i > 0:
                ps.append(_metrics(frame, cap.gt_at(c))[0])
                ts.append(dt)
            prev = frame
        out[name] = (float(np.mean(ps)), float(statistics.median(ts)))
    speed = float(np.hypot(*WARM_PAN)) * 10 / cap.tick_rate
    return out, speed


def timing_section(obs, repeats: int = 5) -> list[str]:
    """Markdown lines: repeated timing (min and median of ``repeats`` runs after a warm-up) of the
    baseline, the default guided sampler and DPS with the same steps, on one window, in one process."""
    from spikeview.guided.baseline import baseline
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import GuidedSampler, load_prior

    prior = load_prior(GuidedConfig(), 3)
    smp = GuidedSampler(prior=prior)
    d = GuidedConfig()
    runs = {
        "baseline σ×2.5 (one FFDNet pass)": lambda: baseline(obs, prior, sigma_scale=2.5),
        f"guided default (HQS, {d.steps} steps)": lambda: smp.run(obs, GuidedConfig(eta=1.0, diffusion="always")),
        f"guided DPS ({d.steps} steps)": lambda: smp.run(obs, GuidedConfig(eta=1.0, guidance="dps", diffusion="always")),
    }
    med = {}
    lines = ["", f"## Repeated timing (one {obs.shape[0]}×{obs.shape[1]} window, {repeats} runs after a warm-up, same process)", "",
             "| method | min s | median s | median / baseline | load average |", "|---|---|---|---|---|"]
    for name, fn in runs.items():
        fn()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        med[name] = statistics.median(ts)
        ratio = med[name] / next(iter(med.values()))
        lines.append(f"| {name} | {min(ts):.2f} | {med[name]:.2f} | {ratio:.1f}× | {os.getloadavg()[0]:.1f} |")
    return lines


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points not dominated in (lower seconds, higher PSNR)."""
    idx = []
    for i, (t, p) in enumerate(points):
        if not any((t2 <= t and p2 >= p) and (t2 < t or p2 > p) for t2, p2 in points):
            idx.append(i)
    return idx


def run_benchmark(out_dir: str | os.PathLike[str] | None = "benchmarks/results", *, size: int = 256, scenes=None,
                  frames: int = 2, quick: bool = False, log=print) -> list[dict]:
    """Run the benchmark; write ``guided.md`` and ``guided_pareto.png`` to ``out_dir`` (``None``: don't write).

    Returns:
        one dict per method: name, group, psnr/ssim (all, tune scenes, held-out scenes), seconds.
    """
    import torch

    from spikeview.guided.observation import Observation

    torch.set_num_threads(2)
    names = list(scenes or SCENES)
    cases = make_cases(names, size=size, frames=frames)
    obs = [Observation.from_source(c.source, c.center, 10, alpha=c.alpha, eta=1.0) for c in cases]
    rows = []
    for name, group, fn in _methods(quick):
        fn(obs[0], cases[0])  # warm-up (first-call allocations, caches)
        res, secs = [], []
        for o, c in zip(obs, cases):
            t0 = time.perf_counter()
            out = fn(o, c)
            secs.append(time.perf_counter() - t0)
            res.append(_metrics(out, c.gt))
        res_a = np.array(res)
        tune = np.array([r for r, c in zip(res, cases) if c.scene in TUNE_SCENES])
        held = np.array([r for r, c in zip(res, cases) if c.scene not in TUNE_SCENES])
        row = dict(name=name, group=group, psnr=res_a[:, 0].mean(), ssim=res_a[:, 1].mean(), seconds=statistics.median(secs),
                   psnr_tune=tune[:, 0].mean() if len(tune) else np.nan, ssim_tune=tune[:, 1].mean() if len(tune) else np.nan,
                   psnr_held=held[:, 0].mean() if len(held) else np.nan, ssim_held=held[:, 1].mean() if len(held) else np.nan,
                   per_case=res_a[:, 0].tolist())
        rows.append(row)
        log(f"{name:45s} PSNR {row['psnr']:.2f}  SSIM {row['ssim']:.3f}  {row['seconds']:.2f} s/frame", flush=True)
    sweeps = _sweeps((obs[0], cases[0]), quick)
    warm, speed = _warm_start(size, quick)
    timing = timing_section(obs[-1], 2 if quick else 5)
    for k, v in warm.items():
        log(f"{k}: PSNR {v[0]:.2f} dB, {v[1]:.2f} s/frame")
    if out_dir is not None:
        import json

        _write(Path(out_dir), rows, sweeps, warm, speed, cases, size, timing)
        (Path(out_dir) / "guided.json").write_text(json.dumps(dict(rows=rows, sweeps=sweeps, warm=warm), indent=1), encoding="utf-8")
    return rows


def _write(out: Path, rows, sweeps, warm, speed, cases, size, timing=()) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    base = [r for r in rows if r["group"] == "baseline"]
    best = max(base, key=lambda r: r["psnr_tune"] if np.isfinite(r["psnr_tune"]) else r["psnr"])
    tfp = next(r for r in rows if r["name"] == "TFP + bilinear")
    default = next((r for r in rows if r["name"] == DEFAULT_ROW), None)
    front = pareto([(r["seconds"], r["psnr"]) for r in rows])
    scenes = sorted({c.scene for c in cases})
    lines = [
        "# Guided reconstruction: error against run time",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores visible, torch threads 2, "
        f"Python {platform.python_version()}; load average at the end {os.getloadavg()[0]:.1f} (other jobs shared the CPU, "
        "so seconds are upper bounds).",
        f"Set: {len(cases)} windows of 10 ticks at {size}×{size} from scenes {', '.join(scenes)} (simulated, all noise on, "
        f"RGGB, known calibration, η = 1); tuning scenes: {', '.join(TUNE_SCENES)}; held out: the others.",
        "PSNR/SSIM: skimage.metrics, data_range = 1.0 (SSIM over the colour axis), against the clean linear frame at the "
        "window centre. Seconds: median per frame after a warm-up run.",
        f"Reference baseline (best σ scale on the tuning scenes): **{best['name']}**. ★ = on the Pareto front "
        "(no other method is both faster and better).",
        "",
    ]
    if default is not None:
        def verdict(ok: bool) -> str:
            return "met" if ok else "**missed**"

        dp_h, ds_h = default["psnr_held"] - best["psnr_held"], default["ssim_held"] - best["ssim_held"]
        dp_t, ds_t = default["psnr_tune"] - best["psnr_tune"], default["ssim_tune"] - best["ssim_tune"]
        dtfp = default["psnr"] - tfp["psnr"]
        lines += [
            f"**Targets** (default sampler = {DEFAULT_ROW}, against {best['name']}):",
            "",
            f"* ≥ +1.0 dB PSNR over the baseline: held-out {dp_h:+.2f} dB ({verdict(dp_h >= 1.0)}), tuning scenes {dp_t:+.2f} dB.",
            f"* ≥ +0.02 SSIM over the baseline: held-out {ds_h:+.3f} ({verdict(ds_h >= 0.02)}), tuning scenes {ds_t:+.3f}.",
            f"* ≤ 10 s per 256×256 frame: {default['seconds']:.2f} s ({verdict(default['seconds'] <= 10.0)}).",
            f"* ≥ +6 dB over TFP: {dtfp:+.2f} dB on all windows ({verdict(dtfp >= 6.0)}).",
            "",
        ]
    lines += [
        "| method | PSNR all | SSIM all | PSNR tune | PSNR held-out | SSIM held-out | ΔPSNR vs baseline (held-out) | "
        "ΔSSIM vs baseline (held-out) | s/frame |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(rows):
        star = " ★" if i in front else ""
        lines.append(
            f"| {r['name']}{star} | {r['psnr']:.2f} | {r['ssim']:.3f} | {r['psnr_tune']:.2f} | {r['psnr_held']:.2f} | "
            f"{r['ssim_held']:.3f} | {r['psnr_held'] - best['psnr_held']:+.2f} | {r['ssim_held'] - best['ssim_held']:+.3f} | "
            f"{r['seconds']:.2f} |"
        )
    lines += ["", "## Where quality breaks down (one window, scene " + cases[0].scene + ")", "",
              "| parameter | value | PSNR | SSIM |", "|---|---|---|---|"]
    for name, v, p, s in sweeps:
        lines.append(f"| {name} | {v:g} | {p:.2f} | {s:.3f} |")
    lines += ["", f"## Warm start on a moving scene (coins_rgb, pan {speed:.1f} px per 10-tick window)", "",
              "| variant | mean PSNR of windows 2… | s/frame |", "|---|---|---|"]
    for k, (p, t) in warm.items():
        lines.append(f"| {k} | {p:.2f} | {t:.2f} |")
    lines += list(timing)
    (out / "guided.md").write_text("\n".join(lines) + "\n", encoding="utf-8")

    fig, ax = plt.subplots(figsize=(8, 5.5))
    colours = {"classical": "tab:gray", "baseline": "tab:blue", "guided-hqs": "tab:green", "guided-dps": "tab:red",
               "ablation": "tab:orange"}
    for g, col in colours.items():
        pts = [r for r in rows if r["group"] == g]
        ax.scatter([r["seconds"] for r in pts], [r["psnr"] for r in pts], c=col, label=g, s=30)
    fr = sorted((rows[i] for i in front), key=lambda r: r["seconds"])
    ax.plot([r["seconds"] for r in fr], [r["psnr"] for r in fr], "k--", lw=1, label="Pareto front")
    for r in fr:
        ax.annotate(r["name"], (r["seconds"], r["psnr"]), fontsize=6, xytext=(3, -8), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_xlabel("seconds per frame (2 CPU threads)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"Guided reconstruction, {size}×{size}, 10-tick windows")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "guided_pareto.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="64x64, 2 scenes, fewer steps (smoke run)")
    p.add_argument("--size", type=int, default=None)
    p.add_argument("--frames", type=int, default=2, help="windows per scene")
    p.add_argument("--out", default=None, help="results folder (default benchmarks/results; none for --quick)")
    a = p.parse_args(argv)
    size = a.size or (64 if a.quick else 256)
    out = a.out or (None if a.quick else "benchmarks/results")
    run_benchmark(out, size=size, scenes=list(SCENES)[:2] if a.quick else None, frames=a.frames, quick=a.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
