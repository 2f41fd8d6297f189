"""User-facing errors.

Every :class:`SpikeviewError` message is one sentence for a person: it names the file or the
parameter at fault and says how to fix it. The CLI prints it without a traceback; the GUI shows it
in a dialog or the status bar.
"""

from __future__ import annotations

from typing import Any


class SpikeviewError(Exception):
    """An error caused by the user's input (file, parameter, setting), with a fix in the message."""


class InputFileError(SpikeviewError):
    """A spike/image/video file that is missing, empty, truncated or not what its settings say."""


class ParameterError(SpikeviewError, ValueError):
    """A parameter value that is out of range or inconsistent with the data."""


class GeometryError(InputFileError):
    """Width/height/format could not be determined or do not fit the file.

    ``candidates`` lists ``(width, height)`` pairs that would fit, when some could be found.
    """

    def __init__(self, message: str, candidates: list[tuple[int, int]] | None = None):
        super().__init__(message)
        self.candidates = list(candidates or [])


class Cancelled(Exception):
    """Raised inside long jobs when their cancel flag is set (not an error for the user)."""


def is_cancelled(cancel: Any) -> bool:
    """Whether a job's cancel flag is set: ``None`` (never), a ``threading.Event``-like (``is_set()``),
    a callable, or a plain truth value. The one cancel check of the library's long loops."""
    if cancel is None:
        return False
    if hasattr(cancel, "is_set"):
        return bool(cancel.is_set())
    if callable(cancel):
        return bool(cancel())
    return bool(cancel)


class OutputFileError(SpikeviewError):
    """An output file or folder that cannot be written (missing folder, no permission, disk full)."""
