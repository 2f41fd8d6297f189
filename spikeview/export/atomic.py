"""Atomic file writes: write to a temporary name, rename on success, delete on failure.

An export that is interrupted (an error, a cancel, Ctrl-C) must never leave a file that looks
finished but is not. Every writer in :mod:`spikeview.export` therefore writes to a hidden
temporary file **in the destination folder** (so the final :func:`os.replace` is a same-filesystem
rename, which is atomic on POSIX and Windows) and renames it only once the file is complete. Image
sequences do this per frame, so the frames finished before an interruption stay valid.

Temporary names look like ``.<stem>.partial-<random><suffix>``: hidden, unique, and ending in the
real suffix because OpenImageIO picks its writer from the extension.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

#: marker in every temporary name (tests look for it to find stray temporaries)
PARTIAL_MARKER = ".partial-"


def temporary_name(path: str | os.PathLike[str]) -> Path:
    """A fresh hidden temporary path next to ``path``, with the same suffix.

    The file is not created; the caller's writer creates it.
    """
    path = Path(path)
    return path.with_name(f".{path.stem}{PARTIAL_MARKER}{secrets.token_hex(4)}{path.suffix}")


def _fsync(path: Path) -> None:
    # Flush the contents to disk before the rename so a power cut cannot leave a renamed but
    # empty file (a known ext4/xfs hazard of rename-without-fsync).
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class AtomicFile:
    """A temporary file that becomes ``path`` on :meth:`commit` or vanishes on :meth:`discard`.

    Use it when the temporary must live across many calls (an MP4 being encoded, a memory-mapped
    ``.npy``); for a single write, :func:`atomic_path` is simpler.

    Attributes:
        path: the final destination.
        tmp: the temporary file to write (not created here).
    """

    def __init__(self, path: str | os.PathLike[str], *, fsync: bool = True):
        self.path = Path(path)
        self.tmp = temporary_name(self.path)
        self.fsync = fsync
        self.done = False

    def commit(self) -> Path:
        """Rename the finished temporary to :attr:`path` (replacing any existing file)."""
        if self.done:
            raise RuntimeError(f"{self.path}: atomic file already committed or discarded")
        if self.fsync:
            _fsync(self.tmp)
        os.replace(self.tmp, self.path)
        self.done = True
        return self.path

    def discard(self) -> None:
        """Delete the temporary, if it exists; the destination is left untouched."""
        if self.done:
            return
        self.done = True
        with contextlib.suppress(FileNotFoundError):
            os.remove(self.tmp)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, fsync: bool = True) -> Iterator[Path]:
    """Context manager yielding a temporary path that replaces ``path`` when the block succeeds.

    If the block raises anything (including :class:`~spikeview.errors.Cancelled` and
    ``KeyboardInterrupt``), the temporary is deleted and ``path`` is left as it was.

    Example:
        >>> with atomic_path("frame_0001.exr") as tmp:  # doctest: +SKIP
        ...     write_exr(tmp, frame)
    """
    f = AtomicFile(path, fsync=fsync)
    try:
        yield f.tmp
        f.commit()
    except BaseException:
        f.discard()
        raise
