"""The Zarr store of a batch reconstruction.

Layout of ``OUT.zarr`` (Zarr v3, one file per chunk, every chunk file written atomically by Zarr's
local store: temporary name, then rename):

==================  ===================  ================================================================
array               shape, dtype         meaning
==================  ===================  ================================================================
``frames``          (N, H, W, C) f4      linear frames (``Y·α/η``, not divided by the white point:
                                         ``spikeview export`` maps them as ``reconstruct`` does);
                                         C = 3 (Bayer) or 1 (monochrome); zstd with its content
                                         checksum (a chunk damaged on disk fails to decode);
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

:func:`check_store` validates all of it before ``spikeview export`` or ``--resume`` reads a store
(one sentence per problem); :meth:`StoreCheck.read_chunk` decodes one work chunk and names it on failure.
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
    from zarr.codecs import ZstdCodec

    # zstd with its content checksum: a chunk damaged on disk fails to decode (and is named) instead of
    # being exported with wrong values
    g.create_array("frames", shape=(n, *frame_shape), chunks=(chunk, *frame_shape), dtype="float32", fill_value=np.nan,
                   compressors=ZstdCodec(level=0, checksum=True))
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


# ------------------------------------------------------------------------------- validation
#: attributes every store records, with a check and what the value must be (for the message)
_METHODS = ("tfp", "tfi", "guided")


from spikeview.export.settings import WHITE_MAX as _WHITE_MAX, WHITE_MIN as _WHITE_MIN  # noqa: E402 (one rule)

_WHITE = (_WHITE_MIN, _WHITE_MAX)


def _is_int(v: Any, lo: int = 0) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool) and int(v) >= lo


def _is_pos(v: Any) -> bool:
    return isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and bool(np.isfinite(v)) and v > 0


_ATTR_RULES: dict[str, tuple[Any, str]] = {
    "input": (lambda v: isinstance(v, str) and bool(v), "the input's path (text)"),
    "fingerprint": (lambda v: isinstance(v, dict) and isinstance(v.get("name"), str) and _is_int(v.get("size"))
                    and isinstance(v.get("blake2b"), str) and len(v["blake2b"]) == 32,
                    "a table of the input's name, size and blake2b hash"),
    "settings": (lambda v: isinstance(v, dict), "the recipe tables"),
    "recipe": (lambda v: isinstance(v, str), "the preset TOML (text)"),
    "alpha": (lambda v: v is None or (isinstance(v, list) and len(v) == 3 and all(_is_pos(a) for a in v)),
              "three positive gains (or null for a monochrome stream)"),
    "white_point": (lambda v: _is_pos(v) and _WHITE[0] <= float(v) <= _WHITE[1],
                    f"a white point from {_WHITE[0]:g} to {_WHITE[1]:g} (the export settings' range)"),
    "method": (lambda v: v in _METHODS, "one of tfp, tfi, guided"),
    "window": (lambda v: _is_int(v, 1), "a whole number of ticks >= 1"),
    "step": (lambda v: _is_int(v, 1), "a whole number of ticks >= 1"),
    "tick_rate": (_is_pos, "a positive number of ticks per second"),
    "chunk": (lambda v: _is_int(v, 1), "a whole number of windows >= 1"),
    "keyframe": (lambda v: _is_int(v, 1), "a whole number of windows >= 1"),
    "n_windows": (lambda v: _is_int(v, 1), "a whole number of windows >= 1"),
    "frame_shape": (lambda v: isinstance(v, list) and len(v) == 3 and all(_is_int(x, 1) for x in v) and v[2] in (1, 3),
                    "[height, width, channels] with 1 or 3 channels"),
}


class StoreCheck:
    """A store that :func:`check_store` accepted: its group, attributes and completion markers.

    Attributes:
        path: the store.
        group: the Zarr group (opened read-only).
        attrs: the ``spikeview`` attribute (every field checked).
        done: ``(n_chunks,)`` bool, chunks marked complete by a readable marker.
        unreadable: chunks whose marker is missing or unreadable (not in ``done``).
        markers_lost: the ``done`` array itself is missing or cannot be opened.
        seconds_lost: the ``seconds`` array (timings) is missing or cannot be opened.
    """

    def __init__(self, path: Path, group: Any, attrs: dict[str, Any], done: np.ndarray, unreadable: list[int],
                 markers_lost: bool):
        self.path, self.group, self.attrs = path, group, attrs
        self.done, self.unreadable, self.markers_lost = done, unreadable, markers_lost
        self.seconds_lost = False

    @property
    def n_chunks(self) -> int:
        return int(self.done.size)

    def bounds(self, index: int) -> tuple[int, int]:
        """Window indices ``[lo, hi)`` of work chunk ``index``."""
        chunk, n = int(self.attrs["chunk"]), int(self.attrs["n_windows"])
        return index * chunk, min((index + 1) * chunk, n)

    def rerun(self) -> str:
        """The command that finishes the store (``--resume``)."""
        return f"spikeview reconstruct {self.attrs['input']} --out {self.path} --resume"

    def read_chunk(self, index: int) -> np.ndarray:
        """The frames of work chunk ``index`` (float32 ``(n, H, W, C)``), all finite.

        Raises:
            InputFileError: the chunk cannot be decoded or holds no frames (names the chunk, its windows and the fix).
        """
        lo, hi = self.bounds(index)
        where = f"{self.path}: chunk {index} (windows {lo}-{hi - 1})"
        try:
            block = np.asarray(self.group["frames"][lo:hi], dtype=np.float32)
        except Exception as e:  # noqa: BLE001 - zarr/numcodecs raise many kinds for a damaged chunk file
            raise InputFileError(f"{where} cannot be read ({type(e).__name__}: {_short(e)}); recompute it with "
                                 f"{self.rerun()}.") from None
        if not np.isfinite(block).all():
            raise InputFileError(f"{where} holds no frames or non-finite values although it is marked done; recompute "
                                 f"it with {self.rerun()}.")
        return block


def _short(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return (text[:120] + "…") if len(text) > 120 else (text or "no message")


def check_store(path: str | os.PathLike[str]) -> StoreCheck:
    """Validate a store before ``spikeview export`` or ``--resume`` reads it: the layout, every array's
    shape, dtype and chunking, every attribute's presence, type and range, and their consistency
    (window count, channels, chunk size, the recipe), then read the completion markers.

    Missing or unreadable markers are not an error here (``unreadable``, ``markers_lost``): export
    refuses such a store, ``--resume`` recomputes those chunks. Frames are not decoded
    (:meth:`StoreCheck.read_chunk` does that, chunk by chunk).

    Raises:
        InputFileError: one sentence naming the store, what is wrong and what to do.
    """
    import tomllib

    from spikeview.recipe import Recipe

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputFileError(f"{p}: a file, not a Zarr store (a folder); pass a store written by spikeview reconstruct.")
    group = open_store(p)
    try:
        attrs = dict(group.attrs["spikeview"])
    except Exception as e:  # noqa: BLE001
        raise InputFileError(f"{p}: its attributes cannot be read ({type(e).__name__}); write the store again.") from None
    source = attrs.get("input") if isinstance(attrs.get("input"), str) and attrs.get("input") else "INPUT"
    run = attrs.get("settings", {}).get("run", {}) if isinstance(attrs.get("settings"), dict) else {}
    span = run.get("range") if isinstance(run, dict) and isinstance(run.get("range"), str) else "A:B"
    again = f"write it again with spikeview reconstruct {source} --range {span} --out {p} --overwrite"

    def bad(what: str) -> InputFileError:
        return InputFileError(f"{p}: {what}; {again}.")

    for name, (ok, expected) in _ATTR_RULES.items():
        if name not in attrs:
            raise bad(f"the attribute {name} is missing (it should be {expected})")
        try:
            good = bool(ok(attrs[name]))
        except Exception:  # noqa: BLE001 - a value of a type the rule did not expect
            good = False
        if not good:
            shown = repr(attrs[name])
            raise bad(f"the attribute {name} is {shown[:60]}, not {expected}")
    try:
        settings = Recipe.from_dict(attrs["settings"], where="settings")
        recipe = Recipe.from_dict(tomllib.loads(attrs["recipe"]), where="recipe")
    except (tomllib.TOMLDecodeError, ValueError, TypeError, KeyError) as e:
        raise bad(f"its recorded recipe is damaged ({_short(e).rstrip('.')})") from None
    n, chunk = int(attrs["n_windows"]), int(attrs["chunk"])
    fshape = tuple(int(v) for v in attrs["frame_shape"])
    mono = settings.stream.cfa in (None, "none")
    checks = [
        (settings.run.method == attrs["method"] == recipe.run.method,
         f"the attribute method ({attrs['method']}) disagrees with its recipe ({settings.run.method})"),
        (settings.span() == int(attrs["window"]),
         f"the attribute window ({attrs['window']}) disagrees with its recipe ({settings.span()} ticks)"),
        ((fshape[2] == 1) == mono, f"frames of {fshape[2]} channel(s) disagree with its recipe's cfa "
                                   f"({settings.stream.cfa or 'none'})"),
        (attrs["alpha"] is None or fshape[2] == 3, "a monochrome store records a colour cast alpha"),
    ]
    for ok, what in checks:
        if not ok:
            raise bad(what)

    def array(name: str, shape: tuple[int, ...], dtype: str, chunks: tuple[int, ...] | None = None):
        try:
            a = group[name]
            a_shape, a_dtype, a_chunks = tuple(a.shape), np.dtype(a.dtype), tuple(a.chunks)
        except KeyError:
            raise bad(f"the array {name} is missing") from None
        except Exception as e:  # noqa: BLE001 - garbage metadata raises many kinds
            raise bad(f"the array {name} cannot be opened (damaged metadata: {type(e).__name__})") from None
        if len(a_shape) != len(shape):
            raise bad(f"the array {name} has {len(a_shape)} dimensions, not {len(shape)}")
        if a_shape != shape:
            raise bad(f"the array {name} has shape {a_shape}, not {shape} ({n} windows recorded)")
        if a_dtype != np.dtype(dtype):
            raise bad(f"the array {name} holds {a_dtype}, not {dtype}")
        if chunks is not None and a_chunks != chunks:
            raise bad(f"the array {name} is chunked {a_chunks}, not {chunks} (chunks of {chunk} windows recorded)")
        return a

    array("frames", (n, *fshape), "float32", (chunk, *fshape))
    ticks = array("centre_tick", (n,), "int64")
    wins = array("window", (n, 2), "int64")
    try:
        centres, spans = np.asarray(ticks[:]), np.asarray(wins[:])
    except Exception as e:  # noqa: BLE001
        raise bad(f"the window ticks cannot be read ({type(e).__name__})") from None
    step = int(attrs["step"])
    if not ((spans[:, 0] <= centres) & (centres < spans[:, 1])).all() or (n > 1 and not (np.diff(centres) == step).all()):
        raise bad(f"its window ticks disagree with the recorded step ({step} ticks) or windows")
    n_chunks = -(-n // chunk)
    lost, unreadable = False, []
    done = np.zeros(n_chunks, dtype=bool)
    try:
        array("done", (n_chunks,), "uint8", (1,))
    except InputFileError:
        lost = True
    try:
        array("seconds", (n_chunks,), "float64", (1,))
        seconds_lost = False
    except InputFileError:
        seconds_lost = True  # timings only: export does not need them, --resume rewrites the array
    if not lost:
        marks = group["done"]
        for i in range(n_chunks):
            try:
                v = int(np.asarray(marks[i]))
            except Exception:  # noqa: BLE001 - a damaged marker file
                v = -1
            if v == 1:
                done[i] = True
            elif v != 0:
                unreadable.append(i)
    check = StoreCheck(p, group, attrs, done, unreadable, lost)
    check.seconds_lost = seconds_lost
    return check


def repair_markers(check: StoreCheck, redo: list[int]) -> None:
    """Make ``--resume`` recompute ``redo`` (and every chunk with an unreadable marker): rewrite the
    ``done``/``seconds`` arrays when they are lost, else clear those markers."""
    import zarr

    import shutil

    n = check.n_chunks
    lost = [name for name, gone in (("done", check.markers_lost), ("seconds", check.seconds_lost)) if gone]
    for name in lost:
        shutil.rmtree(check.path / name, ignore_errors=True)  # garbage metadata: zarr cannot delete it itself
    g = zarr.open_group(str(check.path), mode="r+")
    if check.seconds_lost:
        g.create_array("seconds", shape=(n,), chunks=(1,), dtype="float64", fill_value=np.nan)
    if check.markers_lost:
        g.create_array("done", shape=(n,), chunks=(1,), dtype="uint8", fill_value=0)[:] = check.done.astype(np.uint8)
        return
    for i in sorted(set(redo) | set(check.unreadable)):
        g["done"][i] = 0
        check.done[i] = False
