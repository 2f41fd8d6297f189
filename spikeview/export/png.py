"""PNG image sequences: display-encoded 8- or 16-bit images with the metadata as text chunks.

Conventions:
    * Pixels are the fixed display mapping of :mod:`spikeview.export.display`: levels
      ``black``/``white`` from the :class:`~spikeview.export.ExportConfig` (never automatic),
      clipped, then the sRGB curve (default; tagged with an ``sRGB``/``gAMA`` chunk by
      OpenImageIO), a pure gamma or none, rounded to 8 bits (default) or 16 bits.
    * Colour frames are RGB, **mono frames single-channel greyscale**.
    * One file per output frame, numbered ``first_frame + index`` (see :mod:`spikeview.export`).
    * Metadata: the same attribute names as the EXR files (:mod:`spikeview.export.exr`), all
      stored as ``tEXt`` text chunks (numbers as decimal text, since PNG has no typed
      metadata); ``spikeview:config`` holds the TOML record. OpenImageIO writes the text as
      UTF-8 bytes and reads it back unchanged, although the PNG standard asks for Latin-1 in
      ``tEXt``: strict readers may show non-ASCII file names garbled.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spikeview._files import os_error_sentence
from spikeview.errors import OutputFileError
from spikeview.export import _oiio
from spikeview.export.base import SequenceExporter
from spikeview.export.display import to_display
from spikeview.export.exr import frame_attributes


class PngExporter(SequenceExporter):
    """Display-encoded PNG files, one per frame (see module docstring)."""

    format = "png"

    def _write_file(self, tmp: Path, frame: np.ndarray, record: dict[str, Any]) -> None:
        bits = self.config.png_bits
        pixels = to_display(frame, self.config, bits)
        if self.mono:
            pixels, names = pixels[:, :, None], ("Y",)
        else:
            names = ("R", "G", "B")
        if self.config.curve() == "srgb":
            colorspace = "sRGB"
        elif self.config.curve() == "gamma":
            colorspace = f"Gamma{self.config.gamma:g}"
        else:
            colorspace = "linear"
        attrs = frame_attributes(record, self.describe(record), typed=False)
        attrs.append(("oiio:ColorSpace", "string", colorspace))
        fmt = "uint8" if bits == 8 else "uint16"
        final = self.frame_path(record["frame_index"])
        _oiio.write_image(tmp, final, pixels, fmt, names, attrs)
        check_png_complete(tmp, final)


#: the last 12 bytes of every complete PNG: an empty IEND chunk and its CRC
_IEND = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def check_png_complete(tmp: Path, final: Path) -> None:
    """Raise :class:`OutputFileError` unless ``tmp`` ends with the IEND chunk.

    OpenImageIO's PNG writer does not report failed writes (a full disk, a file-size limit): it
    leaves a truncated file and says it succeeded, so the end of the file is checked here.
    """
    try:
        with open(tmp, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - len(_IEND)))
            tail = f.read()
    except OSError as e:
        raise OutputFileError(f"{final}: the PNG could not be read back: {os_error_sentence(e)}.") from None
    if tail != _IEND:
        import shutil

        try:
            full = shutil.disk_usage(final.parent).free < (1 << 20)
        except OSError:
            full = False
        why = "the disk is full" if full else "the disk may be full or a file-size limit reached"
        raise OutputFileError(f"{final}: the PNG was cut short after {size} bytes: {why}; "
                              "free some space or choose another disk, then export again.")
