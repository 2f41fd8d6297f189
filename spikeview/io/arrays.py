"""Spike arrays in ``.npy`` / ``.npz`` files: shape ``(T, H, W)`` or ``(H, W, T)``, uint8 or bool, values 0/1.

``.npy`` files are memory-mapped (``mmap_mode="r"``); ``.npz`` members are loaded into memory (zip
members cannot be mapped). Values are checked as they are read: anything other than 0/1 raises
:class:`~spikeview.errors.InputFileError` (nothing is silently thresholded).

**Layout rule** (which axis is time), in order:

1. ``layout="thw"`` or ``"hwt"`` when given;
2. else, with ``width``/``height`` given, the layout whose frame axes match them (``(T, H, W)`` is
   preferred if both match);
3. else, if the last two axes are a known sensor size (250×400 or 1000×1000) → ``(T, H, W)``;
   if the first two are → ``(H, W, T)``;
4. else ``(T, H, W)``, the toolkits' convention.

``info.warnings`` says which layout was used only when the choice is open to doubt: (H, W, T) from a
known sensor size, or (T, H, W) by the default rule when the first axis is not the longest (a real
capture has more ticks than rows or columns); a first axis longer than both others, or a known sensor
size in the last two axes, reads as (T, H, W) without a note.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError, InputFileError, ParameterError
from spikeview.io._base import check_dims, check_tick_rate
from spikeview.io.source import DEFAULT_TICK_RATE, SpikeSource, StreamInfo

LAYOUTS = ("thw", "hwt")
#: known sensor frame sizes as (height, width)
KNOWN_FRAME_SHAPES = ((250, 400), (1000, 1000))
#: member names tried, in order, when an .npz holds several arrays
NPZ_KEYS = ("spikes", "spike", "spk", "data", "arr_0")
#: elements checked for 0/1 values when the file is opened (the rest is checked as it is read)
_OPEN_CHECK_ELEMENTS = 1 << 24


def _load_array(path: Path, key: str | None) -> tuple[np.ndarray, str | None]:
    """The spike array of an .npy/.npz file, with errors that name the file."""
    if not path.exists():
        raise InputFileError(f"{path}: file not found; check the path.")
    if path.is_dir():
        raise InputFileError(f"{path}: is a folder, not a .npy/.npz file; point to the file inside it.")
    if path.stat().st_size == 0:
        raise InputFileError(f"{path}: the file is empty (0 bytes); check that it finished writing.")
    with open(path, "rb") as fh:
        magic = fh.read(4)
    # numpy's own test (a zip local-file or end-of-archive header first), not zipfile.is_zipfile's
    is_zip = magic in (b"PK\x03\x04", b"PK\x05\x06")
    try:
        if not is_zip:
            arr = np.load(path, mmap_mode="r", allow_pickle=False)
            if not isinstance(arr, np.ndarray):
                raise ValueError("not an array")
            return arr, None
        # our own file handle: numpy leaks the one it opens when the zip turns out to be damaged
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as npz:
            names = list(npz.files)
            if key is None:
                if len(names) == 1:
                    key = names[0]
                else:
                    key = next((k for k in NPZ_KEYS if k in names), None)
                    if key is None and {"frames", "ticks"} <= set(names):  # spikeview simulate's OUT.gt.npz
                        raise InputFileError(
                            f"{path}: holds ground-truth frames (arrays {', '.join(names)}), not spikes; open the "
                            f"capture it belongs to (the .dat beside it, e.g. {path.name.removesuffix('.gt.npz')}.dat).")
                    if key is None:
                        raise InputFileError(
                            f"{path}: holds arrays {', '.join(names) or '(none)'}, none of them named "
                            f"{'/'.join(NPZ_KEYS)}; save the spike array under one of those names "
                            f"(numpy.savez(file, spikes=a)), or in Python pass key=... to open_source.")
            elif key not in names:
                raise InputFileError(f"{path}: has no array named {key!r}; it holds {', '.join(names) or 'none'}.")
            return np.asarray(npz[key]), key
    except InputFileError:
        raise
    except MemoryError:
        raise InputFileError(f"{path}: the array is too large to load into memory; save it as an uncompressed .npy "
                             f"instead (spikeview memory-maps those).") from None
    except Exception as e:  # numpy/zipfile raise many types for damaged files
        kind = ".npz" if is_zip else ".npy"
        import zipfile

        text = str(e).lower()
        if isinstance(e, (zipfile.BadZipFile, EOFError)) or any(w in text for w in ("eof", "truncat", "greater than file size",
                                                                                  "cannot reshape array of size")):
            raise InputFileError(f"{path}: the {kind} file looks truncated or damaged ({type(e).__name__}: {e}); copy "
                                 "it again from where it was recorded or saved.") from None
        raise InputFileError(f"{path}: not a readable {kind} spike array ({type(e).__name__}: {e}); "
                             f"save the spikes with numpy.save as a (T, H, W) uint8 array.") from None


def decide_layout(shape: tuple[int, ...], *, layout: str | None = None, width: int | None = None,
                  height: int | None = None) -> tuple[str, str | None]:
    """Which axis of a 3-D spike array is time (see the module docstring for the rule).

    Returns:
        ``(layout, note)``: ``"thw"`` or ``"hwt"``, and a sentence for ``info.warnings`` when the
        rule rather than an explicit setting decided (else ``None``).

    Raises:
        ParameterError: unknown ``layout``.
        GeometryError: ``width``/``height`` fit neither layout.
    """
    if layout is not None:
        layout = str(layout).lower()
        if layout not in LAYOUTS:
            raise ParameterError(f"layout {layout!r} is unknown: use 'thw' for (T, H, W) or 'hwt' for (H, W, T).")
    frame = {"thw": (shape[1], shape[2]), "hwt": (shape[0], shape[1])}

    def fits(lay: str) -> bool:
        h, w = frame[lay]
        return (height is None or h == height) and (width is None or w == width)

    if layout is not None:
        if not fits(layout):
            h, w = frame[layout]
            raise GeometryError(f"an array of shape {shape} read as {layout} has {w}x{h} frames, not "
                                f"{width or w}x{height or h}; check --layout, --width and --height.",
                                [(frame[lay][1], frame[lay][0]) for lay in LAYOUTS if lay != layout])
        return layout, None
    if width is not None or height is not None:
        matches = [lay for lay in LAYOUTS if fits(lay)]
        if not matches:
            raise GeometryError(f"an array of shape {shape} has no axes of size {width or '?'}x{height or '?'} "
                                f"(width x height); check --width and --height.",
                                [(frame[lay][1], frame[lay][0]) for lay in LAYOUTS])
        if len(matches) == 1:
            return matches[0], None
        return "thw", (f"array of shape {shape} fits {width or '?'}x{height or '?'} frames either way; read it as "
                       f"(T, H, W) — pass --layout hwt (layout='hwt' in Python) if time is the last axis.")
    if frame["thw"] in KNOWN_FRAME_SHAPES:
        return "thw", None  # the last two axes are a known sensor size: nothing to doubt
    if frame["hwt"] in KNOWN_FRAME_SHAPES:
        return "hwt", f"array of shape {shape} read as (H, W, T) (its first two axes are a known sensor size)."
    if shape[0] > max(shape[1], shape[2]):
        return "thw", None  # the first axis is the longest, as time is in any real capture
    longest = " (its last axis is the longest, as time usually is)" if shape[2] > max(shape[0], shape[1]) else ""
    return "thw", (f"array of shape {shape} read as (T, H, W), the usual order, though that is ambiguous here{longest}; "
                   f"pass --layout hwt (layout='hwt' in Python) if time is the last axis.")


class NpySource(SpikeSource):
    """A spike array from an ``.npy`` (memory-mapped) or ``.npz`` (loaded) file.

    Args:
        path: the file.
        layout: ``"thw"`` / ``"hwt"``, or ``None`` to decide by the module's rule.
        width, height: expected frame size (also used to decide the layout).
        cfa: CFA after the flips, or ``None``.
        tick_rate: readouts per second (Hz).
        flip_vertical, flip_horizontal: flips applied to the frames as stored (default none).
        key: the ``.npz`` member holding the spikes (default: the only one, or the first of
            :data:`NPZ_KEYS` present).

    Raises:
        InputFileError: unreadable file, wrong number of dimensions, dtype other than uint8/bool,
            values other than 0/1.
        GeometryError: ``width``/``height``/``layout`` do not fit the array.
    """

    def __init__(self, path: str | os.PathLike[str], *, layout: str | None = None, width: int | None = None,
                 height: int | None = None, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
                 flip_vertical: bool = False, flip_horizontal: bool = False, key: str | None = None):
        path = Path(path)
        tick_rate = check_tick_rate(tick_rate)
        cfa = parse_cfa(cfa)
        if width is not None or height is not None:
            check_dims(width if width is not None else 1, height if height is not None else 1)
        arr, key = _load_array(path, key)
        if arr.ndim != 3:
            raise InputFileError(f"{path}: holds an array of shape {arr.shape}; spike arrays must be 3-D, "
                                 f"(T, H, W) or (H, W, T).")
        if arr.dtype not in (np.uint8, np.bool_):
            raise InputFileError(f"{path}: holds dtype {arr.dtype}; spike arrays must be uint8 or bool with values 0/1 "
                                 f"(convert with (a != 0).astype(numpy.uint8) if that is what you mean).")
        try:
            lay, note = decide_layout(arr.shape, layout=layout, width=width, height=height)
        except GeometryError as e:
            raise GeometryError(f"{path}: {e}", e.candidates) from None
        self._arr = arr
        self._layout = lay
        t, h, w = (arr.shape if lay == "thw" else (arr.shape[2], arr.shape[0], arr.shape[1]))
        if min(t, h, w) == 0:
            raise InputFileError(f"{path}: the spike array of shape {arr.shape} is empty; nothing to read.")
        self.info = StreamInfo(width=int(w), height=int(h), n_frames=int(t), tick_rate=tick_rate, cfa=cfa,
                               format="npz", flip_vertical=bool(flip_vertical), flip_horizontal=bool(flip_horizontal),
                               path=path, warnings=[note] if note else [],
                               extra={"npz_key": key} if key else {})
        # check a first stretch now, so that a clearly wrong file fails on open
        n_check = max(1, min(t, _OPEN_CHECK_ELEMENTS // max(1, h * w)))
        self._frames(0, n_check)

    def _frames(self, a: int, b: int) -> np.ndarray:
        """Frames ``[a, b)`` as stored (no flips), uint8, values checked."""
        if self._arr is None:
            raise ParameterError(f"{self.info.path.name if self.info.path else 'the stream'} has been closed; open it again.")
        try:
            if self._layout == "thw":
                block = np.array(self._arr[a:b], copy=True)
            else:
                block = np.ascontiguousarray(np.moveaxis(self._arr[:, :, a:b], 2, 0))
        except (OSError, ValueError) as e:
            raise InputFileError(f"{self.info.path}: reading ticks [{a}, {b}) failed ({e}); the file may be truncated.") from None
        if block.dtype == np.bool_:
            block = block.view(np.uint8)  # a damaged bool file can hold bytes other than 0/1: check them too
        if block.size and block.max() > 1:
            bad = int(np.argmax(block.reshape(block.shape[0], -1).max(axis=1) > 1)) + a
            raise InputFileError(f"{self.info.path}: tick {bad} holds values other than 0 and 1; a spike array must be "
                                 f"binary (threshold it before saving).")
        return block

    def _read(self, a: int, b: int) -> np.ndarray:
        frames = self._frames(a, b)
        if self.info.flip_vertical:
            frames = frames[:, ::-1]
        if self.info.flip_horizontal:
            frames = frames[:, :, ::-1]
        return np.ascontiguousarray(frames)

    def close(self) -> None:
        """Release the array (and its memory map). Safe to call twice."""
        self._arr = None  # type: ignore[assignment]


def write_array(path: str | os.PathLike[str], spikes: np.ndarray, *, cfa: str | None = None,
                tick_rate: float = DEFAULT_TICK_RATE, sidecar: bool = True,
                extra_tables: dict[str, dict[str, Any]] | None = None) -> Path:
    """Save ``(T, H, W)`` 0/1 spikes as ``.npy`` (or compressed ``.npz`` member ``spikes``) plus sidecar.

    The format follows the suffix of ``path`` (``.npz`` → compressed zip, anything else → ``.npy``).
    """
    from spikeview.io.plain import check_spikes
    from spikeview.io.sidecar import write_sidecar

    from spikeview._files import write_atomic

    arr = check_spikes(spikes).astype(np.uint8, copy=False)
    path = Path(path)

    def save(f) -> None:
        if path.suffix.lower() == ".npz":
            np.savez_compressed(f, spikes=arr)
        else:
            np.save(f, arr)

    write_atomic(path, save, "the spike array")
    if sidecar:
        t, h, w = arr.shape
        write_sidecar(path, StreamInfo(width=w, height=h, n_frames=t, tick_rate=check_tick_rate(tick_rate), cfa=cfa,
                                       format="npz", path=path), extra_tables)
    return path
