"""Stand-ins for core pieces the app needs while they are being written (no Qt).

Used only when the core module is missing (an ImportError); each mirrors the agreed interface:

* :func:`demo_capture` — ``spikeview.sim.demo_capture(size, n_ticks)``;
* :func:`open_source` — ``spikeview.io.open_source(path, format=, width=, height=, cfa=, flip_vertical=)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from spikeview.cfa import channel_map
from spikeview.errors import GeometryError, InputFileError
from spikeview.io.source import ArraySource, SpikeSource, StreamInfo

#: per-channel sensor response (R, G, B): a green cast like real captures
_RESPONSE = np.array([0.55, 0.9, 0.4], dtype=np.float32)


def _scene(h: int, w: int, t: float) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: colour gradient, moving disc and a rotating bar; ``t`` in [0, 1]."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u, v = xx / max(w - 1, 1), yy / max(h - 1, 1)
    img = np.stack([0.25 + 0.5 * u, 0.3 + 0.3 * v, 0.7 - 0.5 * u], axis=-1)
    cx, cy, r = w * (0.2 + 0.6 * t), h * 0.5, min(h, w) * 0.18
    disc = ((xx - cx) ** 2 + (yy - cy) ** 2) < r * r
    img[disc] = (0.95, 0.25, 0.15)
    ang = np.pi * t
    d = np.abs((xx - w / 2) * np.sin(ang) - (yy - h / 2) * np.cos(ang))
    bar = (d < min(h, w) * 0.04) & (np.hypot(xx - w / 2, yy - h / 2) < min(h, w) * 0.45)
    img[bar] = (0.15, 0.85, 0.2)
    return img.astype(np.float32)


def demo_capture(size: int = 128, n_ticks: int = 1000, seed: int = 0, cfa: str = "RGGB") -> ArraySource:
    h = w = size
    rng = np.random.default_rng(seed)
    cmap = channel_map(cfa, h, w)
    resp = _RESPONSE[cmap]
    v = rng.uniform(0, 1, (h, w)).astype(np.float32)
    out = np.empty((n_ticks, h, w), dtype=np.uint8)
    n_key = 16
    keys = [_scene(h, w, i / (n_key - 1)) for i in range(n_key)]

    def gt_at(tick: int) -> np.ndarray:
        f = tick / max(n_ticks - 1, 1) * (n_key - 1)
        i = min(int(f), n_key - 2)
        a = f - i
        return ((1 - a) * keys[i] + a * keys[i + 1]).astype(np.float32)

    take = np.take_along_axis
    for tick in range(n_ticks):
        gt = gt_at(tick)
        intensity = take(gt, cmap[..., None].astype(np.intp), axis=-1)[..., 0] * resp * 0.6
        v += intensity
        fire = v >= 1.0
        v -= fire
        out[tick] = fire
    src = ArraySource(out, cfa=cfa)
    src.gt_at = gt_at  # type: ignore[attr-defined]
    return src


def open_source(path: str | Path, format: str | None = None, width: int | None = None, height: int | None = None,
                cfa: str | None = "RGGB", flip_vertical: bool | None = None, **_: Any) -> SpikeSource:
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{path}: file not found; check the path.")
    if path.suffix in (".npy", ".npz"):
        try:
            data = np.load(path)
            arr = data[data.files[0]] if hasattr(data, "files") else data
        except Exception as e:
            raise InputFileError(f"{path}: not a readable numpy file ({e}); export the spikes as a (T, H, W) array.") from None
        if arr.ndim != 3:
            raise InputFileError(f"{path}: array of shape {arr.shape} is not (T, H, W); reshape it first.")
        return ArraySource(arr, cfa=None if cfa in (None, "none") else cfa)
    size = path.stat().st_size
    if size == 0:
        raise InputFileError(f"{path}: the file is empty; check that the capture finished writing.")
    if width is None or height is None:
        cands = [(w, h) for (w, h) in [(1000, 1000), (400, 250), (256, 256), (128, 128), (64, 64)] if size % (w * h // 8) == 0]
        raise GeometryError(f"{path}: a plain .dat file has no header; give its width and height (or write a sidecar).", cands)
    frame = width * height // 8
    n = size // frame
    if n == 0:
        raise GeometryError(f"{path}: smaller than one {width}x{height} frame; check width and height.", [])
    raw = np.fromfile(path, dtype=np.uint8, count=n * frame).reshape(n, frame)
    bits = np.unpackbits(raw, axis=1, bitorder="little").reshape(n, height, width)
    fv = True if flip_vertical is None else bool(flip_vertical)
    if fv:
        bits = bits[:, ::-1]
    info = StreamInfo(width=width, height=height, n_frames=n, cfa=None if cfa in (None, "none") else cfa,
                      format="plain", flip_vertical=fv, path=path)
    return ArraySource(np.ascontiguousarray(bits), info=info)
