"""Safe file writing shared by every writer: never destroy data, check space first, fail cleanly.

* :func:`check_writable` — the one overwrite rule: an existing output is replaced only with
  ``overwrite=True`` (``--overwrite`` on the command line), and an *input* of the run (the
  capture, its sidecar, its ground truth, a scene file) never, whatever ``overwrite`` says.
* :func:`check_free_space` — refuse a write the disk cannot hold, before writing anything.
* :func:`preallocate` — reserve a file's full size up front (``posix_fallocate``), so a full disk
  fails at the start with ``ENOSPC`` instead of half-way (or, for a memory map, with a bus error).
* :func:`write_atomic` — small files (sidecars, presets, settings): temporary name, then rename.
* :func:`os_error_sentence` — an ``OSError`` as the end of a sentence for people ("the disk is
  full" rather than "[Errno 28] No space left on device").
"""

from __future__ import annotations

import errno
import io
import os
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, BinaryIO

from spikeview.errors import InputFileError, OutputFileError

#: writes at least this large are announced with their size before they start (bytes)
LARGE_WRITE_BYTES = 100 * 1024 * 1024


def human_bytes(n: float) -> str:
    """``1536`` → ``"1.5 KB"`` (decimal units, like file browsers and ``df -H``)."""
    n = float(n)
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} TB"  # pragma: no cover


def existing_file(path: str | os.PathLike[str], what: str, folder_fix: str) -> Path:
    """``path`` as a :class:`Path` if it names a file; :class:`InputFileError` naming ``what`` otherwise
    (missing: check the path; a folder: ``folder_fix``)."""
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{path}: {what} not found; check the path.")
    if path.is_dir():
        raise InputFileError(f"{path}: is a folder, not a {what}; {folder_fix}.")
    return path


def is_disk_full(e: BaseException) -> bool:
    """Whether ``e`` is an out-of-space error (``ENOSPC``, or ``EDQUOT``/``EFBIG`` limits)."""
    if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        return True
    text = str(e).lower()
    return "no space left" in text or "disk quota" in text or "file too large" in text


def os_error_sentence(e: BaseException) -> str:
    """What went wrong and the fix, for the end of a sentence (no errno numbers)."""
    if isinstance(e, OSError) and e.errno == errno.EFBIG or "file too large" in str(e).lower():
        return "the file is larger than this disk or account allows; choose another disk or write less"
    if is_disk_full(e):
        return "the disk is full; free some space or choose another disk"
    if isinstance(e, PermissionError) or getattr(e, "errno", None) in (errno.EACCES, errno.EPERM, errno.EROFS):
        return "no permission to write there; choose a folder you can write to"
    reason = getattr(e, "strerror", None) or str(e) or type(e).__name__
    return f"{reason[0].lower() + reason[1:] if reason else reason}; check the folder and free space"


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.abspath(os.path.realpath(a)) == os.path.abspath(os.path.realpath(b))


