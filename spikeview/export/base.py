"""The :class:`Exporter` interface shared by every output format, and its bookkeeping.

An exporter is opened for a known number of frames of one shape, takes the frames one at a time
through :meth:`Exporter.write`, and is finished with :meth:`Exporter.close` (keep) or
:meth:`Exporter.abort` (discard). Used as a context manager it closes on success, keeps the
finished frames on :class:`~spikeview.errors.Cancelled`, and aborts on any other exception.

What survives an interruption:

===========  ==========================================  =====================================
format       cancelled (``close(allow_partial=True)``)   error (``abort()``)
===========  ==========================================  =====================================
EXR, PNG     the finished frames (each file is atomic)   the finished frames
MP4          a valid, shorter video of the finished      nothing (the temporary is deleted)
             frames; no file if none was finished
npy          a shorter ``(k, H, W[, 3])`` array and its  nothing (the temporary is deleted)
             sidecar; no file if none was finished
===========  ==========================================  =====================================

A file that existed under the final name is replaced only when the new one is complete.
"""

from __future__ import annotations

import os
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import Any, ClassVar

import numpy as np

from spikeview._files import check_writable, os_error_sentence
from spikeview.errors import Cancelled, OutputFileError, ParameterError
from spikeview.export.atomic import PARTIAL_MARKER, atomic_path
from spikeview.export.settings import ExportConfig, ExportMetadata, tomlable

#: a printf-style frame-number field: %d or %0Nd
_FIELD = re.compile(r"%0?\d*d")
#: the same with the separator before it (``_%04d``, ``.%d``): what :func:`strip_frame_field` removes
_FIELD_AND_SEPARATOR = re.compile(r"[_.\-]?%0?\d*d")

CancelCheck = Callable[[], bool]
ProgressCallback = Callable[[int, int], None]


def has_frame_field(path: str | os.PathLike[str]) -> bool:
    """Whether the file name holds one printf frame-number field (``%04d``, ``%d``).

    Raises:
        ParameterError: for any other ``%`` in the name (a literal percent sign is written ``%%``).
    """
    name = Path(path).name
    if "%" not in name:
        return False
    rest = name.replace("%%", "")
    fields = _FIELD.findall(rest)
    if len(fields) != 1 or rest.count("%") != 1:
        raise ParameterError(
            f"{path}: the file name may hold exactly one frame-number field such as %04d "
            "(write a literal percent sign as %%)."
        )
    return True


def check_frame_field(path: Path, n_frames: int, sequence: bool, fmt: str) -> None:
    """A one-file-per-frame format (``sequence``) of several frames needs a frame-number field in its
    name; a one-file format takes none (:class:`ParameterError` naming the fix otherwise)."""
    field = has_frame_field(path)
    if sequence and not field and n_frames > 1:
        raise ParameterError(
            f"{path}: a {n_frames}-frame {fmt.upper()} export writes one file per frame, "
            f"so the name needs a frame-number field, e.g. {path.with_suffix('')}_%04d{path.suffix}."
        )
    if not sequence and field:
        raise ParameterError(
            f"{path}: one {fmt.upper()} file holds all frames, so its name takes no frame-number field; remove the %d part."
        )


def strip_frame_field(name: str) -> str:
    """``name`` without its frame-number field and the separator before it: ``f_%04d.exr`` → ``f.exr``."""
    return _FIELD_AND_SEPARATOR.sub("", name)


def existing_frame_files(out: str | os.PathLike[str]) -> list[Path]:
    """Files an export to ``out`` could replace: ``out`` itself, or for a ``name_%04d.png`` pattern every
    file in its folder that fits the pattern (whatever the frame numbers)."""
    out = Path(out)
    if "%" not in out.name:
        return [out] if out.exists() else []
    parts = re.split(r"%0?(\d*)d", out.name.replace("%%", "\0"), maxsplit=1)
    if len(parts) != 3:
        return []
    head, width, tail = (p.replace("\0", "%") for p in parts)
    digits = rf"\d{{{width},}}" if width else r"\d+"
    rx = re.compile(re.escape(head) + digits + re.escape(tail) + "$")
    try:
        return sorted(p for p in out.parent.iterdir() if rx.match(p.name))
    except OSError:
        return []


@contextmanager
def finishing(path: Path, undo: Callable[[], Any]) -> Iterator[None]:
    """Finish an output: on any failure ``undo()`` runs first; an ``OSError`` becomes one sentence naming ``path``."""
    try:
        yield
    except OSError as e:
        undo()
        raise OutputFileError(f"{path}: finishing the file failed: {os_error_sentence(e)}.") from None
    except BaseException:
        undo()
        raise


