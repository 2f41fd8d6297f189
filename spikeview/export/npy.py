"""NumPy ``.npy`` stacks with a TOML sidecar.

Conventions:
    * One array of float32, shape ``(N, H, W, 3)`` for colour or ``(N, H, W)`` for mono, the
      linear values exactly as given (no levels, no clipping, no transfer curve).
    * Written through :func:`numpy.lib.format.open_memmap` into a hidden temporary file, so a
      long sequence never has to be in memory; renamed into place on close.
    * Sidecar ``<file>.toml`` (``frames.npy`` → ``frames.npy.toml``), written atomically just
      before the array is renamed: the export record (source, method, tick rate, first window,
      step, ``[params]``, ``[export]``), ``n_frames``, ``shape``, ``dtype``, and one
      ``[[frames]]`` entry per frame with its index and, where known, window and centre tick.
    * On cancel (``close(allow_partial=True)``) the finished ``k`` frames are copied into a
      ``(k, …)`` array (a memory map's shape is fixed in its header) and kept with their
      sidecar; with none finished, or on an error, no file is left.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import InputFileError, OutputFileError
from spikeview.export.atomic import AtomicFile
from spikeview.export.base import Exporter

#: frames copied at a time when shortening a cancelled export
_COPY_CHUNK = 64


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


class NpyExporter(Exporter):
    """A float32 ``.npy`` stack plus ``<file>.toml`` (see module docstring)."""

    format = "npy"

    def _open(self) -> None:
        self._file = AtomicFile(self.path)
        self._frames: list[dict[str, Any]] = []
        try:
            self._array = np.lib.format.open_memmap(
                self._file.tmp, mode="w+", dtype=np.float32, shape=(self.n_frames, *self.frame_shape)
            )
        except OSError as e:
            self._file.discard()
            raise OutputFileError(
                f"{self.path}: could not create the file ({e}); check the folder and free space."
            ) from None

    def _write(self, frame: np.ndarray, index: int, record: dict[str, Any]) -> None:
        self._array[index] = frame
        entry = {"index": index}
        for key in ("window", "centre_tick"):
            if key in record:
                entry[key] = record[key]
        self._frames.append(entry)

    def _finish(self) -> None:
        import tomli_w

        k = self.frames_written
        side = AtomicFile(sidecar_path(self.path))
        try:
            self._array.flush()
            if k < self.n_frames:
                self._shorten(k)
            self.__dict__.pop("_array", None)  # unmap before the rename
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
        except OSError as e:
            side.discard()
            raise OutputFileError(f"{self.path}: finishing the file failed ({e}); check free disk space.") from None
        except BaseException:
            side.discard()
            raise
        self.paths += [self.path, side.path]

    def _shorten(self, k: int) -> None:
        """Replace the temporary by one holding only the first ``k`` frames."""
        short = AtomicFile(self.path)
        try:
            out = np.lib.format.open_memmap(short.tmp, mode="w+", dtype=np.float32, shape=(k, *self.frame_shape))
            for i in range(0, k, _COPY_CHUNK):
                out[i : min(k, i + _COPY_CHUNK)] = self._array[i : min(k, i + _COPY_CHUNK)]
            out.flush()
            del out
        except BaseException:
            short.discard()
            raise
        del self._array
        self._file.discard()
        self._file = short

    def _discard(self) -> None:
        # drop the memory map before deleting its file (Windows cannot delete a mapped file)
        self.__dict__.pop("_array", None)
        self._file.discard()
