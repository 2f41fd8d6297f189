"""Atomic small-file writes (sidecars, presets, settings, raw test files): temporary name, then rename."""

from __future__ import annotations

import os
from pathlib import Path

from spikeview.errors import OutputFileError


def write_atomic(path: str | os.PathLike[str], data: str | bytes, what: str = "the file",
                 fix: str = "check the folder exists and is writable") -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the complete new one, never a part.

    Raises:
        OutputFileError: one sentence naming ``path`` and ``what``, with ``fix``; no temporary is left.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputFileError(f"{path}: cannot write {what} ({e.strerror or e}); {fix}.") from None
    return path
