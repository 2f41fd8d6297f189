"""Image files and arrays as linear RGB: what the simulator's scenes are made of.

Colour: 8- and 16-bit inputs (image files, videos, integer arrays) are sRGB-encoded and are
converted to linear with the sRGB transfer function (:mod:`spikeview.transfer`); float inputs
(EXR, HDR, float arrays) are taken as linear already and clipped to ``[0, 1]``. Pass
``srgb=True``/``False`` to override. The scenes themselves are in :mod:`spikeview.sim.scenes`.
"""

from __future__ import annotations

import glob
import re
from collections.abc import Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from spikeview.errors import InputFileError
from spikeview.transfer import srgb_decode, srgb_encode

#: file extensions picked up when a folder is given as an image sequence
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".bmp", ".hdr", ".dpx", ".tga", ".webp")


# ---------------------------------------------------------------------------------------------
# colour
# ---------------------------------------------------------------------------------------------
def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in ``[0, 1]`` to linear light (IEC 61966-2-1), float32, same shape."""
    return srgb_decode(np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Linear light in ``[0, 1]`` to sRGB encoding, float32, same shape (inverse of :func:`srgb_to_linear`)."""
    return srgb_encode(np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)).astype(np.float32)


_SRGB_LUT8 = srgb_to_linear(np.arange(256, dtype=np.float32) / 255.0)


def to_linear_rgb(image: np.ndarray, srgb: bool | None = None, name: str = "image") -> np.ndarray:
    """Any image array to ``(H, W, 3)`` float32 linear RGB in ``[0, 1]``.

    Args:
        image: ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` (alpha dropped); uint8 or
            uint16 (full range), or float (``[0, 1]`` nominal, clipped).
        srgb: decode the sRGB transfer function; ``None`` decides by dtype (integers are sRGB,
            floats are linear).
        name: what to call the image in error messages.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (1, 3, 4):
        a = a[..., :3] if a.shape[2] >= 3 else np.repeat(a, 3, axis=2)
    elif a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    else:
        raise InputFileError(f"{name} has shape {a.shape}; give an (H, W) grey or (H, W, 3) colour image.")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise InputFileError(f"{name} is empty (shape {a.shape}); give an image with pixels.")
    integer = np.issubdtype(a.dtype, np.integer)
    if srgb is None:
        srgb = integer
    if a.dtype == np.uint8 and srgb:
        return _SRGB_LUT8[a]
    if integer:
        a = a.astype(np.float32) / float(np.iinfo(a.dtype).max)
    elif a.dtype == bool:
        a = a.astype(np.float32)
    else:
        a = np.nan_to_num(a.astype(np.float32), nan=0.0, posinf=1.0, neginf=0.0)
    return srgb_to_linear(a) if srgb else np.clip(a, 0.0, 1.0).astype(np.float32)


def read_image(path: str | Path, srgb: bool | None = None) -> np.ndarray:
    """Read an image file as ``(H, W, 3)`` float32 linear RGB in ``[0, 1]`` (OpenImageIO).

    Args:
        path: any format OpenImageIO reads (PNG, JPEG, TIFF, EXR, …).
        srgb: decode sRGB; ``None`` decides from the file (integer pixels or an sRGB colour space
            tag mean sRGB; float pixels are linear).

    Raises:
        InputFileError: missing or unreadable file.
    """
    path = Path(path)
    with _open_image(path) as (oiio, inp):
        spec = inp.spec()
        pixels = inp.read_image(format="float")
        if pixels is None:
            raise InputFileError(f"{path}: the image data could not be decoded ({inp.geterror()}); re-export the file.")
        if srgb is None:
            cs = str(spec.getattribute("oiio:ColorSpace") or "").lower()
            integer = spec.format.basetype not in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
            srgb = integer or "srgb" in cs and "linear" not in cs and "lin_" not in cs
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    return to_linear_rgb(pixels, srgb=srgb, name=str(path))


@contextmanager
def _open_image(path: Path) -> Iterator[tuple[Any, Any]]:
    """``(OpenImageIO, ImageInput)`` of an image file, closed on exit; :class:`InputFileError` if unreadable."""
    if not path.is_file():
        raise InputFileError(f"{path}: image file not found; check the path.")
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputFileError(f"{path}: not a readable image ({oiio.geterror() or 'unknown format'}); convert it to PNG, TIFF or EXR.")
    try:
        yield oiio, inp
    finally:
        inp.close()


def image_size(path: Path) -> tuple[int, int]:
    """(height, width) of an image file from its header."""
    with _open_image(Path(path)) as (_, inp):
        spec = inp.spec()
        return spec.height, spec.width


def _natural_key(path: Path) -> list[Any]:
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", path.name)]


def list_image_files(spec: str | Path | Sequence[str | Path]) -> list[Path]:
    """The files of an image sequence, in natural order (``frame2`` before ``frame10``).

    Args:
        spec: a folder (every file with an image extension in it), a glob pattern
            (``"shots/*.png"``) or an explicit list of files (kept in the given order).

    Raises:
        InputFileError: a missing folder or file, or nothing matching.
    """
    if isinstance(spec, (str, Path)):
        p = Path(spec)
        if p.is_dir():
            files = sorted((f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_EXTENSIONS), key=_natural_key)
            if not files:
                raise InputFileError(
                    f"{p}: the folder holds no image files ({', '.join(IMAGE_EXTENSIONS)}); point to the folder with the frames."
                )
            return files
        if glob.has_magic(str(spec)):
            files = sorted((Path(f) for f in glob.glob(str(spec)) if Path(f).is_file()), key=_natural_key)
            if not files:
                raise InputFileError(f"{spec}: no file matches this pattern; check the folder and the pattern.")
            return files
        if p.is_file():
            return [p]
        raise InputFileError(f"{p}: no such folder or file; check the path of the image sequence.")
    files = [Path(f) for f in spec]
    if not files:
        raise InputFileError("The image sequence is an empty list; give at least one image file.")
    for f in files:
        if not f.is_file():
            raise InputFileError(f"{f}: image file not found; check the path.")
    return files
