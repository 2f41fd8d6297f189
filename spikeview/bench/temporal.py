"""Sequences benchmark: back-to-back 10-tick windows, PSNR/SSIM and the temporal error (flicker).

Usage::

    spikeview bench --sequences                        # this benchmark only (128×128, 12 frames per sequence)
    python benchmarks/bench_guided.py --sequences      # the same
    python benchmarks/bench_guided.py --sequences --quick   # 64×64, 4 frames, 2 steps: a smoke run

Every sequence is a simulated capture (:mod:`spikeview.sim`, the realistic sensor model of the
guided benchmark, :func:`spikeview.bench.data.make_capture`) of a still image under a camera motion,
read as back-to-back 10-tick windows with the clean linear frame at every window centre as ground
truth. Three motions: ``static`` (no motion), ``slow`` (a slow pan, ≤ 0.2 px per window) and
``fast`` (a fast pan, 2–3 px per window, or rotating fans in front of a panned scene). Each motion
has a **tuning** sequence (the default ``temporal_radius`` was chosen on these only) and held-out
sequences, monochrome and Bayer.

Methods, all on the user's path (:func:`spikeview.pipeline.prepare_sequence`: the default white balance's α and the
white point from the spikes, :func:`spikeview.pipeline.reconstruct_windows` with its reuse test and
keyframes, frames divided by the white point and clipped as in a bounded output):

* ``TFP-10``: the classical reconstruction;
* ``FFDNet pass``: the strong one-pass baseline (σ × 2) on the sampler's observation;
* ``guided (single window)``: the default guided reconstruction with ``temporal_radius = 0``;
* ``guided (pooled ±R)``: the same with ``temporal_radius = R``.

Scores: PSNR and SSIM (:mod:`spikeview.metrics`, ``data_range = 1``) per frame after the per-channel
least-squares gain of the guided benchmark (:func:`spikeview.bench.guided.score`), averaged over the
frames; the **temporal error** ``RMS_t,p((x_t − x_{t−1}) − (g_t − g_{t−1}))`` in 1/255 with one gain per
channel, sequence and method (fitted over all its frames), so a flickering exposure counts; seconds per frame
(mean over the sequence, so reused frames count at their cost; 2 torch threads, a shared machine).
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

#: name -> (motion, tuning?, image recipe of spikeview.bench.data.scene_image, pan px/s, rotation deg/s, fans?, cfa)
SEQUENCES: dict[str, tuple[str, bool, str, tuple[float, float], float, bool, str]] = {
    "coffee/static": ("static", True, "coffee", (0.0, 0.0), 0.0, False, "RGGB"),
    "coffee/slow": ("slow", True, "coffee", (250.0, 150.0), 0.0, False, "RGGB"),
    "coffee/fast": ("fast", True, "coffee", (4500.0, 1500.0), 0.0, False, "RGGB"),
    "astronaut/fans": ("fast", True, "lowkey:astronaut", (-500.0, 300.0), 0.0, True, "RGGB"),
    "astronaut/static": ("static", False, "astronaut", (0.0, 0.0), 0.0, False, "RGGB"),
    "camera/static (mono)": ("static", False, "camera", (0.0, 0.0), 0.0, False, "none"),
    "rocket/slow": ("slow", False, "rocket", (300.0, 0.0), 0.0, False, "RGGB"),
    "chelsea/slow (mono)": ("slow", False, "chelsea", (-200.0, 200.0), 0.0, False, "none"),
    "astronaut/fast": ("fast", False, "astronaut", (5000.0, -2000.0), 0.0, False, "RGGB"),
    "coffee/fans": ("fast", False, "lowkey:coffee", (600.0, 0.0), 0.0, True, "RGGB"),
    "camera/fast (mono)": ("fast", False, "camera", (-4000.0, 3000.0), 15.0, False, "none"),
}
MOTIONS = ("static", "slow", "fast")
WINDOW = 10
#: radii compared on the tuning sequences to choose the default (``run_sequences(radii=(0,) + RADII)``)
RADII = (1, 2, 3)
#: neighbouring windows kept on each side of the first and last frame (so every frame has its ±R)
MARGIN = 4


def make_sequence(name: str, size: int = 128, frames: int = 8, seed: int = 0):
    """The capture of sequence ``name`` and its centre ticks (``frames`` back-to-back windows)."""
    from spikeview.bench.data import scene_image
    from spikeview.sim import Fan, MotionScene, SimConfig, simulate

    motion, _, recipe, pan, rot, fans, cfa = SEQUENCES[name]
    img = scene_image(recipe)
    fan = [Fan(center=(0.62 * size, 0.45 * size), radius=0.3 * size, rev_per_s=40.0, n_blades=3, hub_radius=0.04 * size)] if fans else []
    scene = MotionScene(img, size=(size, size), pan=pan, rotation=rot, fans=fan)
    n_ticks = (frames + 2 * MARGIN) * WINDOW
    cap = simulate(scene, SimConfig(n_ticks=n_ticks, seed=seed + sum(map(ord, name)), gt_every=WINDOW, cfa=cfa))
    centres = [MARGIN * WINDOW + WINDOW // 2 + i * WINDOW for i in range(frames)]
    return cap, centres


def ground_truth(cap: Any, tick: int) -> np.ndarray:
    """The clean linear frame at ``tick``: RGB for Bayer, Rec. 709 luminance for monochrome."""
    g = np.asarray(cap.gt_at(tick), dtype=np.float32)
    if cap.cfa is None:
        return (g @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)).astype(np.float32)
    return g


def temporal_error(frames: list[np.ndarray], gts: list[np.ndarray], moved: tuple[int, int] = (0, 0)) -> float:
    """``RMS((x_t − x_{t−1}) − (g_t − g_{t−1}))`` in 1/255 over every frame pair and pixel, after one
    per-channel least-squares gain of the whole sequence to its ground truth.

    ``moved = (dy, dx)``: the same with each frame's error ``e_t = x_t − g_t`` carried along by ``(dy, dx)``
    pixels per window, ``RMS(e_t(p) − e_{t−1}(p − (dy, dx)))`` (borders cropped): on a static sequence,
    what its errors would give if they moved with the content of a pan of that speed (:data:`CEILING_SHIFT`).
    """
    from spikeview.bench.score import fit_gain

    x = np.stack(frames).astype(np.float64)
    g = np.stack(gts).astype(np.float64)
    c = x.shape[-1] if x.ndim == 4 else 1  # (T, H, W, 3) colour or (T, H, W) gray: one gain per channel
    x = x * fit_gain(x.reshape(-1, 1, c), g.reshape(-1, 1, c))
    if moved == (0, 0):
        d = np.diff(x, axis=0) - np.diff(g, axis=0)
    else:
        dy, dx = moved
        e = x - g
        h, w = e.shape[1:3]
        ay, ax = abs(dy), abs(dx)
        now = e[1:, ay:h - ay, ax:w - ax]
        before = e[:-1, ay - dy:h - ay - dy, ax - dx:w - ax - dx]
        d = now - before
    return float(255.0 * np.sqrt(np.mean(d * d)))


#: ``(dy, dx)`` pixels per window of the fast pans (coffee/fast 0.75, 2.25; astronaut/fast −1, 2.5; camera/fast
#: 1.5, −2): the speed at which a static sequence's errors are carried for the ceiling on fast motion
CEILING_SHIFT = (1, 2)


def _method_runs(cap: Any, centres: list[int], prior: Any, steps: dict, radii) -> dict[str, tuple[list[np.ndarray], list[float], list]]:
    """``{method: (bounded frames, seconds per frame, pooling kinds)}`` on the user's path."""
    from spikeview.guided.baseline import baseline
    from spikeview.guided.window import observe_window
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.pipeline import guided_scale, output_white, prepare_sequence, reconstruct_windows, sampler_params
    from spikeview.recipe import Recipe

    from spikeview.classical.calibration import attach_own

    base = Recipe().with_values({"run.method": "guided", **{f"guided.{k}": v for k, v in steps.items()}})
    attach_own(cap)  # the capture's own corrections, as the CLI opens a file
    state = prepare_sequence(cap, base)
    white = output_white(base, state)
    out: dict[str, tuple[list[np.ndarray], list[float], list]] = {}

    def bounded(x: np.ndarray) -> np.ndarray:
        return np.clip(np.asarray(x, dtype=np.float32) / white, 0.0, 1.0)

    def timed(frames_iter) -> tuple[list[np.ndarray], list[float]]:
        fr, ts = [], []
        t0 = time.perf_counter()
        for f in frames_iter:
            t1 = time.perf_counter()
            fr.append(bounded(f))
            ts.append(t1 - t0)
            t0 = time.perf_counter()
        return fr, ts

    fr, ts = timed(reconstruct_windows(cap, centres, base.with_values({"run.method": "tfp"}), state))
    out["TFP-10"] = (fr, ts, [])
    cfg = sampler_params(base, state)
    scale = guided_scale(state)
    fr, ts = [], []
    for c in centres:
        t0 = time.perf_counter()
        obs = observe_window(cap, c, cfg.replace(temporal_radius=0), state.alpha, plan=False).obs
        fr.append(bounded(baseline(obs, prior, sigma_scale=2.0) * scale))
        ts.append(time.perf_counter() - t0)
    out["FFDNet pass"] = (fr, ts, [])
    for r in radii:
        recipe = base.with_values({"guided.temporal_radius": r})
        smp = GuidedSampler(sampler_params(recipe, state), prior=prior)
        infos: list = []
        fr, ts = timed(reconstruct_windows(cap, centres, recipe, state, sampler=smp, infos=infos))
        kinds = [getattr(i.plan, "temporal", "off") if i.plan is not None else "?" for i in infos]
        out[method_name(r)] = (fr, ts, kinds)
    return out


