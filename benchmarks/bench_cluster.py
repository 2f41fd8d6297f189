"""Batch path scaling: windows/s in-process vs. Dask ``local:1`` vs. ``local:2``, for TFP and guided at 256×256.

What it measures (all through ``spikeview reconstruct … --out OUT.zarr``, the path users take):

* windows/s of the whole run (store creation, α estimate, dispatch, compute, Zarr writes) in-process
  and on a LocalCluster of 1 and 2 single-threaded worker processes (cluster start-up timed apart);
* scheduler overhead per window: (wall time of the cluster run − the chunks' own compute time) /
  windows, and its share of a guided window's compute time (target ≤ 5 %);
* peak memory (max RSS) of every worker process;
* the compute time of one guided 1000×1000 window on one thread, and from it and the measured
  overheads a worked estimate of a 1 s capture (2,000 windows) on 1, 8 and 64 workers.

Guided runs set ``guided.reuse = false`` so that every window pays the full sampler (a static demo
scene would otherwise reuse most windows and measure nothing). Usage::

    python benchmarks/bench_cluster.py [--guided-windows 16] [--tfp-windows 480] [--no-big] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load() -> str:
    try:
        return "/".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:  # pragma: no cover
        return "n/a"


def _simulate(path: Path, size: int, ticks: int) -> None:
    from spikeview.cli.main import main

    rc = main(["simulate", "--demo", "--size", str(size), "--ticks", str(ticks), "--seed", "1", "--out", str(path),
               "--overwrite"])
    if rc != 0:
        raise SystemExit(f"simulate failed ({rc})")


def _run(dat: Path, out: Path, extra: list[str], client=None) -> dict:
    from spikeview.cli.batch import run_zarr
    from spikeview.cli.main import build_parser

    if out.exists():
        shutil.rmtree(out)
    args = build_parser().parse_args(["reconstruct", str(dat), "--out", str(out), *extra])
    reports: list = []
    t0 = time.perf_counter()
    run_zarr(args, client=client, reports=reports)
    wall = time.perf_counter() - t0
    rep = reports[0]
    compute = sum(r["seconds"] for r in rep.results)
    rss: dict[int, float] = {}
    for r in rep.results:
        rss[r["pid"]] = max(rss.get(r["pid"], 0.0), r["max_rss_mb"])
    return {"windows": rep.windows, "wall_s": wall, "dispatch_s": rep.seconds, "compute_s": compute,
            "windows_per_s": rep.windows / wall, "chunks": rep.chunks_done, "max_rss_mb": sorted(rss.values())}


def _cluster(n: int):
    import logging

    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    lc = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.ERROR)
    client = Client(lc)
    return lc, client, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tfp-windows", type=int, default=480)
    ap.add_argument("--guided-windows", type=int, default=16)
    ap.add_argument("--chunk", type=int, default=16, help="TFP windows per chunk (default 16)")
    ap.add_argument("--guided-chunk", type=int, default=4, help="guided windows per chunk (default 4: 4 chunks to share)")
    ap.add_argument("--steps", type=int, default=None, help="guided steps (default: the recipe's)")
    ap.add_argument("--no-big", action="store_true", help="skip the 1000x1000 guided window")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument("--from-json", metavar="FILE", help="only re-render cluster.md from an earlier cluster.json")
    a = ap.parse_args(argv)
    if a.from_json:
        res = json.loads(Path(a.from_json).read_text(encoding="utf-8"))
        for k, v in res.get("args", {}).items():
            if k not in ("out", "from_json"):
                setattr(a, k, v)
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "cluster.md").write_text(report(res, a), encoding="utf-8")
        print((out / "cluster.md").read_text(encoding="utf-8"))
        return 0

    import torch

    tmp = Path(tempfile.mkdtemp(prefix="bench_cluster_"))
    load_before = _load()
    res: dict = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                             "torch_threads_in_process": torch.get_num_threads()}}
    try:
        dat = tmp / "cap256.dat"
        ticks = max(a.tfp_windows * 10, a.guided_windows * 10) + 10
        _simulate(dat, 256, ticks)
        tfp = ["--method", "tfp", "--range", f"5:{a.tfp_windows * 10}:10", "--chunk", str(a.chunk)]
        guided = ["--method", "guided", "--range", f"5:{a.guided_windows * 10}:10", "--chunk", str(a.guided_chunk)]
        if a.steps:
            guided += ["--steps", str(a.steps)]
        # every window a full sample: write a preset with reuse off
        preset = tmp / "noreuse.toml"
        preset.write_text("[guided]\nreuse = false\n", encoding="utf-8")
        guided += ["--preset", str(preset)]
        runs: dict = {}

        def warm(extra: list[str], n: int, client=None) -> float:
            # one single-window chunk per worker first: imports, numba caches, prior load (timed apart)
            rng = extra.index("--range")
            w = extra[:rng] + ["--range", f"5:{5 + 10 * n}:10"] + extra[rng + 2:]
            w[w.index("--chunk") + 1] = "1"
            return _run(dat, tmp / "warm.zarr", w, client=client)["wall_s"]

        for name, extra in (("tfp", tfp), ("guided", guided)):
            w0 = warm(extra, 1)
            runs[name] = {"in-process": _run(dat, tmp / f"{name}_in.zarr", extra)}
            runs[name]["in-process"]["warmup_s"] = w0
            for n in (1, 2):
                lc, client, start = _cluster(n)
                try:
                    w = warm(extra, n, client)
                    r = _run(dat, tmp / f"{name}_l{n}.zarr", extra, client=client)
                finally:
                    client.close()
                    lc.close()
                r["cluster_start_s"], r["warmup_s"] = start, w
                runs[name][f"local:{n}"] = r
        res["runs"] = runs
        if not a.no_big:
            big = tmp / "cap1000.dat"
            _simulate(big, 1000, 30)
            lc, client, _ = _cluster(1)
            try:
                # warm the worker on the small capture first (imports, prior), then time one 1000x1000 window
                _run(dat, tmp / "warm.zarr", ["--method", "guided", "--at", "15", "--preset", str(preset),
                                              *(["--steps", str(a.steps)] if a.steps else [])], client=client)
                r = _run(big, tmp / "big.zarr", ["--method", "guided", "--at", "15", "--preset", str(preset),
                                                  *(["--steps", str(a.steps)] if a.steps else [])], client=client)
            finally:
                client.close()
                lc.close()
            res["big"] = r
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    res["load_before"], res["load_after"] = load_before, _load()
    try:
        import subprocess

        res["commit"] = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                       text=True, timeout=10).stdout.strip()
    except OSError:  # pragma: no cover - no git
        res["commit"] = ""
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    res["args"] = vars(a)
    (out / "cluster.json").write_text(json.dumps(res, indent=2), encoding="utf-8")
    (out / "cluster.md").write_text(report(res, a), encoding="utf-8")
    print((out / "cluster.md").read_text(encoding="utf-8"))
    return 0


def _estimate(per_window: float, overhead_per_chunk: float, start: float, workers: int, n: int = 2000,
              chunk: int = 16) -> float:
    """Wall seconds for ``n`` windows in chunks of ``chunk`` on ``workers`` single-threaded workers."""
    chunks = math.ceil(n / chunk)
    rounds = math.ceil(chunks / workers)
    return start + rounds * (chunk * per_window + overhead_per_chunk)


def report(res: dict, a) -> str:
    runs = res["runs"]
    lines = ["# Long captures on Dask: chunked batch path (`benchmarks/bench_cluster.py`)", ""]
    lines.append(
        f"256×256 Bayer demo capture (simulated), 10-tick windows, chunks of {a.chunk} (TFP) and {a.guided_chunk} (guided) "
        "windows, written to a Zarr store "
        "through `spikeview reconstruct … --out OUT.zarr` (store, α estimate, dispatch, compute, writes all timed). "
        "Guided: the recipe's defaults with `reuse = false`, so every window pays the full sampler. In-process uses "
        f"torch's default {res['machine']['torch_threads_in_process']} threads; Dask workers are single-threaded "
        "processes (`local:N`). Cluster start-up is timed apart and not in windows/s.")
    lines.append("")
    lines.append("| method | run | windows | wall s | windows/s | vs in-process | compute s (sum of chunks) | "
                 "wall − compute, per window | cluster start s | warm-up s | worker max RSS (MiB) |")
    lines.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for m in ("tfp", "guided"):
        base = runs[m]["in-process"]["windows_per_s"]
        for k in ("in-process", "local:1", "local:2"):
            r = runs[m][k]
            ovh = (r["wall_s"] - r["compute_s"]) / r["windows"]
            ovh_s = f"{ovh * 1000:.1f} ms" if k != "local:2" else "— (compute runs in parallel)"
            rss = ", ".join(f"{v:.0f}" for v in r["max_rss_mb"]) if k != "in-process" else f"(driver {r['max_rss_mb'][0]:.0f})"
            start = f"{r['cluster_start_s']:.1f}" if "cluster_start_s" in r else "—"
            lines.append(f"| {m} | {k} | {r['windows']} | {r['wall_s']:.2f} | {r['windows_per_s']:.2f} | "
                         f"{r['windows_per_s'] / base:.2f}× | {r['compute_s']:.2f} | {ovh_s} | "
                         f"{start} | {r['warmup_s']:.1f} | {rss} |")
    lines += ["", "Warm-up: a first run of one single-window chunk per worker (imports, numba caches, loading the "
                  "prior), once per worker process and not counted in windows/s."]
    def sched(m: str) -> float:
        # what a local:1 run spends beyond an in-process run, per window, compute time taken out of both:
        # task round trips, the worker opening the store per chunk (α and store creation are in both)
        r, i = runs[m]["local:1"], runs[m]["in-process"]
        return ((r["wall_s"] - r["compute_s"]) - (i["wall_s"] - i["compute_s"])) / r["windows"]

    g1 = runs["guided"]["local:1"]
    t1 = runs["tfp"]["local:1"]
    g_pw = g1["compute_s"] / g1["windows"]
    g_ovh, t_ovh = sched("guided"), sched("tfp")
    lines += ["", "**Scheduler overhead per window** = (wall − compute of the `local:1` run − the same of the "
                  "in-process run) / windows: what Dask adds (task round trips, the worker opening the store for "
                  "each chunk), with the per-run costs both share (α estimate, store creation) taken out. "
                  f"TFP (chunks of {a.chunk}): {t_ovh * 1000:.2f} ms a window, i.e. {t_ovh * a.chunk * 1000:.0f} ms a "
                  f"chunk, against {t1['compute_s'] / t1['windows'] * 1000:.2f} ms of TFP compute a window: TFP is "
                  f"overhead-bound on Dask and best run in-process. Guided (chunks of {a.guided_chunk}): "
                  f"{g_ovh * 1000:.1f} ms a window = **{100 * g_ovh / g_pw:.2f} % of a guided window's {g_pw:.2f} s** "
                  "of compute on one worker (target ≤ 5 %). In-process guided ran slower than `local:1` here: its torch "
                  "used 2 threads on 2 cores that other jobs were also using (load above 6), where a worker uses one."]
    if "big" in res:
        b = res["big"]
        per = b["compute_s"] / b["windows"]
        per_chunk = max(t_ovh, 0.0) * a.chunk  # scheduler cost per chunk of 16, from the TFP run
        start = runs["guided"]["local:2"]["cluster_start_s"]
        lines += ["", "### Worked estimate: 1 s of a 1000×1000 capture (2,000 ten-tick windows), guided",
                  "", f"Measured: one guided 1000×1000 window on one single-threaded worker: **{per:.1f} s** "
                  f"(worker max RSS {max(b['max_rss_mb']):.0f} MiB); scheduler cost per chunk of {a.chunk} windows "
                  f"{per_chunk:.2f} s (TFP run above); cluster start {start:.1f} s. Wall time = start + "
                  f"⌈⌈2000/{a.chunk}⌉ / workers⌉ × ({a.chunk} × {per:.1f} s + {per_chunk:.2f} s), one worker per core, "
                  "reuse off (reuse on a mostly static scene is faster):", "",
                  "| workers | wall time | note |", "|---:|---:|---|"]
        n_chunks = math.ceil(2000 / a.chunk)
        for w, note in ((1, "one core"), (8, f"one 8-core node: {n_chunks} chunks in {math.ceil(n_chunks / 8)} rounds"),
                        (64, f"{n_chunks} chunks in {math.ceil(n_chunks / 64)} rounds: {math.ceil(n_chunks / 64) * a.chunk} "
                             f"windows per worker where a perfect split gives {2000 / 64:.1f}")):
            t = _estimate(per, per_chunk, start, w, chunk=a.chunk)
            lines.append(f"| {w} | {t / 3600:.2f} h ({t:,.0f} s) | {note} |")
        lines += ["", f"Not in the estimate: reading the input (a 1 s 1000×1000 capture is 2.5 GB; each window reads "
                      "its 10 ticks, 1.25 MB), the α estimate before the split (64 windows counted: well under a second) "
                      "and the writes: every window is 12 MB of float32 (Zstandard-compressed in the store), so 64 "
                      f"workers write about {64 * 12 / per:.0f} MB/s in total, 24 GB for the whole second, which the "
                      "shared file system must absorb. Reuse (on by default) makes mostly static scenes faster than "
                      "these figures."]
    lines += ["", (f"Code: commit {res['commit']}. " if res.get("commit") else "")
              + f"Machine: {res['machine']['platform']}, os.cpu_count() = {res['machine']['cpus']}, Python "
                  f"{res['machine']['python']}. **Shared with other jobs while measuring** (load average 1/5/15 min "
                  f"before {res['load_before']}, after {res['load_after']}): seconds are upper bounds; with 2 cores "
                  "and other engineers' jobs, `local:2` cannot show a clean 2×.", "",
              f"Command: `python benchmarks/bench_cluster.py --tfp-windows {a.tfp_windows} --guided-windows "
              f"{a.guided_windows} --chunk {a.chunk} --guided-chunk {a.guided_chunk}`", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