def check_output_folder(path: Path) -> None:
    """Raise :class:`OutputFileError` unless ``path``'s folder exists and is writable."""
    folder = path.parent
    if not folder.exists():
        raise OutputFileError(f"{path}: the folder {folder} does not exist; create it or choose another output path.")
    if not folder.is_dir():
        raise OutputFileError(f"{path}: {folder} is not a folder; choose another output path.")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputFileError(f"{path}: no permission to write in {folder}; choose a folder you can write to.")
    # access() does not see everything (read-only mounts under root, ACLs, network shares):
    # create and remove a probe file so an unwritable place is reported now, not after encoding
    probe = folder / f".{path.stem}{PARTIAL_MARKER}probe{os.getpid()}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return
    except OSError as e:
        raise OutputFileError(f"{path}: cannot create files in {folder}: {os_error_sentence(e)}.") from None
    os.close(fd)
    try:
        os.remove(probe)
    except OSError:
        pass


def source_files(source: str | os.PathLike[str] | None) -> list[Path]:
    """The files that belong to input capture ``source``: itself, its sidecar and its ground truth.

    (The naming rules of :mod:`spikeview.io.sidecar` and :mod:`spikeview.sim.write`, repeated
    here because the export layer imports neither.)
    """
    if not source:
        return []
    p = Path(source)
    return [p, p.with_name(p.name + ".toml"), p.with_name(p.stem + ".gt.npz")]


def check_frame_shape(frame_shape: Any) -> tuple[int, ...]:
    """Validate ``(H, W)`` or ``(H, W, 3)`` and return it as a tuple of ints."""
    try:
        shape = tuple(int(v) for v in frame_shape)
    except (TypeError, ValueError):
        shape = ()
    if len(shape) not in (2, 3) or min(shape, default=0) < 1 or (len(shape) == 3 and shape[2] != 3):
        raise ParameterError(
            f"frame_shape {frame_shape!r} is not valid; pass (H, W) for mono or (H, W, 3) for colour frames."
        )
    return shape


