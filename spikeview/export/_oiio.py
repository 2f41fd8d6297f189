"""Small OpenImageIO helpers shared by the EXR and PNG writers (imports OpenImageIO)."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from spikeview.errors import InputFileError, OutputFileError

#: attribute holding the full TOML record of a frame
CONFIG_ATTRIBUTE = "spikeview:config"

Attribute = tuple[str, str, Any]  # (name, OIIO type name, value)


def write_image(
    tmp: Path,
    final: Path,
    pixels: np.ndarray,
    pixel_format: str,
    channel_names: tuple[str, ...],
    attributes: list[Attribute],
) -> None:
    """Write ``pixels`` (``(H, W, C)``) to ``tmp`` stored as ``pixel_format`` ("half", "uint8"…).

    ``final`` is only used in error messages (the user never sees the temporary name).
    """
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, pixel_format)
    spec.channelnames = channel_names
    for name, type_name, value in attributes:
        spec.attribute(name, type_name, value)
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise OutputFileError(f"{final}: OpenImageIO cannot write this format ({oiio.geterror()}).")
    if not out.open(str(tmp), spec):
        raise _failure(final, tmp, "could not create the file", out.geterror(), pixels.nbytes)
    try:
        if not out.write_image(np.ascontiguousarray(pixels)):
            raise _failure(final, tmp, "writing failed", out.geterror(), pixels.nbytes)
    except BaseException:
        out.close()
        raise
    if not out.close():
        raise _failure(final, tmp, "finishing the file failed", out.geterror(), pixels.nbytes)


def _failure(final: Path, tmp: Path, what: str, detail: str, n_bytes: int) -> OutputFileError:
    """One sentence for a failed OpenImageIO write: a full disk said as such, never the temporary's name."""
    import shutil

    try:
        free = shutil.disk_usage(final.parent).free
    except OSError:
        free = None
    if free is not None and free < n_bytes + (1 << 16):
        return OutputFileError(f"{final}: {what}: the disk is full; free some space or choose another disk.")
    detail = " ".join(str(detail).replace(str(tmp), str(final)).replace(tmp.name, final.name).split()).rstrip(".")
    return OutputFileError(f"{final}: {what} ({detail}); check the folder and free disk space.")


def read_attributes(path: str | Path) -> dict[str, Any]:
    """All metadata attributes of an image file as ``{name: value}``."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputFileError(f"{path}: cannot be read as an image ({oiio.geterror()}); check the path.")
    try:
        return {a.name: a.value for a in inp.spec().extra_attribs}
    finally:
        inp.close()


def read_record(path: str | Path) -> dict[str, Any]:
    """The TOML record stored in the ``spikeview:config`` attribute of an exported EXR/PNG."""
    text = read_attributes(path).get(CONFIG_ATTRIBUTE)
    if not isinstance(text, str):
        raise InputFileError(f"{path}: has no {CONFIG_ATTRIBUTE} attribute; it was not exported by spikeview.")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputFileError(f"{path}: the {CONFIG_ATTRIBUTE} attribute is not valid TOML ({e}).") from None