def method_name(radius: int) -> str:
    return "guided (single window)" if radius == 0 else f"guided (pooled ±{radius})"


def run_sequences(out_dir: str | os.PathLike[str] | None = "benchmarks/results", *, size: int = 128, frames: int = 8,
                  quick: bool = False, names=None, radii=None) -> dict:
    """Run every sequence (or ``names``); write ``temporal.md`` / ``temporal.json`` to ``out_dir`` (``None``: nothing)."""
    import torch

    from spikeview.bench.score import score
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import load_prior

    torch.set_num_threads(2)
    t_start = time.time()
    steps = dict(steps=2) if quick else {}
    if radii is None:
        from spikeview.guided.config import GuidedConfig as _G

        radii = (0, _G().temporal_radius)
    radii = tuple(radii)
    rows = []
    for name in (names or list(SEQUENCES)):
        motion, tuning, _, pan, rot, fans, cfa = SEQUENCES[name]
        cap, centres = make_sequence(name, size, frames)
        prior = load_prior(GuidedConfig(), 1 if cap.cfa is None else 3)
        gts = [ground_truth(cap, c) for c in centres]
        runs = _method_runs(cap, centres, prior, steps, radii)
        for m, (fr, ts, kinds) in runs.items():
            sc = [score(f, g) for f, g in zip(fr, gts)]
            rows.append(dict(sequence=name, motion=motion, tuning=tuning, mono=cap.cfa is None, method=m,
                             psnr=float(np.mean([s[0] for s in sc])), ssim=float(np.mean([s[1] for s in sc])),
                             temporal=temporal_error(fr, gts), seconds=float(np.mean(ts)),
                             temporal_moved=temporal_error(fr, gts, CEILING_SHIFT) if motion == "static" else None,
                             kinds={k: kinds.count(k) for k in sorted(set(kinds))}))
        print(f"  {name}: " + ", ".join(f"{r['method']} {r['psnr']:.2f}/{r['temporal']:.1f}" for r in rows if r["sequence"] == name),
              flush=True)
    timings = []
    if names is None and not quick:
        timings = [timing(size=s_) for s_ in dict.fromkeys((size, 256))]
    info = dict(machine=f"{platform.machine()}, {os.cpu_count()} CPU cores visible, torch threads 2, Python {platform.python_version()}",
                cpu=_cpu_model(), load_end=os.getloadavg()[0], size=size, frames=frames, quick=quick,
                minutes=(time.time() - t_start) / 60)
    res = dict(info=info, rows=rows, timing=timings)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "temporal.json").write_text(json.dumps(res, indent=1), encoding="utf-8")
        (out / "temporal.md").write_text(report(res), encoding="utf-8")
    return res