class Exporter(ABC):
    """Writes ``n_frames`` frames of one shape to one output (a file or a numbered sequence).

    Frames are float32 ``(H, W, 3)`` RGB or ``(H, W)`` mono, linear light, nominally in
    ``[0, 1]``, one per output time, written in output order.

    Args:
        path: output file, or for EXR/PNG sequences a printf pattern such as ``frame_%04d.exr``.
        n_frames: number of frames that will be written (>= 1).
        frame_shape: ``(H, W)`` or ``(H, W, 3)``.
        config: export settings.
        metadata: what produced the frames (written into the output).
        cancel: called before each frame; when it returns true, :meth:`write` raises
            :class:`~spikeview.errors.Cancelled`.
        progress: called after each frame as ``progress(frames_done, n_frames)``.
        overwrite: replace output files that already exist (otherwise that is an
            :class:`~spikeview.errors.OutputFileError`, raised before anything is written).
        inputs: files the run reads; no output may be one of them, even with ``overwrite``.
            The source named in ``metadata`` (with its sidecar and ground truth) is always
            protected.
        extra_outputs: further files the caller will write beside the output (a preset):
            checked by the same rules, up front.
        announce: called with one sentence giving the size of a large output (100 MB or more)
            before it is written, where the size is known in advance (npy); the CLI prints it.

    Attributes:
        frames_written: frames accepted so far.
        paths: finished output files (for sequences, filled as frames finish).
    """

    #: short name used in messages and records ("exr", "png", "mp4", "npy")
    format: ClassVar[str]
    #: whether the output is one file per frame
    sequence: ClassVar[bool] = False

    def __init__(
        self,
        path: str | os.PathLike[str],
        n_frames: int,
        frame_shape: tuple[int, ...],
        config: ExportConfig | None = None,
        metadata: ExportMetadata | None = None,
        *,
        cancel: CancelCheck | None = None,
        progress: ProgressCallback | None = None,
        overwrite: bool = False,
        inputs: Iterable[str | os.PathLike[str] | None] = (),
        extra_outputs: Iterable[str | os.PathLike[str]] = (),
        announce: Callable[[str], None] | None = None,
    ):
        self.path = Path(path)
        self.announce = announce
        if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
            raise ParameterError(f"{self.path}: n_frames = {n_frames!r}; pass the number of frames to write (>= 1).")
        self.n_frames = int(n_frames)
        self.frame_shape = check_frame_shape(frame_shape)
        self.config = config if config is not None else ExportConfig()
        self.metadata = metadata if metadata is not None else ExportMetadata()
        self.cancel = cancel
        self.progress = progress
        self.frames_written = 0
        self.paths: list[Path] = []
        self._state = "open"
        check_frame_field(self.path, self.n_frames, self.sequence, self.format)
        check_output_folder(self.path)
        self.overwrite = bool(overwrite)
        protected = [*source_files(self.metadata.source), *(p for p in inputs if p)]
        for out in [*self.output_files(), *map(Path, extra_outputs)]:
            check_writable(out, self.overwrite, protected)
        self._open()

    # -- what subclasses implement -------------------------------------------------------------

    def _open(self) -> None:  # noqa: B027 - optional hook
        """Prepare the output (create the temporary file…)."""

    @abstractmethod
    def _write(self, frame: np.ndarray, index: int, record: dict[str, Any]) -> None:
        """Write validated frame ``index``; ``record`` is its metadata (see :meth:`frame_record`)."""

    def _finish(self) -> None:  # noqa: B027 - optional hook
        """Complete the output with the ``frames_written`` frames (at least one) and rename it into place."""

    def _discard(self) -> None:  # noqa: B027 - optional hook
        """Remove every temporary; finished sequence frames stay."""

    def output_files(self) -> list[Path]:
        """Every file this export will create (checked against existing files before writing)."""
        if self.sequence:
            return [self.frame_path(i) for i in range(self.n_frames)]
        return [self.path]

    # -- shared --------------------------------------------------------------------------------

    @property
    def mono(self) -> bool:
        """Whether frames are ``(H, W)``."""
        return len(self.frame_shape) == 2

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` or :meth:`abort` has run."""
        return self._state != "open"

    def frame_path(self, index: int) -> Path:
        """File of frame ``index`` of a sequence: the pattern filled with ``first_frame + index``."""
        if not has_frame_field(self.path):
            return self.path
        number = self.config.first_frame + index
        return self.path.with_name(self.path.name % number)

    def export_record(self) -> dict[str, Any]:
        """The export-level metadata as a TOML-ready dict (source, method, ticks, params, settings)."""
        m = self.metadata
        from spikeview import __version__

        rec: dict[str, Any] = {
            "spikeview_version": __version__,
            "format": self.format,
            "source": m.source,
            "method": m.method,
            "tick_rate": m.tick_rate,
        }
        if m.window is not None:
            rec["window"] = list(m.window)
        if m.centre_tick is not None:
            rec["centre_tick"] = m.centre_tick
        if m.step_ticks is not None:
            rec["step_ticks"] = m.step_ticks
        rec["frame_shape"] = list(self.frame_shape)
        rec["params"] = m.params
        if m.plan:
            rec["plan"] = dict(m.plan)
        rec["export"] = self.config.to_dict()
        return tomlable(rec)

    def frame_record(
        self, index: int, window: tuple[int, int] | None = None, centre_tick: int | None = None
    ) -> dict[str, Any]:
        """Metadata of output frame ``index``: :meth:`export_record` with this frame's ticks.

        ``window``/``centre_tick`` default to :meth:`ExportMetadata.frame_ticks`.
        """
        rec = self.export_record()
        w0, c0 = self.metadata.frame_ticks(index)
        window = w0 if window is None else window
        centre_tick = c0 if centre_tick is None else centre_tick
        for key in ("window", "centre_tick", "step_ticks"):
            rec.pop(key, None)
        rec["frame_index"] = index
        if self.sequence:
            rec["frame_number"] = self.config.first_frame + index
        if window is not None:
            rec["window"] = [int(window[0]), int(window[1])]
        if centre_tick is not None:
            rec["centre_tick"] = int(centre_tick)
        # keep the tables last so the TOML reads top-down
        rec["params"] = rec.pop("params")
        rec["export"] = rec.pop("export")
        return rec

    def describe(self, record: dict[str, Any]) -> str:
        """A one-line human description of a record (for ImageDescription / MP4 title)."""
        what = f"{record['method'] or 'spikeview'} reconstruction"
        if record.get("source"):
            what += f" of {record['source']}"
        if "window" in record:
            a, b = record["window"]
            what += f", ticks [{a}, {b})"
            if "centre_tick" in record:
                what += f" centred on {record['centre_tick']}"
        return f"{what} at {record['tick_rate']:g} Hz"

    def _check_frame(self, frame: Any, index: int) -> np.ndarray:
        where = f"{self.path}: frame {index}"
        if not isinstance(frame, np.ndarray):
            raise ParameterError(f"{where} is a {type(frame).__name__}; pass a numpy float32 array.")
        if frame.shape != self.frame_shape:
            raise ParameterError(
                f"{where} has shape {frame.shape} but this export was opened for {self.frame_shape}; "
                "every frame of one export must have the same shape."
            )
        if frame.dtype != np.float32:
            raise ParameterError(
                f"{where} has dtype {frame.dtype}; frames are float32 in [0, 1], convert with frame.astype(np.float32)."
            )
        finite = np.isfinite(frame)
        if not finite.all():
            bad = int(finite.size - np.count_nonzero(finite))
            raise ParameterError(
                f"{where} has {bad} NaN or infinite value(s); fix the reconstruction before exporting "
                "(np.nan_to_num replaces them)."
            )
        return frame

    def write(
        self, frame: np.ndarray, *, window: tuple[int, int] | None = None, centre_tick: int | None = None
    ) -> None:
        """Write the next frame.

        Args:
            frame: float32 ``frame_shape`` array, linear light in ``[0, 1]``, finite.
            window: this frame's tick range ``[a, b)``, overriding what the metadata implies.
            centre_tick: this frame's centre tick, overriding what the metadata implies.

        Raises:
            Cancelled: the cancel check returned true (nothing was written for this frame).
            ParameterError: wrong shape, dtype, non-finite values, or more than ``n_frames`` frames.
            OutputFileError: the file could not be written.
        """
        if self._state != "open":
            raise ParameterError(f"{self.path}: this export is already {self._state}; open a new exporter.")
        if self.cancel is not None and self.cancel():
            raise Cancelled(f"{self.path}: export cancelled after {self.frames_written} of {self.n_frames} frames")
        index = self.frames_written
        if index >= self.n_frames:
            raise ParameterError(
                f"{self.path}: this export was opened for {self.n_frames} frame(s) and got one more; "
                "pass the right n_frames."
            )
        frame = self._check_frame(frame, index)
        try:
            self._write(frame, index, self.frame_record(index, window, centre_tick))
        except OSError as e:
            raise OutputFileError(f"{self.path}: writing frame {index} failed: {os_error_sentence(e)}.") from None
        self.frames_written += 1
        if self.progress is not None:
            self.progress(self.frames_written, self.n_frames)

    def close(self, *, allow_partial: bool = False) -> list[Path]:
        """Finish the output and return the files written.

        Args:
            allow_partial: keep an output with fewer than ``n_frames`` frames (after a cancel).
                With no frame at all, single-file formats leave no file.

        Raises:
            ParameterError: fewer than ``n_frames`` frames were written and ``allow_partial`` is
                false (the exporter stays open: write the rest, or abort).
        """
        if self._state == "closed":
            return list(self.paths)
        if self._state == "aborted":
            raise ParameterError(f"{self.path}: this export was aborted; open a new exporter.")
        if self.frames_written < self.n_frames and not allow_partial:
            raise ParameterError(
                f"{self.path}: only {self.frames_written} of {self.n_frames} frames were written; write the rest "
                "before close(), or call close(allow_partial=True) to keep the finished ones."
            )
        if self.frames_written == 0 and not self.sequence:
            self.abort()
            return []
        with finishing(self.path, self.abort):
            self._finish()
        self._state = "closed"
        return list(self.paths)

    def abort(self) -> None:
        """Stop and delete unfinished output (finished sequence frames stay). Safe to call twice."""
        if self._state != "open":
            return
        self._state = "aborted"
        self._discard()

    def __enter__(self) -> Exporter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._state != "open":
            return
        if exc_type is None:
            try:
                self.close()
            except BaseException:
                self.abort()
                raise
        elif issubclass(exc_type, Cancelled):
            self.close(allow_partial=True)
        else:
            self.abort()

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}({str(self.path)!r}, {self.frames_written}/{self.n_frames} frames, "
            f"shape={self.frame_shape}, {self._state})"
        )


class SequenceExporter(Exporter):
    """One file per frame (EXR, PNG), each written atomically, numbered ``first_frame + index``."""

    sequence = True

    @abstractmethod
    def _write_file(self, tmp: Path, frame: np.ndarray, record: dict[str, Any]) -> None:
        """Write one complete image file at ``tmp`` (a temporary name with the right suffix)."""

    def _write(self, frame: np.ndarray, index: int, record: dict[str, Any]) -> None:
        path = self.frame_path(index)
        with atomic_path(path) as tmp:
            self._write_file(tmp, frame, record)
        self.paths.append(path)