#: a spike file's sidecar is its name plus this (``scene.dat`` → ``scene.dat.toml``; :mod:`spikeview.io.sidecar`)
SIDECAR_SUFFIX = ".toml"


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The sidecar of spike file ``path``: the same name plus ``.toml`` (``scene.dat`` → ``scene.dat.toml``)."""
    path = Path(path)
    return path.with_name(path.name + SIDECAR_SUFFIX)


def check_writable(path: str | os.PathLike[str], overwrite: bool = False,
                   inputs: Iterable[str | os.PathLike[str] | None] = (), *, owner: str | os.PathLike[str] | None = None) -> Path:
    """Raise :class:`OutputFileError` unless writing ``path`` destroys nothing that must be kept.

    Args:
        path: an output file about to be written.
        overwrite: an existing ``path`` may be replaced (``--overwrite``).
        inputs: files this run reads; ``path`` may never be one of them nor an input's sidecar (compared after
            resolving links, and by inode when both exist), even with ``overwrite``. ``None`` entries are ignored.
        owner: the output whose settings file ``path`` is (``clip.mp4`` for ``clip.mp4.preset.toml``): where that
            output is gone, the message says so.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.
    """
    path = Path(path)
    for inp in inputs:
        if inp is None or str(inp) == "":
            continue
        if _same(path, Path(inp)):
            raise OutputFileError(f"{path}: this is an input of the run ({Path(inp).name}), which is never "
                                  "overwritten, even with --overwrite; choose another output name.")
        if _same(path, sidecar_path(inp)):  # existing or not: written, it would be read as the input's sidecar
            raise OutputFileError(f"{path}: this is the sidecar of an input of the run ({Path(inp).name}: how to read "
                                  "it), which is never overwritten, even with --overwrite; choose another output name.")
    if path.is_dir():
        raise OutputFileError(f"{path}: is a folder; give a file name inside it.")
    if (path.exists() or path.is_symlink()) and not overwrite:
        if owner is not None and not Path(owner).exists():
            raise OutputFileError(
                f"{path}: the settings file of an earlier run whose output {Path(owner).name} is gone is still there "
                f"and would be replaced; delete it, choose another output name, or pass --overwrite.")
        raise OutputFileError(f"{path}: the file already exists; choose another name, or pass --overwrite to replace it.")
    return path


def check_free_space(folder: str | os.PathLike[str], n_bytes: int, what: str) -> None:
    """Raise :class:`OutputFileError` when the disk holding ``folder`` has less than ``n_bytes`` free.

    ``what`` names the write in the message (``"the capture and its ground truth"``).
    """
    folder = Path(folder)
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # cannot tell: let the write itself find out
        return
    if n_bytes > free:
        raise OutputFileError(f"{folder}: {what} need {human_bytes(n_bytes)} but only {human_bytes(free)} are free "
                              "on that disk; free some space, choose another disk, or write less.")


def preallocate(fd: int, n_bytes: int, path: str | os.PathLike[str]) -> None:
    """Reserve ``n_bytes`` for open file ``fd`` (its size becomes ``n_bytes``).

    Writing into reserved blocks cannot fail for lack of space, so a full disk is found here,
    before any work. Filesystems without ``fallocate`` support are left alone.

    Raises:
        OutputFileError: the disk cannot hold ``n_bytes`` (the caller removes the file).
    """
    if n_bytes <= 0:
        return
    try:
        os.posix_fallocate(fd, 0, int(n_bytes))
    except AttributeError:  # pragma: no cover - not on this platform
        return
    except OSError as e:
        if e.errno in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS, getattr(errno, "ENOTSUP", -1)):
            return
        raise OutputFileError(f"{path}: cannot reserve {human_bytes(n_bytes)} for the file: {os_error_sentence(e)}.") \
            from None


def write_all(fd: int, data: bytes | bytearray | memoryview) -> None:
    """Write all of ``data`` to file descriptor ``fd`` (``os.write`` may write only part)."""
    view = memoryview(data).cast("B")
    while len(view):
        n = os.write(fd, view)
        if n <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        view = view[n:]


class RawFile(io.RawIOBase):
    """A file written with plain ``os.write`` calls (wrap it in :class:`io.BufferedWriter`).

    Every writer's bytes pass through :func:`os.write`, one place where a full disk shows up
    as ``OSError(ENOSPC)`` (and where tests inject it).
    """

    def __init__(self, path: str | os.PathLike[str]):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def write(self, b) -> int:  # type: ignore[override]
        return os.write(self.fd, b)

    def seek(self, offset: int, whence: int = 0) -> int:
        return os.lseek(self.fd, offset, whence)

    def tell(self) -> int:
        return os.lseek(self.fd, 0, os.SEEK_CUR)

    def fileno(self) -> int:
        return self.fd

    def close(self) -> None:
        if not self.closed:
            try:
                os.close(self.fd)
            finally:
                super().close()


def write_atomic(path: str | os.PathLike[str], data: str | bytes | Callable[[BinaryIO], Any], what: str = "the file",
                 fix: str = "check the folder exists and is writable") -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the complete new one, never a part.

    ``data`` is text, bytes, or a function that writes the content into the binary file it is given.

    This does not check :func:`check_writable`: callers that must not replace a file check first.

    Raises:
        OutputFileError: one sentence naming ``path`` and ``what``, with ``fix``; no temporary is left.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        elif isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            with open(tmp, "wb") as f:
                data(f)
        os.replace(tmp, path)
    except OSError as e:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if is_disk_full(e):
            raise OutputFileError(f"{path}: cannot write {what}: {os_error_sentence(e)}.") from None
        raise OutputFileError(f"{path}: cannot write {what} ({e.strerror or e}); {fix}.") from None
    return path