def timing(size: int = 256, repeats: int = 5, name: str = "coffee/fast", radius: int | None = None) -> dict:
    """Cost per frame of the single-window and the pooled guided run on the same windows (no reuse),
    interleaved, after a warm-up: median and min seconds, and the pooling alone (``pool_counts``)."""
    import torch

    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.window import observe_window
    from spikeview.guided.sampler import GuidedSampler, load_prior
    from spikeview.guided.temporal import pool_counts
    from spikeview.pipeline import prepare_sequence, sampler_params
    from spikeview.recipe import Recipe

    torch.set_num_threads(2)
    r = GuidedConfig().temporal_radius if radius is None else radius
    cap, centres = make_sequence(name, size, repeats + 1)
    from spikeview.classical.calibration import attach_own

    recipe = Recipe().with_values({"run.method": "guided"})
    attach_own(cap)  # the capture's own corrections, as the CLI opens a file
    state = prepare_sequence(cap, recipe)
    cfg = sampler_params(recipe, state).replace(reuse=False)
    smp = GuidedSampler(cfg, prior=load_prior(cfg, 1 if cap.cfa is None else 3))
    ts: dict[str, list[float]] = {"single": [], "pooled": [], "pooling": []}

    def once(c: int, rad: int) -> float:
        t0 = time.perf_counter()
        p = cfg.replace(temporal_radius=rad)
        w = observe_window(cap, c, p, state.alpha)
        smp.run(w.obs, p, plan=w.plan)
        return time.perf_counter() - t0

    once(centres[0], 0), once(centres[0], r)  # warm-up
    for c in centres[1:]:
        ts["single"].append(once(c, 0))
        ts["pooled"].append(once(c, r))
        a = c - cfg.window // 2
        t0 = time.perf_counter()
        pool_counts(cap, a, a + cfg.window, r, cap.cfa)
        ts["pooling"].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) for k, v in ts.items()}
    return dict(size=size, sequence=name, radius=r, repeats=repeats, load=os.getloadavg()[0],
                median=med, min={k: float(np.min(v)) for k, v in ts.items()}, ratio=med["pooled"] / med["single"])


