"""What the benchmark scripts share: the CPU's name and the load for the report header, waiting on a Qt event
loop, and writing the report."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np


def cpu_model(default: str = "unknown CPU") -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (``default`` where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return default


def machine_words(m: dict) -> str:
    """The machine of a result's ``machine`` record in a report's words: model, CPUs, the flags that matter, torch."""
    return f"{m['model']}, {m['cpus']} CPUs, flags {' '.join(m['flags'])}; torch {m['torch']}"


def load_average(sep: str = " / ") -> str:
    """The 1-, 5- and 15-minute load averages (``"n/a"`` where the system has none)."""
    try:
        return sep.join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def wait(app, cond, timeout: float = 120.0, pause: float = 0.001) -> None:
    """Run ``app``'s event loop until ``cond()`` holds (``TimeoutError`` after ``timeout`` s)."""
    end = time.perf_counter() + timeout
    while not cond():
        if time.perf_counter() > end:
            raise TimeoutError("benchmark step timed out")
        app.processEvents()
        time.sleep(pause)


def write_report(out: Path, lines: list[str]) -> int:
    """Write the report's lines to ``out`` (its folder made), say so, and return the exit status 0."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0


def synthetic_capture(folder: Path, size: int, ticks: int, cfa: str | None, seed: int = 0) -> Path:
    """A moving scene as a plain ``.dat`` with sidecar (integrate-and-fire; RGGB or monochrome).

    A smooth pattern sliding 0.2 px per tick, green-heavy spectral gains on RGGB, random initial
    phase: cheap at 1000x1000 (no simulator), good enough where only speed is measured.
    """
    from spikeview.cfa import channel_map
    from spikeview.io import write_plain

    name = f"ui_{size}_{cfa or 'mono'}_{ticks}.dat"
    path = folder / name
    if path.exists() and Path(str(path) + ".toml").exists():
        return path
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) / size
    if cfa is not None:
        cmap = channel_map(cfa, size, size)
        gains = np.array([0.45, 0.8, 0.35], np.float32)[cmap]
    else:
        cmap, gains = None, np.float32(0.7)
    v = rng.random((size, size), dtype=np.float32)
    spikes = np.empty((ticks, size, size), np.uint8)
    for t in range(ticks):
        shift = 0.2 * t / size
        r = 0.5 + 0.45 * np.sin(2 * np.pi * (3 * (xx + shift) + yy))
        if cmap is None:
            scene = r
        else:
            g = 0.5 + 0.45 * np.sin(2 * np.pi * (2 * (yy - shift) + 0.3))
            b = 0.5 + 0.45 * np.cos(2 * np.pi * (4 * (xx + yy) + shift))
            scene = np.where(cmap == 0, r, np.where(cmap == 1, g, b))
        v += scene * gains
        fire = v >= 1.0
        v -= fire
        spikes[t] = fire
    write_plain(path, spikes, flip_vertical=True, cfa=cfa)
    return path
