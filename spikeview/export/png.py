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
        if self.config.transfer == "srgb":
            colorspace = "sRGB"
        elif self.config.transfer == "gamma":
            colorspace = f"Gamma{self.config.gamma:g}"
        else:
            colorspace = "linear"
        attrs = frame_attributes(record, self.describe(record), typed=False)
        attrs.append(("oiio:ColorSpace", "string", colorspace))
        fmt = "uint8" if bits == 8 else "uint16"
        _oiio.write_image(tmp, self.frame_path(record["frame_index"]), pixels, fmt, names, attrs)