def _cpu_model() -> str:
    from spikeview.guided.device import cpu_model
    from spikeview.guided.precision import cpu_flags

    have = [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in cpu_flags()]
    return f"{cpu_model()} ({', '.join(have) or 'no avx2'})"


def report(res: dict, default_radius: int | None = None) -> str:
    """Markdown of a run: per sequence and method PSNR / SSIM / temporal error / s per frame, and the targets."""
    from spikeview.guided.config import GuidedConfig

    rows, info = res["rows"], res["info"]
    r_def = GuidedConfig().temporal_radius if default_radius is None else default_radius
    pooled = method_name(r_def) if r_def else method_name(max(RADII))
    single = method_name(0)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    seqs = list(dict.fromkeys(r["sequence"] for r in rows))

    def get(seq, m):
        return next((r for r in rows if r["sequence"] == seq and r["method"] == m), None)

    L = ["# Sequences: PSNR / SSIM / temporal error of back-to-back 10-tick windows", "",
         f"Machine: {info['machine']}; {info['cpu']}; load average at the end {info['load_end']:.1f} (shared, 2 cores: seconds "
         f"are upper bounds); run took {info['minutes']:.0f} min. Command: `spikeview bench --sequences`"
         + (" --quick" if info.get("quick") else "") + f" ({info['size']}×{info['size']}, {info['frames']} frames per sequence).",
         "Scores: per frame after a per-channel least-squares gain (PSNR/SSIM, data_range 1, mean over frames); temporal error "
         "RMS((x_t − x_{t−1}) − (g_t − g_{t−1})) ×255 with one gain per channel for the whole sequence; seconds: mean per frame (reused frames included).",
         f"Compared for the targets: **{pooled}** against **{single}**.", "",
         "| sequence | set | method | PSNR | SSIM | temporal error /255 | s/frame | pooling (frames) |", "|---|---|---|---|---|---|---|---|"]
    for s in seqs:
        for m in methods:
            r = get(s, m)
            if r is None:
                continue
            kinds = ", ".join(f"{k} {n}" for k, n in r["kinds"].items())
            L.append(f"| {s} | {'tune' if r['tuning'] else 'held-out'} | {m} | {r['psnr']:.2f} | {r['ssim']:.3f} | "
                     f"{r['temporal']:.2f} | {r['seconds']:.2f} | {kinds} |")
    L += ["", f"## Targets on the held-out sequences ({pooled} vs {single})", "",
          "| sequence | motion | ΔPSNR dB | ΔSSIM | temporal error ratio | s/frame ratio in the sequence (reuse included) | verdict (PSNR, temporal) |",
          "|---|---|---|---|---|---|---|"]
    for s in seqs:
        a, b = get(s, single), get(s, pooled)
        if a is None or b is None or a["tuning"]:
            continue
        dp, ds = b["psnr"] - a["psnr"], b["ssim"] - a["ssim"]
        te = b["temporal"] / a["temporal"] if a["temporal"] > 1e-6 else (0.0 if b["temporal"] <= 1e-6 else float("inf"))
        cost = b["seconds"] / max(a["seconds"], 1e-9)
        ok_p = dp >= 1.5 if a["motion"] != "fast" else dp >= -0.1
        miss = []
        if not ok_p:
            miss.append(f"PSNR short by {(1.5 - dp) if a['motion'] != 'fast' else (-0.1 - dp):.2f} dB")
        if te > 0.6:
            miss.append(f"temporal ratio {te:.2f} > 0.6")
        L.append(f"| {s} | {a['motion']} | {dp:+.2f} | {ds:+.3f} | {te:.2f} | {cost:.2f}× | {'met' if not miss else '**missed**: ' + '; '.join(miss)} |")
    for motion in MOTIONS:
        held = [s for s in seqs if get(s, single) and not get(s, single)["tuning"] and get(s, single)["motion"] == motion]
        if held and all(get(s, pooled) for s in held):
            dp = float(np.mean([get(s, pooled)["psnr"] - get(s, single)["psnr"] for s in held]))
            L.append(f"| **mean {motion}** | | {dp:+.2f} | | | | |")
    ceil = [(s, get(s, single), get(s, pooled)) for s in seqs if get(s, single) and get(s, pooled)
            and get(s, single).get("temporal_moved") and get(s, pooled).get("temporal_moved")]
    if ceil:
        dy, dx = CEILING_SHIFT
        L += ["", f"Ceiling on fast motion: the temporal error of the static sequences if every frame's error moved with the "
              f"content at {dx} px (x) and {dy} px (y) per window, i.e. a fast pan pooled with perfect alignment "
              f"(`temporal_error(..., moved=CEILING_SHIFT)`):", "",
              f"| sequence | set | {single} | {pooled} | ratio |", "|---|---|---|---|---|"]
        for s, a, b in ceil:
            L.append(f"| {s} | {'tune' if a['tuning'] else 'held-out'} | {a['temporal_moved']:.2f} | {b['temporal_moved']:.2f} | "
                     f"{b['temporal_moved'] / a['temporal_moved']:.2f} |")
    for t in res.get("timing", []):
        L += ["", f"Cost ({t['size']}×{t['size']}, {t['sequence']}, every window sampled — no reuse — interleaved after a warm-up, "
              f"{t['repeats']} windows, load {t['load']:.1f}): single window {t['median']['single']:.2f} s (min {t['min']['single']:.2f}), "
              f"pooled ±{t['radius']} {t['median']['pooled']:.2f} s (min {t['min']['pooled']:.2f}), of which the pooling "
              f"{t['median']['pooling']:.2f} s: **{t['ratio']:.2f}×** per frame (target ≤ 1.5×: {'met' if t['ratio'] <= 1.5 else '**missed**'})."]
    L += ["", "Targets: ≥ +1.5 dB mean PSNR on static and slow held-out sequences; ≤ 0.1 dB loss on fast motion; temporal "
          "error ≤ 0.6× the single window's on every sequence; cost ≤ 1.5× per frame.", ""]
    return "\n".join(L)
