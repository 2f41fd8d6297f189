"""Shared machinery of the packed-bit file readers (plain ``.dat``, raw 400×250, raw 1000×1000).

A packed frame is ``n_rows`` storage rows of ``row_bytes`` bytes (LSB-first bits). The decoded
frame keeps some storage columns (``segments``: ``(src_col, dst_col, length)`` rows) and then
applies the orientation flips. Frames start at byte offsets given by the subclass (a fixed stride
for plain files, an index built by synchronisation for raw 1000×1000 streams).
"""

from __future__ import annotations

import mmap
import os
from abc import abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np

from spikeview.errors import InputFileError, ParameterError
from spikeview.io.source import DEFAULT_TICK_RATE, SpikeSource, StreamInfo, check_tick_rate  # noqa: F401 (re-exported)


def check_dims(width: object, height: object, where: str = "") -> tuple[int, int]:
    """Validate a (width, height) pair given by a person; returns them as ints."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < 1:
            raise ParameterError(f"{where}{name} must be a positive whole number of pixels, got {v!r}; "
                                 f"pass the sensor size, e.g. width 400 and height 250.")
    return int(width), int(height)  # type: ignore[arg-type]


def open_bytes(path: str | os.PathLike[str], what: str) -> tuple[Path, np.ndarray]:
    """Memory-map a spike file read-only as a 1-D uint8 array, with errors for people.

    ``what`` names the expected format in messages (e.g. ``"plain .dat"``).
    """
    from spikeview._files import existing_file

    path = existing_file(path, f"{what} file", "point to the spike file inside it")
    try:
        size = path.stat().st_size
        if size == 0:
            raise InputFileError(f"{path}: the file is empty (0 bytes); check that the capture finished writing.")
        mm = np.memmap(path, dtype=np.uint8, mode="r")
    except PermissionError:
        raise InputFileError(f"{path}: permission denied; check that you may read the file.") from None
    except OSError as e:
        raise InputFileError(f"{path}: cannot read the file ({e.strerror or e}); check the path and the disk.") from None
    return path, mm.view(np.ndarray)


#: bytes read through a mapping after which its pages are handed back to the OS (see ``_touch``)
RELEASE_AFTER_BYTES = 256 * 1024 * 1024


def _mmap_of(arr: np.ndarray | None) -> mmap.mmap | None:
    """The ``mmap.mmap`` under a memory-mapped array (following ``.base``), or ``None``."""
    obj = arr
    for _ in range(8):
        if obj is None:
            return None
        if isinstance(obj, mmap.mmap):
            return obj
        obj = getattr(obj, "_mmap", None) or getattr(obj, "base", None)
    return None


class PackedFileSource(SpikeSource):
    """Base of the packed-bit file readers; subclasses set the layout and implement :meth:`_frame_offsets`.

    Attributes set by subclasses before use: ``_buf`` (1-D uint8), ``_row_bytes``, ``_n_rows``,
    ``_segments`` (``(n, 3)`` int64), and ``info``. When a row is not a whole number of bytes
    (plain files whose width is not a multiple of 8) the subclass sets ``_flat = True`` and the
    whole frame is one storage "row" of ``H·W`` pixels.
    """

    _buf: np.ndarray | None
    _row_bytes: int
    _n_rows: int
    _segments: np.ndarray
    _flat: bool = False
    _touched: int = 0

    def _touch(self, n_bytes: int) -> None:
        """Count bytes read through the mapping; past :data:`RELEASE_AFTER_BYTES`, drop the mapped pages.

        Pages of a read-only file mapping stay in the process's resident set once touched, so
        playing or randomly accessing a multi-GB file would make the RSS grow towards the file
        size. ``MADV_DONTNEED`` unmaps them from the process (they stay in the OS page cache, so
        the next access is a cheap minor fault): resident memory stays bounded whatever the file
        length. No-op where ``madvise`` is unavailable.
        """
        self._touched += int(n_bytes)
        if self._touched < RELEASE_AFTER_BYTES:
            return
        self._touched = 0
        mm = _mmap_of(self._buf)
        if mm is not None and hasattr(mm, "madvise") and hasattr(mmap, "MADV_DONTNEED"):
            try:
                mm.madvise(mmap.MADV_DONTNEED)
            except (OSError, ValueError):  # closed or unsupported: nothing to release
                pass

    @property
    def frame_bytes(self) -> int:
        """Bytes of one stored frame."""
        return self._row_bytes * self._n_rows

    @abstractmethod
    def _frame_offsets(self, a: int, b: int) -> np.ndarray:
        """Byte offsets (int64, shape ``(b - a,)``) of frames ``a..b-1`` in ``_buf``."""

    def _buffer(self) -> np.ndarray:
        if self._buf is None:
            name = self.info.path.name if self.info.path else "the stream"
            raise ParameterError(f"{name} has been closed; open it again to read from it.")
        return self._buf

    # ------------------------------------------------------------------------------- reading
    def _read(self, a: int, b: int) -> np.ndarray:
        buf = self._buffer()
        offs = self._frame_offsets(a, b)
        fb = self.frame_bytes
        n = b - a
        if n > 1 and np.all(np.diff(offs) == fb):
            packed = buf[offs[0]:offs[0] + n * fb].reshape(n, fb)
        else:
            packed = np.empty((n, fb), dtype=np.uint8)
            for i, o in enumerate(offs):
                packed[i] = buf[o:o + fb]
        bits = np.unpackbits(packed, axis=1, bitorder="little")
        self._touch(n * fb)
        if self._flat:
            frames = bits.reshape(n, self.height, self.width)
        else:
            rows = bits.reshape(n, self._n_rows, self._row_bytes * 8)
            segs = self._segments
            if len(segs) == 1 and segs[0, 0] == 0 and segs[0, 2] == rows.shape[2]:
                frames = rows
            else:
                frames = np.empty((n, self.height, self.width), dtype=np.uint8)
                for src, dst, ln in segs:
                    frames[:, :, dst:dst + ln] = rows[:, :, src:src + ln]
        if self.info.flip_vertical:
            frames = frames[:, ::-1]
        if self.info.flip_horizontal:
            frames = frames[:, :, ::-1]
        return np.ascontiguousarray(frames)

    # ------------------------------------------------------------------------------ counting
    def count(self, a: int, b: int) -> np.ndarray:
        """Spike count per pixel over ticks ``[a, b)``, counted on the packed bytes.

        Returns:
            ``(H, W)`` counts with flips applied: uint16 when ``b - a <= 65535``, else uint32.
        """
        a, b = self.check_range(a, b)
        if a == b:
            return np.zeros((self.height, self.width), dtype=np.uint16)
        return self._count_offsets(self._frame_offsets(a, b)[None, :])[0]

    def count_windows(self, a: int, b: int, window: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """Counts of consecutive non-overlapping ``window``-tick windows in ``[a, b)`` (fast path).

        Only windows that lie entirely inside ``[a, b)`` are counted. Windows are processed in
        parallel; pass ``out`` (a reused C-contiguous ``(n_windows, H, W)`` uint16 array) to avoid
        allocating fresh memory on every call.

        Returns:
            ``(n_windows, H, W)`` uint16 counts (uint32 for windows over 65,535 ticks), flips applied.
        """
        a, b = self.check_range(a, b)
        window = int(window)
        if window < 1:
            raise ParameterError(f"window must be at least 1 tick, got {window}; pass a positive window length.")
        n = (b - a) // window
        offs = self._frame_offsets(a, a + n * window).reshape(n, window)
        if out is not None:
            dtype = np.uint16 if window <= 65535 else np.uint32
            if out.shape != (n, self.height, self.width) or out.dtype != dtype or not out.flags.c_contiguous:
                raise ParameterError(f"out must be a C-contiguous {np.dtype(dtype).name} array of shape "
                                     f"{(n, self.height, self.width)}, got {out.dtype} {out.shape}; allocate it to match.")
        return self._count_offsets(offs, out)

    def _count_offsets(self, offsets: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        from spikeview.io._packed import count_frames  # numba: imported on first use only

        buf = self._buffer()
        self._touch(offsets.size * self.frame_bytes)
        if self._flat:
            n_w = offsets.shape[0]
            flat = count_frames(buf, offsets, row_bytes=self._row_bytes, n_rows=1,
                                segments=np.array([[0, 0, self.height * self.width]]), width=self.height * self.width,
                                flip_vertical=False, flip_horizontal=False)
            res = flat.reshape(n_w, self.height, self.width)
            if self.info.flip_vertical:
                res = res[:, ::-1]
            if self.info.flip_horizontal:
                res = res[:, :, ::-1]
            if out is None:
                return np.ascontiguousarray(res)
            out[...] = res
            return out
        return count_frames(buf, offsets, row_bytes=self._row_bytes, n_rows=self._n_rows, segments=self._segments,
                            width=self.width, flip_vertical=self.info.flip_vertical,
                            flip_horizontal=self.info.flip_horizontal, out=out)

    def close(self) -> None:
        """Drop the file mapping (the OS unmaps it once no array still refers to it). Safe to call twice."""
        self._buf = None


def raw_writer(fmt: str, encode: Callable[..., bytes], width: int, height: int, frame_bytes: int, *,
               flip_vertical: bool, doc: str) -> Callable[..., Path]:
    """The ``write_<fmt>(path, frames, *, flip_vertical, flip_horizontal, cfa, tick_rate, sidecar)`` function of a
    raw camera format: ``encode`` the frames, write them atomically, and the sidecar unless ``sidecar`` is false."""

    def write(path: str | os.PathLike[str], frames: np.ndarray, *, flip_vertical: bool = flip_vertical,
              flip_horizontal: bool = False, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
              sidecar: bool = True) -> Path:
        from spikeview._files import write_atomic
        from spikeview.io.sidecar import write_sidecar

        data = encode(frames, flip_vertical=flip_vertical, flip_horizontal=flip_horizontal)
        path = Path(path)
        write_atomic(path, data)
        if sidecar:
            info = StreamInfo(width=width, height=height, n_frames=len(data) // frame_bytes,
                              tick_rate=check_tick_rate(tick_rate), cfa=cfa, format=fmt,
                              flip_vertical=flip_vertical, flip_horizontal=flip_horizontal, path=path)
            write_sidecar(path, info)
        return path

    write.__name__ = write.__qualname__ = f"write_{fmt}"
    write.__doc__ = doc
    return write
