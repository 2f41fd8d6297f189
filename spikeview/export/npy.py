"""NumPy ``.npy`` stacks with a TOML sidecar.

Conventions:
    * One array of float32, shape ``(N, H, W, 3)`` for colour or ``(N, H, W)`` for mono, the
      linear values exactly as given (no levels, no clipping, no transfer curve).
    * Written with ordinary file writes (no memory map: writing to a memory map on a full disk
      kills the process with a bus error) into a hidden temporary file whose full size is
      reserved up front (``posix_fallocate``), so a disk too small for the array is reported
      before the first frame; a long sequence never has to be in memory; renamed into place on
      close.
    * Sidecar ``<file>.toml`` (``frames.npy`` → ``frames.npy.toml``), written atomically just
      before the array is renamed: the export record (source, method, tick rate, first window,
      step, ``[params]``, ``[export]``), ``n_frames``, ``shape``, ``dtype``, and one
      ``[[frames]]`` entry per frame with its index and, where known, window and centre tick.
    * On cancel (``close(allow_partial=True)``) the header is rewritten in place for the ``k``
      finished frames and the file truncated after them; they are kept with their
      sidecar; with none finished, or on an error, no file is left.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview._files import os_error_sentence
from spikeview.errors import InputFileError, OutputFileError
from spikeview.export.atomic import AtomicFile
from spikeview.export.base import Exporter, finishing


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The metadata sidecar of an exported ``.npy``: the same name plus ``.toml``."""
    path = Path(path)
    return path.with_name(path.name + ".toml")


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The sidecar record of an exported ``.npy`` (pass the ``.npy`` path)."""
    from spikeview.config import load_toml

    side = sidecar_path(path)
    if not side.exists():
        raise InputFileError(f"{path}: no metadata sidecar {side.name} next to it; it was not exported by spikeview.")
    return load_toml(side)


def _header(shape: tuple[int, ...]) -> bytes:
    """The ``.npy`` header of a C-order little-endian float32 array of ``shape``.

    NumPy pads the header so that the first axis can grow or shrink without changing its
    length, which lets a cancelled export rewrite it in place.
    """
    import io

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": np.lib.format.dtype_to_descr(np.dtype("<f4")), "fortran_order": False, "shape": shape})
    return buf.getvalue()


class NpyExporter(Exporter):
    """A float32 ``.npy`` stack plus ``<file>.toml`` (see module docstring)."""

    format = "npy"

    def output_files(self) -> list[Path]:
        return [self.path, sidecar_path(self.path)]

    @property
    def nbytes(self) -> int:
        """Size of the finished file in bytes (header plus every frame)."""
        return len(_header((self.n_frames, *self.frame_shape))) + self.n_frames * self._frame_bytes

    def _open(self) -> None:
        from spikeview._files import LARGE_WRITE_BYTES, check_free_space, human_bytes, preallocate

        self._frame_bytes = int(np.prod(self.frame_shape)) * 4
        self._head = _header((self.n_frames, *self.frame_shape))
        self._file = AtomicFile(self.path)
        self._frames: list[dict[str, Any]] = []
        check_free_space(self.path.parent, self.nbytes, f"{self.n_frames} frames of {self.path.name} "
                         f"({human_bytes(self.nbytes)})")
        if self.announce is not None and self.nbytes >= LARGE_WRITE_BYTES:
            self.announce(f"writing {self.path.name}: {self.n_frames} float32 frames, {human_bytes(self.nbytes)}")
        try:
            self._fd = os.open(self._file.tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as e:
            self._file.discard()
            raise OutputFileError(f"{self.path}: could not create the file: {os_error_sentence(e)}.") from None
        try:
            preallocate(self._fd, self.nbytes, self.path)
            self._pwrite(self._head, 0)
        except BaseException:
            self._close_fd()
            self._file.discard()
            raise

    def _pwrite(self, data: bytes | memoryview, offset: int) -> None:
        view = memoryview(data).cast("B")
        while len(view):
            n = os.pwrite(self._fd, view, offset)
            view, offset = view[n:], offset + n

    def _close_fd(self) -> None:
        fd = self.__dict__.pop("_fd", None)
        if fd is not None:
            os.close(fd)

    def _write(self, frame: np.ndarray, index: int, record: dict[str, Any]) -> None:
        data = np.ascontiguousarray(frame, dtype="<f4")
        self._pwrite(memoryview(data).cast("B"), len(self._head) + index * self._frame_bytes)
        entry = {"index": index}
        for key in ("window", "centre_tick"):
            if key in record:
                entry[key] = record[key]
        self._frames.append(entry)

    def _finish(self) -> None:
        import tomli_w

        k = self.frames_written
        side = AtomicFile(sidecar_path(self.path))
        with finishing(self.path, side.discard):
            if k < self.n_frames:
                head = _header((k, *self.frame_shape))
                if len(head) != len(self._head):  # pragma: no cover - numpy always pads the shape
                    raise OutputFileError(f"{self.path}: cannot shorten the array header; export the range again.")
                self._pwrite(head, 0)
                os.ftruncate(self._fd, len(head) + k * self._frame_bytes)
            os.fsync(self._fd)
            self._close_fd()
            record = self.export_record()
            record["n_frames"] = k
            record["shape"] = [k, *self.frame_shape]
            record["dtype"] = "float32"
            record["params"] = record.pop("params")
            record["export"] = record.pop("export")
            record["frames"] = self._frames
            side.tmp.write_text(tomli_w.dumps(record), encoding="utf-8")
            side.commit()
            try:
                self._file.commit()
            except BaseException:
                os.remove(side.path)  # no sidecar without its array
                raise
        self.paths += [self.path, side.path]

    def _discard(self) -> None:
        self._close_fd()
        self._file.discard()
