"""User-facing errors.

Every :class:`SpikeviewError` message is one sentence for a person: it names the file or the
parameter at fault and says how to fix it. The CLI prints it without a traceback; the GUI shows it
in a dialog or the status bar.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
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


#: the cancel flags of the jobs running in this thread (innermost last), for loops deep inside a job
#: that are not handed a flag (a prior's strips and layers): :func:`check_cancelled`
_SCOPE: contextvars.ContextVar[tuple[Any, ...]] = contextvars.ContextVar("spikeview_cancel_scope", default=())


@contextlib.contextmanager
def cancel_scope(cancel: Any) -> Iterator[None]:
    """Make ``cancel`` (as for :func:`is_cancelled`; ``None`` adds nothing) visible to
    :func:`check_cancelled` in everything this thread runs inside the block; scopes nest."""
    if cancel is None:
        yield
        return
    token = _SCOPE.set(_SCOPE.get() + (cancel,))
    try:
        yield
    finally:
        _SCOPE.reset(token)


def check_cancelled(where: str = "") -> None:
    """Raise :class:`Cancelled` when a flag of an enclosing :func:`cancel_scope` is set (a no-op
    outside every scope; costs a few microseconds, so inner loops can call it between their
    pieces of work)."""
    for cancel in _SCOPE.get():
        if is_cancelled(cancel):
            raise Cancelled(f"cancelled {where}".rstrip())


class OutputFileError(SpikeviewError):
    """An output file or folder that cannot be written (missing folder, no permission, disk full)."""
