"""The Zarr store of a batch reconstruction.

Layout of ``OUT.zarr`` (Zarr v3, one file per chunk, every chunk file written atomically by Zarr's
local store: temporary name, then rename):

==================  ===================  ================================================================
array               shape, dtype         meaning
==================  ===================  ================================================================
``frames``          (N, H, W, C) f4      linear frames in [0, 1]; C = 3 (Bayer) or 1 (monochrome);
                                         chunks of ``chunk`` windows (one Zarr chunk = one work chunk);
                                         NaN where no chunk has been written yet
``centre_tick``     (N,) i8              centre tick of each window
``window``          (N, 2) i8            tick range ``[a, b)`` of each window
``done``            (n_chunks,) u1       completion marker of each work chunk (1 = frames written);
                                         written after the chunk's frames, one Zarr chunk per marker
``seconds``         (n_chunks,) f8       compute time of each work chunk (for the benchmark / progress)
==================  ===================  ================================================================

Group attribute ``spikeview`` (JSON): ``format``, ``input`` (path) and ``fingerprint`` (name,
size, hash of its first and last MiB), ``settings`` (the recipe tables that decide the frames, as
given), ``recipe`` (the preset TOML, with the α estimate recorded, which ``spikeview reconstruct
--preset`` re-runs), ``alpha`` (colour-cast estimate), ``white_point``, ``method``, ``window``,
``step``, ``tick_rate``, ``chunk``, ``keyframe``, ``n_windows``, ``frame_shape``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import InputFileError, ParameterError

#: version of the layout above
STORE_FORMAT = 1
_MIB = 1 << 20


def input_fingerprint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Name, size and a BLAKE2b hash of the first and last MiB of the input (cheap on multi-GB files)."""
    p = Path(path)
    size = p.stat().st_size
    h = hashlib.blake2b(digest_size=16)
    with open(p, "rb") as f:
        h.update(f.read(_MIB))
        if size > 2 * _MIB:
            f.seek(size - _MIB)
            h.update(f.read(_MIB))
    return {"name": p.name, "size": int(size), "blake2b": h.hexdigest()}


def create_store(path: str | os.PathLike[str], *, centres: np.ndarray, windows: np.ndarray,
                 frame_shape: tuple[int, int, int], chunk: int, attrs: dict[str, Any]) -> None:
    """Create an empty store (replacing any store at ``path``) with the layout of the module docstring."""
    import zarr

    n = len(centres)
    n_chunks = -(-n // chunk)
    g = zarr.open_group(str(path), mode="w")
    g.create_array("frames", shape=(n, *frame_shape), chunks=(chunk, *frame_shape), dtype="float32", fill_value=np.nan)
    g.create_array("centre_tick", shape=(n,), chunks=(n,), dtype="int64")[:] = np.asarray(centres, dtype=np.int64)
    g.create_array("window", shape=(n, 2), chunks=(n, 2), dtype="int64")[:] = np.asarray(windows, dtype=np.int64)
    g.create_array("done", shape=(n_chunks,), chunks=(1,), dtype="uint8", fill_value=0)
    g.create_array("seconds", shape=(n_chunks,), chunks=(1,), dtype="float64", fill_value=np.nan)
    g.attrs["spikeview"] = {"format": STORE_FORMAT, **attrs}


def open_store(path: str | os.PathLike[str], mode: str = "r"):
    """The Zarr group of a spikeview store.

    Raises:
        InputFileError: ``path`` is missing or is not a store written by ``spikeview reconstruct``.
    """
    import zarr

    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{p}: store not found; write it with spikeview reconstruct INPUT --range A:B --out {p.name}.")
    try:
        g = zarr.open_group(str(p), mode=mode)
        meta = g.attrs.get("spikeview")
    except Exception as e:  # zarr raises several kinds for a folder that is not a store
        raise InputFileError(f"{p}: not a Zarr store ({type(e).__name__}); pass a store written by spikeview reconstruct.") from None
    if not isinstance(meta, dict) or meta.get("format") != STORE_FORMAT:
        raise InputFileError(f"{p}: not a spikeview store (format {STORE_FORMAT}); pass a store written by spikeview reconstruct.")
    return g


def store_attrs(group) -> dict[str, Any]:
    return dict(group.attrs["spikeview"])


def done_mask(group) -> np.ndarray:
    """``(n_chunks,)`` bool: which work chunks are complete."""
    return np.asarray(group["done"][:], dtype=bool)


def write_chunk(path: str | os.PathLike[str], index: int, lo: int, frames: np.ndarray, seconds: float) -> None:
    """Write work chunk ``index`` (frames of windows ``lo …``), then its completion marker.

    Each Zarr chunk file is replaced atomically, and the marker is written last: a chunk killed
    half-way has no marker and is recomputed by ``--resume``.
    """
    import zarr

    g = zarr.open_group(str(path), mode="r+")
    g["frames"][lo:lo + len(frames)] = frames
    g["seconds"][index] = seconds
    g["done"][index] = 1


def _first_difference(a: Any, b: Any, where: str = "") -> tuple[str, Any, Any] | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            d = _first_difference(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))
            if d is not None:
                return d
        return None
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        a, b = list(a), list(b)
    return None if a == b else (where, a, b)


def check_compatible(path: str | os.PathLike[str], attrs: dict[str, Any], *, fingerprint: dict[str, Any],
                     settings: dict[str, Any], chunk: int) -> None:
    """Refuse to resume a store that another input or other settings wrote (one sentence each)."""
    p = Path(path)
    theirs = attrs.get("fingerprint", {})
    if theirs.get("size") != fingerprint["size"] or theirs.get("blake2b") != fingerprint["blake2b"]:
        raise ParameterError(
            f"{p.name} belongs to another input ({theirs.get('name')}, {theirs.get('size')} bytes), not "
            f"{fingerprint['name']} ({fingerprint['size']} bytes); resume with that input or write to a new --out."
        )
    # the export table does not change the frames: fps etc. may differ on resume
    diff = _first_difference({k: v for k, v in attrs.get("settings", {}).items() if k != "export"},
                             {k: v for k, v in settings.items() if k != "export"})
    if diff is not None:
        key, old, new = diff
        raise ParameterError(
            f"{p.name} was written with other settings ({key} = {old!r} there, {new!r} now); "
            "resume with the same settings (leave the flags out to use the store's) or write to a new --out."
        )
    if int(attrs.get("chunk", chunk)) != chunk:
        raise ParameterError(
            f"{p.name} was written in chunks of {attrs.get('chunk')} windows, not {chunk}; "
            f"resume with --chunk {attrs.get('chunk')} (or leave --chunk out)."
        )


def read_frames(group, lo: int = 0, hi: int | None = None) -> np.ndarray:
    """Frames ``[lo, hi)`` as float32 ``(n, H, W, C)``."""
    return np.asarray(group["frames"][lo:hi], dtype=np.float32)
