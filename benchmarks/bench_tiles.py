"""Per-tile plan (issue 15, item 2): quality, time and memory of step-synchronous tiles against the whole frame.

Usage::

    python benchmarks/bench_tiles.py [--tile 128] [--quick] [--no-memory] [--out benchmarks/results]

1. **held-out scenes** (``spikeview.bench.data``, the scenes no default was tuned on, 256², 2 windows
   each, the benchmark's observation): the default sampler with ``tile = T`` against ``tile = 0``,
   PSNR/SSIM against the ground truth (``data_range = 1``) for both, and the plan's tile line;
2. **a 1000² natural scene with bright and dark regions** (the astronaut photograph, static, its
   exposure falling from 1 on the left to 0.06 on the right; and from 8, clipped, to 0.05), observed as the CLI does (gray-world
   α, exposure, temporal pooling ``temporal_radius = 3``): tiled vs whole, PSNR/SSIM vs ground
   truth, wall and CPU seconds interleaved (medians), the tile map;
3. **seams**: a uniform-noise scene (160², Bayer and mono) tiled into 9 rectangles against the whole
   frame: largest per-pixel difference (/255) everywhere and the border/inside gradient ratio;
4. **peak memory** (child ``ru_maxrss``) of ``spikeview reconstruct demoN.dat --method guided --at 100``
   at 1000² and 2000², with the defaults and with ``--tile 0``.

Timings on a shared machine: the load is recorded before and after; compare ratios only.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import machine_words  # noqa: E402
from bench_prior import machine, run_cli, save_results, simulate  # noqa: E402


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(f):
    t, c = time.perf_counter(), _cpu()
    out = f()
    return out, time.perf_counter() - t, _cpu() - c


def held_out(tile: int, frames: int, size: int, scenes: list[str] | None) -> dict:
    from spikeview.bench.data import SCENES, TUNE_SCENES, make_cases
    from spikeview.bench.guided import Sequence, score
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import GuidedSampler

    held = scenes or [n for n in SCENES if n not in TUNE_SCENES]
    smp = GuidedSampler(GuidedConfig())
    rows = []
    for case in make_cases(held, size=size, frames=frames):
        obs = Sequence(case.source).observation(case.center)
        whole, tw, cw = _timed(lambda: smp.run(obs, GuidedConfig(tile=0)))
        tiled, tt, ct = _timed(lambda: smp.run(obs, GuidedConfig(tile=tile)))
        line = smp.info.plan.reasons.get("tiles", "")
        qw, qt = score(whole, case.gt), score(tiled, case.gt)
        rows.append({"scene": case.scene, "center": case.center, "psnr_whole": qw[0], "ssim_whole": qw[1],
                     "psnr_tiled": qt[0], "ssim_tiled": qt[1], "dpsnr": qt[0] - qw[0], "dssim": qt[1] - qw[1],
                     "wall_whole": tw, "wall_tiled": tt, "cpu_whole": cw, "cpu_tiled": ct, "tiles": line,
                     "max_abs_diff": float(np.abs(tiled - whole).max())})
        print(f"  {case.scene} @{case.center}: whole {qw[0]:.2f} dB / {qw[1]:.4f}, tiled {qt[0]:.2f} / {qt[1]:.4f} "
              f"({line})", flush=True)
    return {"scenes": held, "size": size, "frames": frames, "rows": rows,
            "dpsnr_worst": min(r["dpsnr"] for r in rows), "dssim_worst": min(r["dssim"] for r in rows),
            "dpsnr_mean": float(np.mean([r["dpsnr"] for r in rows])), "dssim_mean": float(np.mean([r["dssim"] for r in rows]))}


def natural_scene(size: int, n_ticks: int = 80, seed: int = 5, bright: float = 1.0, dark: float = 0.06):
    """The astronaut, static, exposure falling from ``bright`` (left; above 1: clipped, an overexposed
    part) to ``dark`` (right): bright and dark tiles."""
    from spikeview.bench.data import scene_image
    from spikeview.sim import MotionScene, SimConfig, simulate as sim

    img = scene_image("astronaut")
    gain = np.geomspace(bright, dark, img.shape[1]).astype(np.float32)
    img = np.clip(img * gain[None, :, None], 0.0, 1.0)
    scene = MotionScene(img, size=(size, size), pan=(0.0, 0.0))
    return sim(scene, SimConfig(n_ticks=n_ticks, seed=seed, gt_every=10))


def big_scene(tile: int, size: int, repeats: int, bright: float = 1.0, dark: float = 0.06) -> dict:
    from spikeview.bench.guided import Sequence, score
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import EXPOSURE_LEVEL, Observation, exposed_eta
    from spikeview.guided.sampler import GuidedSampler

    t0 = time.perf_counter()
    cap = natural_scene(size, bright=bright, dark=dark)
    center = 45
    seq = Sequence(cap)
    eta = exposed_eta(seq.eta, seq.white, EXPOSURE_LEVEL)
    p = GuidedConfig()
    obs = Observation.from_source(cap, center, p.window, alpha=seq.alpha, eta=eta, radius=p.temporal_radius)
    gt = cap.gt_at(center)
    print(f"  scene {size}²: simulated and observed in {time.perf_counter() - t0:.0f} s", flush=True)
    from spikeview.guided import tiles

    smp = GuidedSampler(p)
    outs, times, plans = {}, {"whole": [], "tiled": [], "short kept": []}, {}
    for r in range(repeats):
        for name, cfg, pay in (("whole", p.replace(tile=0), tiles.PAY_WORK), ("tiled", p.replace(tile=tile), tiles.PAY_WORK),
                               ("short kept", p.replace(tile=tile), 1.0)):
            old, tiles.PAY_WORK = tiles.PAY_WORK, pay
            try:
                out, wall, cpu = _timed(lambda cfg=cfg: smp.run(obs, cfg))
            finally:
                tiles.PAY_WORK = old
            outs[name] = out
            times[name].append((wall, cpu, os.getloadavg()[0]))
            plans[name] = smp.info.plan
            print(f"  {name} run {r + 1}: {wall:.1f} s wall, {cpu:.1f} s CPU (load {os.getloadavg()[0]:.1f}), mode {smp.info.mode}", flush=True)
    plan = plans["tiled"]
    qw, qt = score(outs["whole"], gt), score(outs["tiled"], gt)
    qs = score(outs["short kept"], gt)
    tm = plan.tile_map
    seam = {}
    if tm is not None:  # gradient across the tile borders against the gradient everywhere, whole and tiled
        from spikeview.guided.tiles import tile_spans

        edges = [a for a, _ in tile_spans(size, tm.size)[1:]]
        for name, img in outs.items():  # noqa: B007
            g = img.mean(axis=-1) if img.ndim == 3 else img
            gx, gy = np.abs(np.diff(g, axis=1)), np.abs(np.diff(g, axis=0))
            border = np.concatenate([gx[:, [e - 1 for e in edges]].ravel(), gy[[e - 1 for e in edges], :].ravel()])
            seam[name] = float(border.mean() / np.concatenate([gx.ravel(), gy.ravel()]).mean())
    med = {k: (statistics.median(w for w, _, _ in v), statistics.median(c for _, c, _ in v)) for k, v in times.items()}
    short = {"psnr": qs[0], "ssim": qs[1], "dpsnr": qs[0] - qw[0], "dssim": qs[1] - qw[1], "wall": med["short kept"][0],
             "cpu": med["short kept"][1], "tiles": plans["short kept"].reasons.get("tiles", "")}
    return {"size": size, "center": center, "exposure": [bright, dark], "psnr_whole": qw[0], "ssim_whole": qw[1], "psnr_tiled": qt[0], "ssim_tiled": qt[1],
            "dpsnr": qt[0] - qw[0], "dssim": qt[1] - qw[1], "times": times,
            "wall_whole": med["whole"][0], "cpu_whole": med["whole"][1], "wall_tiled": med["tiled"][0],
            "cpu_tiled": med["tiled"][1], "tiles": plan.reasons.get("tiles", ""),
            "tile_map": None if tm is None else tm.as_dict(), "frame_sigma": [255 * float(s) for s in plan.sigma],
            "max_abs_diff": float(np.abs(outs["tiled"] - outs["whole"]).max()), "border_gradient": seam, "short_kept": short}


def seams() -> list[dict]:
    from spikeview.guided import tiles
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.io.source import ArraySource

    rows = []
    for cfa in ("RGGB", None):
        rng = np.random.default_rng(1)
        src = ArraySource(rng.random((40, 160, 160)) < 0.3, cfa=cfa)
        obs = Observation.from_source(src, 20, 10, alpha=np.ones(3) if cfa else None, eta=2.0, radius=0)
        smp = GuidedSampler(GuidedConfig())
        for precision in ("float32", "auto"):
            p = GuidedConfig(precision=precision)
            whole = smp.run(obs, p)
            old = tiles.MAX_AREA, tiles.TileMap.pays
            tiles.MAX_AREA, tiles.TileMap.pays = 3000, lambda self: True  # tiled on purpose, in 9 rectangles
            try:
                tiled = smp.run(obs, p.replace(tile=64))
            finally:
                tiles.MAX_AREA, tiles.TileMap.pays = old
            gray = tiled.mean(axis=-1) if tiled.ndim == 3 else tiled
            edges = [a for a, _ in tiles.tile_spans(160, 64)[1:]]
            gx = np.abs(np.diff(gray, axis=1))
            ratio = float(gx[:, [c - 1 for c in edges]].mean() / np.delete(gx, [c - 1 for c in edges], axis=1).mean())
            rows.append({"cfa": cfa or "mono", "precision": smp.info.precision, "max_diff_255": 255 * float(np.abs(tiled - whole).max()),
                         "mean_diff_255": 255 * float(np.abs(tiled - whole).mean()), "border_inside": ratio})
            print(f"  seams {cfa or 'mono'} {precision}: max {rows[-1]['max_diff_255']:.4f}/255, border/inside {ratio:.3f}", flush=True)
    return rows


def peak_rss(path: Path, extra: list[str]) -> dict:
    load = os.getloadavg()[0]
    r = run_cli(path, extra, "tiles")
    return {"args": " ".join(extra) or "(defaults)", "peak_mb": r["peak_mb"], "wall_s": r["wall_s"], "rc": r["rc"],
            "tiles": r["row"], "load": load}


def write_report(res: dict, out: Path) -> None:
    kept = (f" Sections {', '.join(res['kept'])}: from earlier runs of this script in this session, before the last two "
            "commits to tiles.py (neither changes a full tile or the whole-frame path; tiles.json keeps them)."
            if res.get("kept") else "")
    L = ["# Per-tile plan: step-synchronous tiles against the whole frame", ""]
    L.append(f"`python benchmarks/bench_tiles.py --tile {res['tile']}` — {machine_words(res['machine'])}; load "
             f"{res['machine']['load_before']:.1f} → {res['load_after']:.1f}; {res['minutes']:.0f} min. Sampler: the default "
             f"recipe (`GuidedConfig()`), `tile = {res['tile']}` against `tile = 0`." + kept)
    L.append("")
    if res.get("seams"):
        L += ["## Seams (uniform noise 160², tile 64, cut into 9 rectangles, vs the whole frame)", "",
              "| stream | precision | max \\|tiled − whole\\| (/255, every pixel) | mean (/255) | gradient at tile borders / inside |",
              "|---|---|---|---|---|"]
        L += [f"| {r['cfa']} | {r['precision']} | {r['max_diff_255']:.4f} | {r['mean_diff_255']:.5f} | {r['border_inside']:.3f} |"
              for r in res["seams"]]
        L += [""]
    if res.get("held_out"):
        h = res["held_out"]
        L += [f"## Held-out scenes ({h['size']}², {h['frames']} windows each): tile {res['tile']} vs whole frame", "",
              f"ΔPSNR mean {h['dpsnr_mean']:+.3f} dB, worst {h['dpsnr_worst']:+.3f} dB; ΔSSIM mean {h['dssim_mean']:+.4f}, "
              f"worst {h['dssim_worst']:+.4f} (budget −0.1 dB / −0.005).", "",
              "| scene | tick | PSNR whole | PSNR tiled | SSIM whole | SSIM tiled | wall whole / tiled (s) | tiles |", "|---|---|---|---|---|---|---|---|"]
        L += [f"| {r['scene']} | {r['center']} | {r['psnr_whole']:.2f} | {r['psnr_tiled']:.2f} | {r['ssim_whole']:.4f} | "
              f"{r['ssim_tiled']:.4f} | {r['wall_whole']:.1f} / {r['wall_tiled']:.1f} | {r['tiles']} |" for r in h["rows"]]
        L += [""]
    for b in res.get("big") or []:
        bright, dark = b.get("exposure", [1.0, 0.06])
        L += [f"## {b['size']}×{b['size']} natural scene, exposure ×{bright:g} (left) to ×{dark:g} (right) "
              f"(astronaut, static, pooled ±3 windows{'; the left part clipped' if bright > 1 else ''})", "",
              f"Tile line: `{b['tiles']}`; frame TFP σ {', '.join(f'{s:.1f}' for s in b['frame_sigma'])} /255.", "",
              "| | PSNR (dB) | SSIM | wall (s, median) | CPU (s, median) |", "|---|---|---|---|---|",
              f"| whole frame (`tile = 0`) | {b['psnr_whole']:.2f} | {b['ssim_whole']:.4f} | {b['wall_whole']:.1f} | {b['cpu_whole']:.1f} |",
              f"| tiles of {res['tile']} px (the default) | {b['psnr_tiled']:.2f} | {b['ssim_tiled']:.4f} | {b['wall_tiled']:.1f} | {b['cpu_tiled']:.1f} |",
              *([f"| tiles, short tiles kept (`PAY_WORK = 1`) | {b['short_kept']['psnr']:.2f} | {b['short_kept']['ssim']:.4f} | "
                 f"{b['short_kept']['wall']:.1f} | {b['short_kept']['cpu']:.1f} |", "",
                 f"Short tiles kept: `{b['short_kept']['tiles']}`; ΔPSNR {b['short_kept']['dpsnr']:+.3f} dB, ΔSSIM "
                 f"{b['short_kept']['dssim']:+.4f} against the whole frame."] if b.get("short_kept") else []),
              "", f"Gradient across the tile borders / everywhere: whole {b['border_gradient'].get('whole', float('nan')):.3f}, "
              f"tiled {b['border_gradient'].get('tiled', float('nan')):.3f}, short tiles kept "
              f"{b['border_gradient'].get('short kept', float('nan')):.3f} (no seam: the same ratio as the whole frame's).",
              "", f"Default against the whole frame: ΔPSNR {b['dpsnr']:+.3f} dB, ΔSSIM {b['dssim']:+.4f}; time saved {100 * (1 - b['wall_tiled'] / b['wall_whole']):.0f}% "
              f"wall, {100 * (1 - b['cpu_tiled'] / b['cpu_whole']):.0f}% CPU (runs interleaved: "
              + "; ".join(f"{k} " + ", ".join(f"{w:.1f} s @ load {ld:.1f}" for w, _, ld in v) for k, v in b["times"].items()) + ").", ""]
    if res.get("memory"):
        L += ["## Peak memory of `spikeview reconstruct demoN.dat --method guided --at 100` (child ru_maxrss)", "",
              "| capture | flags | peak (MB) | wall (s) | load | tiles row |", "|---|---|---|---|---|---|"]
        L += [f"| {r['capture']} | {r['args']} | {r['peak_mb']:.0f} | {r['wall_s']:.1f} | {r['load']:.1f} | {r['tiles']} |"
              for r in res["memory"]]
        L += [""]
    out.with_suffix(".md").write_text("\n".join(L), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tile", type=int, default=128)
    ap.add_argument("--quick", action="store_true", help="small sizes, few scenes (a smoke run; writes nothing unless --out)")
    ap.add_argument("--no-memory", dest="memory", action="store_false")
    ap.add_argument("--no-held-out", dest="held", action="store_false")
    ap.add_argument("--no-big", dest="big", action="store_false")
    ap.add_argument("--no-seams", dest="seams", action="store_false")
    ap.add_argument("--big-size", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--memory-sizes", type=int, nargs="*", default=[256, 1000, 2000])
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    t_start = time.time()
    res: dict = {"machine": machine(), "tile": a.tile}
    if a.seams:
        print("seams", flush=True)
        res["seams"] = seams()
    if a.held:
        print("held-out scenes", flush=True)
        res["held_out"] = held_out(a.tile, 1 if a.quick else 2, 128 if a.quick else 256,
                                   ["rocket", "page_bright"] if a.quick else None)
    if a.big:
        print("natural scene", flush=True)
        res["big"] = [big_scene(a.tile, 256 if a.quick else a.big_size, 1 if a.quick else a.repeats, bright, dark)
                      for bright, dark in ((1.0, 0.06), (8.0, 0.05))]
    if a.memory:
        res["memory"] = []
        with tempfile.TemporaryDirectory() as d:
            for size in ((256,) if a.quick else (1000, 2000)):
                path = simulate(size, Path(d))
                for extra in ([], ["--tile", "0"]) if size in a.memory_sizes else ():
                    r = peak_rss(path, extra)
                    r["capture"] = f"{size}×{size}"
                    res["memory"].append(r)
                    print(f"  memory {size} {r['args']}: {r['peak_mb']:.0f} MB, {r['wall_s']:.1f} s, rc {r['rc']}, {r['tiles']}", flush=True)
    out = a.out if a.out is not None else (None if a.quick else ROOT / "benchmarks" / "results")
    if out is not None:
        if (out / "tiles.json").exists():  # parts not run this time keep their last figures
            last = json.loads((out / "tiles.json").read_text(encoding="utf-8"))
            for key in ("seams", "held_out", "big", "memory"):
                if key not in res and key in last:
                    res[key] = last[key]
                    res.setdefault("kept", []).append(key)
            done = {r["capture"] for r in res.get("memory", [])}
            res["memory"] = res.get("memory", []) + [r for r in last.get("memory", []) if r["capture"] not in done]
    return save_results(res, out, "tiles", write_report, t_start)


if __name__ == "__main__":
    raise SystemExit(main())
