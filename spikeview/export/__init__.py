"""Writing reconstructed frames: EXR, PNG, MP4 and npy, each carrying the settings that made it.

Frames are float32 ``(H, W, 3)`` RGB or ``(H, W)`` mono, linear light in ``[0, 1]``, one per
output time. One entry point picks the format from the suffix of the output path:

===========  ===================================================================================
suffix       what is written
===========  ===================================================================================
``.exr``     half-float linear OpenEXR, one file per frame (:mod:`spikeview.export.exr`)
``.png``     8/16-bit display-encoded PNG, one file per frame (:mod:`spikeview.export.png`)
``.mp4``     H.264 yuv420p video (:mod:`spikeview.export.mp4`)
``.npy``     one float32 ``(N, H, W[, 3])`` array + ``<file>.toml`` (:mod:`spikeview.export.npy`)
===========  ===================================================================================

Conventions:
    * **Frame numbers**: files of an EXR/PNG sequence are numbered by **output index**, starting
      at ``ExportConfig.first_frame`` (0 by default): ``frame_%04d.exr`` gives
      ``frame_0000.exr, frame_0001.exr, …``. Contiguous numbers are what sequence tools expect;
      the centre tick of each frame is in its metadata.
    * **Patterns**: the file name holds one printf field (``%d`` or ``%0Nd``; a literal ``%``
      is ``%%``). A multi-frame EXR/PNG export without a field is an error whose message shows
      the name to use (nothing is inserted silently); a single-frame export without a field
      writes exactly the given name. MP4 and npy names take no field.
    * **Metadata**: every output records source, method, tick rate, tick window ``[a, b)``,
      centre tick, the full parameter set and the export settings as TOML; read it back with
      :func:`read_export_metadata`.
    * **Atomicity**: nothing appears under a final name until it is complete; see
      :mod:`spikeview.export.base` for what survives a cancel or an error. Existing files of
      the same name are **not** replaced unless ``overwrite=True`` (checked for every output
      file before the first frame is written), and an input of the run (the source named in the
      metadata, its sidecar and ground truth, anything in ``inputs``) never is.
    * **Display formats** (PNG, MP4) use fixed levels and the sRGB curve
      (:mod:`spikeview.export.display`), never auto-levels; EXR and npy keep linear values.

Example:
    >>> cfg = ExportConfig(fps=30, crf=18)  # doctest: +SKIP
    >>> meta = ExportMetadata(source="capture.dat", method="tfp", window=(0, 10), centre_tick=5,
    ...                       step_ticks=10, params=recon_config)
    >>> with open_exporter("out/frame_%04d.exr", len(frames), frames[0].shape, cfg, meta) as ex:
    ...     for f in frames:
    ...         ex.write(f)
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import InputFileError, ParameterError
from spikeview.export.base import CancelCheck, Exporter, ProgressCallback
from spikeview.export.mp4 import describe_slow_motion, slow_motion_factor
from spikeview.export.settings import ExportConfig, ExportMetadata

__all__ = [
    "ExportConfig",
    "ExportMetadata",
    "Exporter",
    "SUFFIXES",
    "check_output_name",
    "output_stem",
    "describe_slow_motion",
    "export_frames",
    "open_exporter",
    "read_export_metadata",
    "slow_motion_factor",
]

#: output suffixes understood by :func:`open_exporter`
SUFFIXES = (".exr", ".png", ".mp4", ".npy")


def _exporter_class(path: Path) -> type[Exporter]:
    # imported here: OpenImageIO and PyAV are heavy and only needed when exporting
    suffix = path.suffix.lower()
    if suffix == ".exr":
        from spikeview.export.exr import ExrExporter

        return ExrExporter
    if suffix == ".png":
        from spikeview.export.png import PngExporter

        return PngExporter
    if suffix == ".mp4":
        from spikeview.export.mp4 import Mp4Exporter

        return Mp4Exporter
    if suffix == ".npy":
        from spikeview.export.npy import NpyExporter

        return NpyExporter
    raise ParameterError(
        f"{path}: unknown export format {suffix or '(no suffix)'!r}; end the name with .exr, .png, .mp4 or .npy."
    )


def output_stem(source: str | os.PathLike[str] | None, method: str, *, tick: int | None = None,
                span: tuple[object, object] | None = None) -> str:
    """The default output name without suffix, the app's and the CLI's: ``<capture>_<method>_t<T>`` for the
    window at tick ``T``, ``<capture>_<method>_<A>-<B>`` for the range ``span = (A, B)``."""
    base = Path(source).stem if source else "spikeview"
    if span is not None:
        return f"{base}_{method}_{span[0]}-{span[1]}"
    return f"{base}_{method}_t{tick}" if tick is not None else f"{base}_{method}"


def check_output_name(out: str | os.PathLike[str], n_frames: int) -> None:
    """The format of ``out`` is known and its name fits ``n_frames`` frames (a frame-number field for
    several EXR/PNG frames, none for MP4/npy): checked before any work, nothing written."""
    from spikeview.export.base import check_frame_field

    path = Path(out)
    cls = _exporter_class(path)
    check_frame_field(path, int(n_frames), cls.sequence, cls.format)


def open_exporter(
    out: str | os.PathLike[str],
    n_frames: int,
    frame_shape: tuple[int, ...],
    config: ExportConfig | Mapping[str, Any] | None = None,
    metadata: ExportMetadata | Mapping[str, Any] | None = None,
    **options: Any,
) -> Exporter:
    """Open an exporter for ``n_frames`` frames, choosing the format from the suffix of ``out``.

    ``options`` are the keyword arguments of :class:`Exporter` (``cancel``, ``progress``, ``overwrite``,
    ``inputs``, ``extra_outputs``, ``announce``), described here:

    Args:
        out: output file (``.mp4``, ``.npy``, single-frame ``.exr``/``.png``) or printf pattern
            (``frames/frame_%04d.exr``). Its folder must exist.
        n_frames: number of frames that will be written (>= 1).
        frame_shape: ``(H, W, 3)`` for colour or ``(H, W)`` for mono.
        config: export settings (an :class:`ExportConfig` or a dict of its fields); defaults.
        metadata: what made the frames (an :class:`ExportMetadata` or a dict of its fields).
        cancel: polled before each frame; returning true makes ``write`` raise
            :class:`~spikeview.errors.Cancelled`.
        progress: called after each frame as ``progress(frames_done, n_frames)``.
        overwrite: replace existing output files (``--overwrite``); without it an existing file
            is an error, raised before anything is written.
        inputs: files the run reads, never overwritten (the metadata's source, its sidecar and
            ground truth are always included).
        extra_outputs: other files the caller writes beside the output (e.g. the preset),
            checked by the same rules up front.
        announce: called with one sentence stating the size of a large output (100 MB or more)
            before writing it, where the size is known in advance (npy); the CLI prints it.

    Returns:
        An :class:`Exporter`; use it as a context manager, or call ``close()``/``abort()``.

    Raises:
        ParameterError: unknown suffix, bad pattern, bad shape or settings.
        OutputFileError: the folder is missing or not writable, an output exists (without
            ``overwrite``) or is an input, the disk cannot hold it, or the file cannot be created.
    """
    path = Path(out)
    cls = _exporter_class(path)
    if config is None:
        config = ExportConfig()
    elif isinstance(config, Mapping):
        config = ExportConfig.from_dict(dict(config), where="export settings")
    if metadata is None:
        metadata = ExportMetadata()
    elif isinstance(metadata, Mapping):
        metadata = ExportMetadata.from_dict(dict(metadata), where="export metadata")
    return cls(path, n_frames, frame_shape, config, metadata, **options)


def export_frames(
    frames: Iterable[np.ndarray],
    out: str | os.PathLike[str],
    config: ExportConfig | Mapping[str, Any] | None = None,
    metadata: ExportMetadata | Mapping[str, Any] | None = None,
    *,
    n_frames: int | None = None,
    cancel: CancelCheck | None = None,
    progress: ProgressCallback | None = None,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike[str] | None] = (),
) -> list[Path]:
    """Write every frame of ``frames`` to ``out`` and return the files written.

    Args:
        frames: float32 frames of one shape (a sequence, an ``(N, H, W[, 3])`` array, or an
            iterator/generator, then with ``n_frames``).
        out, config, metadata, cancel, progress, overwrite, inputs: as for :func:`open_exporter`.
        n_frames: number of frames; defaults to ``len(frames)``.

    Raises:
        Cancelled: the cancel check fired; the finished frames were kept (see
            :mod:`spikeview.export.base`).
        ParameterError: as for :func:`open_exporter`, for a bad frame, or when ``frames`` holds a
            different number of frames than ``n_frames`` (the unfinished output is removed).
    """
    if n_frames is None:
        try:
            n_frames = len(frames)  # type: ignore[arg-type]
        except TypeError:
            raise ParameterError(f"{out}: the frames have no length (a generator?); pass n_frames=… as well.") from None
    it = iter(frames)
    first = next(it, None)
    if first is None:
        raise ParameterError(f"{out}: there are no frames to export.")
    shape = np.shape(first)
    with open_exporter(out, n_frames, shape, config, metadata, cancel=cancel, progress=progress,
                       overwrite=overwrite, inputs=inputs) as ex:
        for frame in itertools.chain([first], it):
            ex.write(frame)
        return ex.close()


def read_export_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The TOML record stored in an exported file, as a dict.

    For EXR/PNG it is the frame's record (with ``frame_index``, ``window``, ``centre_tick``); for
    MP4 the container's ``comment``; for npy the sidecar. Reproduce a frame from
    ``record["source"]``, ``record["window"]`` and ``record["params"]``.

    Raises:
        InputFileError: the file is missing or carries no spikeview record.
    """
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{path}: file not found; check the path.")
    suffix = path.suffix.lower()
    if suffix in (".exr", ".png"):
        from spikeview.export._oiio import read_record

        return read_record(path)
    if suffix == ".npy":
        from spikeview.export.npy import read_sidecar

        return read_sidecar(path)
    if suffix == ".mp4":
        import tomllib

        import av

        try:
            with av.open(str(path)) as container:
                text = container.metadata.get("comment")
        except av.error.FFmpegError as e:
            raise InputFileError(f"{path}: cannot be read as a video ({e}).") from None
        if not text:
            raise InputFileError(f"{path}: has no metadata comment; it was not exported by spikeview.")
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise InputFileError(f"{path}: its comment is not a spikeview record ({e}).") from None
    raise InputFileError(f"{path}: unknown export format {suffix!r}; pass an .exr, .png, .mp4 or .npy file.")
