"""``spikeview info``: a human summary of a spike stream."""

from __future__ import annotations

import argparse

import numpy as np

from spikeview.cfa import cfa_to_str
from spikeview.io.source import SpikeSource

#: the command reads a spike file: the geometry flags are added (:func:`spikeview.cli._common.add_geometry_flags`)
GEOMETRY = True
EPILOG = "example:\n  spikeview info capture.dat --width 1000 --height 1000 --cfa BGGR\n"


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="FILE", help="spike file (.dat, raw camera stream, .npy/.npz)")
    p.add_argument("--sample-windows", type=int, default=64,
                   help="number of windows spread over the file used for firing-rate statistics (default 64)")


def run(args: argparse.Namespace) -> int:
    from spikeview.cli._common import open_source_from_args
    from spikeview.errors import ParameterError

    if args.sample_windows < 1:
        raise ParameterError(f"--sample-windows {args.sample_windows} is not valid: use at least 1 (default 64).")
    with open_source_from_args(args, show_warnings=False) as src:  # `info` lists the warnings itself
        print(describe(src, sample_windows=args.sample_windows))
    return 0


def firing_rates(src: SpikeSource, sample_windows: int = 64, window: int = 64) -> dict[str, float]:
    """Mean spikes per tick per photosite class, from windows spread evenly over the stream.

    Returns ``{"all": rate}`` for monochrome streams and ``{"R", "Gr", "Gb", "B", "all"}`` for
    Bayer streams. Rates are in spikes per tick, in [0, 1].
    """
    n = src.n_frames
    window = max(1, min(window, n))
    k = max(1, min(sample_windows, n // window))
    starts = np.linspace(0, n - window, k).round().astype(int)
    total = np.zeros((src.height, src.width), dtype=np.float64)
    for a in starts:
        total += src.count(int(a), int(a) + window)
    rate = total / (k * window)
    from spikeview.classical.colour_cast import site_rates  # the library's per-site statistics

    out: dict[str, float] = site_rates(rate, src.cfa) if src.cfa is not None else {}
    out["all"] = float(rate.mean())
    return out


def describe(src: SpikeSource, sample_windows: int = 64) -> str:
    info = src.info
    lines = []
    if info.path is not None:
        lines.append(f"file:        {info.path}")
    flips = [n for n, f in (("vertical", info.flip_vertical), ("horizontal", info.flip_horizontal)) if f]
    lines += [
        f"format:      {info.format}",
        f"geometry:    {info.width} x {info.height} (width x height)",
        f"cfa:         {cfa_to_str(info.cfa)} (top-left 2x2 after flips)",
        f"flips:       {', '.join(flips) if flips else 'none'}",
        f"tick rate:   {info.tick_rate:g} Hz ({1e6 / info.tick_rate:g} us per tick)",
        f"frames:      {info.n_frames} ticks",
        f"duration:    {info.duration_s * 1e3:.3f} ms",
    ]
    if info.n_frames > 0:
        rates = firing_rates(src, sample_windows=sample_windows)
        parts = [f"{k} {v:.4f}" for k, v in rates.items()]
        lines.append(f"firing rate: {', '.join(parts)} spikes/tick")
    for key, value in info.extra.items():
        if isinstance(value, dict):
            summary = ", ".join(f"{k}={v}" for k, v in list(value.items())[:8])
            more = " ..." if len(value) > 8 else ""
            lines.append(f"{key + ':':<12} {summary}{more}")
    cam = getattr(info, "camera", None)
    if cam is not None:
        lines.append(f"camera:      {cam.describe()}")
    if info.n_frames > 0 and min(info.width, info.height) > 0:
        from spikeview.classical.defects import find_defects

        lines.append(f"defects:     {find_defects(src).describe()}")
    for w in info.warnings:
        lines.append(f"warning:     {w}")
    return "\n".join(lines)
