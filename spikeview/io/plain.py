"""Plain packed ``.dat`` spike files: reader, writers.

Format (the ecosystem's common format; see DOMAIN.md): no header. One frame is ``H·W/8`` bytes;
pixel ``p = row·W + col`` of the *stored* frame is bit ``p % 8`` (least significant bit first) of
byte ``p // 8``. Rows are stored upside down, so readers flip decoded frames vertically by default
and writers flip before packing. Frame count = file size // frame size; a trailing partial frame is
reported in ``info.warnings``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview._files import os_error_sentence, preallocate, write_all
from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError, OutputFileError, ParameterError
from spikeview.io._base import PackedFileSource, check_dims, check_tick_rate, open_bytes
from spikeview.io.source import DEFAULT_TICK_RATE, StreamInfo

#: frames packed per write call by :func:`write_plain` (bounds the temporary memory)
_WRITE_CHUNK = 256


class PlainDatSource(PackedFileSource):
    """A plain packed ``.dat`` file, memory-mapped (never loaded whole).

    Args:
        path: the ``.dat`` file.
        width, height: frame size in pixels (the file does not store it); ``width·height`` must
            be a multiple of 8.
        flip_vertical: rows are stored upside down (default ``True``, like every toolkit): decoded
            frames are flipped so that row 0 is the top of the scene.
        flip_horizontal: columns are stored mirrored (default ``False``).
        cfa: CFA of the decoded frame *after* the flips (``"RGGB"`` …) or ``None`` for monochrome.
        tick_rate: readouts per second (Hz).

    ``read(a, b)`` returns ``(b - a, H, W)`` uint8 0/1; ``count(a, b)`` counts on the packed bytes
    (numba, several threads) without unpacking.

    Raises:
        InputFileError: missing file, folder, empty file (message names the file).
        GeometryError: ``width·height`` not a multiple of 8, or the file is smaller than one frame.
        ParameterError: non-positive width/height/tick rate, unknown CFA.
    """

    def __init__(self, path: str | os.PathLike[str], width: int, height: int, *, flip_vertical: bool = True,
                 flip_horizontal: bool = False, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE):
        width, height = check_dims(width, height)
        tick_rate = check_tick_rate(tick_rate)
        cfa = parse_cfa(cfa)
        path = Path(path)
        if (width * height) % 8:
            raise GeometryError(
                f"{path}: a {width}x{height} frame has {width * height} pixels, not a multiple of 8, so it cannot be a "
                f"plain packed frame; check --width and --height.")
        path, buf = open_bytes(path, "plain .dat")
        fb = width * height // 8
        n, rem = divmod(buf.size, fb)
        if n == 0:
            raise GeometryError(
                f"{path}: the file ({buf.size} bytes) is smaller than one {width}x{height} frame ({fb} bytes); "
                f"check --width and --height.")
        self._buf = buf
        if width % 8 == 0:
            self._row_bytes, self._n_rows, self._flat = width // 8, height, False
        else:  # rows are not byte-aligned: the kernel sees the frame as one long row
            self._row_bytes, self._n_rows, self._flat = fb, 1, True
        self._segments = np.array([[0, 0, width]], dtype=np.int64)
        warnings = []
        if rem:
            warnings.append(
                f"the last {rem} bytes do not fill a whole {width}x{height} frame ({fb} bytes) and are "
                f"not read; if the file should have no partial frame, check --width and --height.")
        self.info = StreamInfo(width=width, height=height, n_frames=n, tick_rate=tick_rate, cfa=cfa, format="plain",
                               flip_vertical=bool(flip_vertical), flip_horizontal=bool(flip_horizontal), path=path,
                               warnings=warnings)

    def _frame_offsets(self, a: int, b: int) -> np.ndarray:
        return np.arange(a, b, dtype=np.int64) * self.frame_bytes


# ------------------------------------------------------------------------------------- writing
def check_spikes(spikes: np.ndarray, name: str = "spikes") -> np.ndarray:
    """Validate a ``(T, H, W)`` (or single ``(H, W)``) spike block of 0/1 values; returns it 3-D.

    Accepts bool or integer dtypes; any value other than 0 or 1 raises :class:`ParameterError`
    (nothing is silently thresholded).
    """
    arr = np.asarray(spikes)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3:
        raise ParameterError(f"{name} must have shape (T, H, W), got shape {arr.shape}; stack the frames first.")
    if arr.dtype != np.bool_:
        if not np.issubdtype(arr.dtype, np.integer):
            raise ParameterError(f"{name} must hold 0/1 integers or bools, got dtype {arr.dtype}; threshold it first.")
        if arr.size and (arr.min() < 0 or arr.max() > 1):
            raise ParameterError(f"{name} holds values other than 0 and 1 (range {arr.min()}..{arr.max()}); "
                                 f"spike frames are binary: threshold them first.")
    return arr


def check_frames(frames: np.ndarray, height: int, width: int, what: str) -> np.ndarray:
    """``frames`` as a ``(T, height, width)`` 0/1 uint8 array for one of the raw encoders; :class:`ParameterError` otherwise."""
    arr = check_spikes(frames, "frames")
    if arr.shape[1:] != (height, width):
        raise ParameterError(f"{what} frames must be {width}x{height}, got {arr.shape[2]}x{arr.shape[1]}.")
    return arr


def pack_frames(spikes: np.ndarray, *, flip_vertical: bool = True, flip_horizontal: bool = False) -> np.ndarray:
    """Pack ``(T, H, W)`` 0/1 frames (display orientation) into plain-format bytes.

    The flips are undone first (so that a reader with the same flips gets ``spikes`` back), then
    pixels are packed 8 per byte, least significant bit first.

    Returns:
        ``(T, H·W/8)`` uint8.
    """
    arr = check_spikes(spikes)
    t, h, w = arr.shape
    if (h * w) % 8:
        raise ParameterError(f"a {w}x{h} frame has {h * w} pixels, not a multiple of 8; plain files pack 8 pixels per byte.")
    if flip_vertical:
        arr = arr[:, ::-1]
    if flip_horizontal:
        arr = arr[:, :, ::-1]
    return np.packbits(arr.reshape(t, h * w), axis=1, bitorder="little")


class PlainDatWriter:
    """Streams frames into a plain packed ``.dat`` file and writes its sidecar.

    Frames are appended with :meth:`write` (0/1 arrays in display orientation) or
    :meth:`write_packed` (bytes already in file order, e.g. from a camera). :meth:`close` flushes,
    fsyncs and (re)writes the sidecar with the current :attr:`tables`; it also runs when the
    writer is used as a context manager, even after an error, so a recording stays readable.

    Args:
        path: the ``.dat`` file to create (or to extend with ``append=True``).
        width, height: frame size; ``width·height`` must be a multiple of 8.
        flip_vertical, flip_horizontal: the flips a reader must apply (the writer undoes them
            before packing); plain files are stored upside down by default.
        cfa: CFA of the frames as given (display orientation), or ``None``.
        tick_rate: readouts per second (Hz).
        sidecar: write ``<path>.toml`` (on open and on close).
        extra_tables: initial free-form sidecar tables (``{"simulation": {...}}``); see :attr:`tables`.
        append: add to an existing file instead of replacing it.
        reserve_frames: reserve the disk space of this many frames up front
            (``posix_fallocate``): a disk too small is reported here, before any frame, and
            writes into the reservation cannot run out of space. :meth:`close` trims the file to
            the frames actually written.

    A failed write (a full disk) raises :class:`~spikeview.errors.OutputFileError` and trims
    the file back to the whole frames written before it, so the file stays readable.
    """

    def __init__(self, path: str | os.PathLike[str], width: int, height: int, *, flip_vertical: bool = True,
                 flip_horizontal: bool = False, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
                 sidecar: bool = True, extra_tables: dict[str, dict[str, Any]] | None = None, append: bool = False,
                 reserve_frames: int = 0):
        self.width, self.height = check_dims(width, height)
        if (self.width * self.height) % 8:
            raise ParameterError(f"a {self.width}x{self.height} frame has {self.width * self.height} pixels, not a "
                                 f"multiple of 8; plain files pack 8 pixels per byte.")
        self.path = Path(path)
        self.flip_vertical = bool(flip_vertical)
        self.flip_horizontal = bool(flip_horizontal)
        self.cfa = parse_cfa(cfa)
        self.tick_rate = check_tick_rate(tick_rate)
        self.frame_bytes = self.width * self.height // 8
        #: free-form sidecar tables written on close (the recorder updates its drop counters here)
        self.tables: dict[str, dict[str, Any]] = {k: dict(v) for k, v in (extra_tables or {}).items()}
        self._sidecar = bool(sidecar)
        self._n_bytes = 0
        if append and self.path.exists():
            size = self.path.stat().st_size
            if size % self.frame_bytes:
                raise OutputFileError(f"{self.path}: cannot append, its {size} bytes are not whole "
                                      f"{self.width}x{self.height} frames; write to a new file.")
            self._n_bytes = size
        try:
            # unbuffered: every byte counted in _n_bytes is on its way to the disk, so a failed
            # write can be trimmed back to whole frames
            self._f = open(self.path, "ab" if append else "wb", buffering=0)
        except FileNotFoundError:
            raise OutputFileError(f"{self.path}: the folder does not exist; create it first.") from None
        except IsADirectoryError:
            raise OutputFileError(f"{self.path}: is a folder; give a file name such as capture.dat.") from None
        except OSError as e:
            raise OutputFileError(f"{self.path}: cannot write: {os_error_sentence(e)}.") from None
        self._closed = False
        self._reserved = False
        if reserve_frames > 0 and not append:
            try:
                preallocate(self._f.fileno(), int(reserve_frames) * self.frame_bytes, self.path)
            except OutputFileError:
                self.discard()
                raise
            self._reserved = True
        if self._sidecar:
            try:
                self._write_sidecar()
            except OutputFileError:
                self.discard()
                raise

    # --------------------------------------------------------------------------------- state
    @property
    def n_frames(self) -> int:
        """Frames in the file so far."""
        return self._n_bytes // self.frame_bytes

    @property
    def info(self) -> StreamInfo:
        """The :class:`StreamInfo` a reader of the file will see (as far as written)."""
        return StreamInfo(width=self.width, height=self.height, n_frames=self.n_frames, tick_rate=self.tick_rate,
                          cfa=self.cfa, format="plain", flip_vertical=self.flip_vertical,
                          flip_horizontal=self.flip_horizontal, path=self.path)

    def set_table(self, name: str, values: dict[str, Any]) -> None:
        """Replace sidecar table ``[name]`` (written on the next :meth:`close` or :meth:`write_sidecar`)."""
        self.tables[name] = dict(values)

    # -------------------------------------------------------------------------------- writing
    def write(self, frames: np.ndarray) -> None:
        """Append ``(T, H, W)`` or ``(H, W)`` 0/1 frames given in display orientation."""
        arr = check_spikes(frames, "frames")
        if arr.shape[1:] != (self.height, self.width):
            raise ParameterError(f"frames have size {arr.shape[2]}x{arr.shape[1]}, but {self.path.name} holds "
                                 f"{self.width}x{self.height} frames; resize or write to another file.")
        for i in range(0, arr.shape[0], _WRITE_CHUNK):
            packed = pack_frames(arr[i:i + _WRITE_CHUNK], flip_vertical=self.flip_vertical,
                                 flip_horizontal=self.flip_horizontal)
            self._write_bytes(memoryview(np.ascontiguousarray(packed)).cast("B"))

    def write_packed(self, data: bytes | bytearray | memoryview | np.ndarray) -> None:
        """Append already-packed frames in file order (a whole number of frames)."""
        if isinstance(data, np.ndarray):
            if data.dtype != np.uint8:
                raise ParameterError(f"packed data must be uint8 bytes, got dtype {data.dtype}; pass the raw file bytes.")
            view = memoryview(np.ascontiguousarray(data).reshape(-1))
        else:
            view = memoryview(data).cast("B")
        if len(view) % self.frame_bytes:
            raise ParameterError(f"packed data of {len(view)} bytes is not a whole number of {self.width}x{self.height} "
                                 f"frames ({self.frame_bytes} bytes each); pass complete frames.")
        self._write_bytes(view)

    def _write_bytes(self, view: memoryview) -> None:
        if self._closed:
            raise ParameterError(f"{self.path.name}: the writer is closed; open a new PlainDatWriter to add frames.")
        try:
            write_all(self._f.fileno(), view)
        except OSError as e:
            self._trim()
            raise OutputFileError(f"{self.path}: writing frame {self.n_frames} failed: {os_error_sentence(e)}.") from None
        self._n_bytes += len(view)

    def _trim(self) -> None:
        """Cut the file back to the whole frames written (after a failed write, or a reservation)."""
        try:
            os.ftruncate(self._f.fileno(), self._n_bytes)
            self._f.seek(self._n_bytes)
        except (OSError, ValueError):  # nothing more can be done; readers report a partial frame
            pass

    def flush(self, fsync: bool = False) -> None:
        """Push buffered bytes to the OS (and to the disk with ``fsync=True``)."""
        if self._closed:
            return
        try:
            self._f.flush()
            if fsync:
                os.fsync(self._f.fileno())
        except OSError as e:
            raise OutputFileError(f"{self.path}: saving the file failed: {os_error_sentence(e)}.") from None

    def write_sidecar(self) -> Path | None:
        """(Re)write ``<path>.toml`` now with the current tables; returns its path (``None`` if disabled)."""
        return self._write_sidecar() if self._sidecar else None

    def _write_sidecar(self) -> Path:
        from spikeview.io.sidecar import write_sidecar

        return write_sidecar(self.path, self.info, self.tables)

    def close(self) -> None:
        """Flush, fsync, close the file and write the sidecar. Safe to call twice."""
        if self._closed:
            return
        try:
            if self._reserved:
                self._trim()
            self.flush(fsync=True)
        finally:
            self._closed = True
            self._f.close()
        if self._sidecar:
            self._write_sidecar()

    def discard(self) -> None:
        """Close without saving and delete the file and its sidecar (for a run that failed)."""
        if not self._closed:
            self._closed = True
            try:
                self._f.close()
            except OSError:
                pass
        from spikeview.io.sidecar import sidecar_path

        for p in (self.path, *([sidecar_path(self.path)] if self._sidecar else [])):
            try:
                p.unlink(missing_ok=True)
            except OSError:
                pass

    def __enter__(self) -> PlainDatWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_plain(path: str | os.PathLike[str], spikes: np.ndarray, *, flip_vertical: bool = True,
                flip_horizontal: bool = False, cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE,
                sidecar: bool = True, extra_tables: dict[str, dict[str, Any]] | None = None) -> Path:
    """Write ``(T, H, W)`` 0/1 spikes (display orientation) as a plain packed ``.dat`` file.

    The file appears complete or not at all (written under a temporary name, then renamed); the
    sidecar ``<path>.toml`` is written next to it unless ``sidecar=False``.

    Args:
        path: destination ``.dat`` file.
        spikes: ``(T, H, W)`` bool or 0/1 integer array, row 0 at the top; ``H·W`` multiple of 8.
        flip_vertical, flip_horizontal: flips a reader applies (undone here before packing).
        cfa: CFA of ``spikes`` as given, or ``None``.
        tick_rate: readouts per second (Hz).
        sidecar: also write the sidecar.
        extra_tables: free-form sidecar tables.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.
    """
    arr = check_spikes(spikes)
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    writer = PlainDatWriter(tmp, arr.shape[2], arr.shape[1], flip_vertical=flip_vertical,
                            flip_horizontal=flip_horizontal, cfa=cfa, tick_rate=tick_rate, sidecar=False)
    try:
        writer.write(arr)
        writer.close()
        os.replace(tmp, path)
    except BaseException:
        writer.discard()
        raise
    if sidecar:
        from spikeview.io.sidecar import write_sidecar

        write_sidecar(path, writer.info.replace(path=path), extra_tables)
    return path
