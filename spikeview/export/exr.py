"""OpenEXR image sequences: half float, linear light, lossless compression, full metadata.

Conventions:
    * Pixels are stored as **half** (16-bit float) in **linear** light, exactly as reconstructed
      (no levels, no clipping, no transfer curve); half keeps about 3 significant digits, so a
      value ``v`` in ``[0, 1]`` comes back within ``2**-11 · v`` (at most ``2**-11 ≈ 4.9e-4``).
    * Colour frames have channels ``R, G, B``; **mono frames a single ``Y`` channel** (the
      OpenEXR luminance convention, shown as grey by EXR viewers and a third of the size).
    * Compression ``zip`` (default), ``piz`` or ``none``; all lossless.
    * ``oiio:ColorSpace`` is ``lin_rec709`` (linear; the primaries are those of the
      reconstruction's RGB, after the colour-cast correction).
    * One file per output frame, numbered ``first_frame + index`` (see :mod:`spikeview.export`).

Metadata attributes of each file (reading them back with OpenImageIO gives these names):

=========================  ======  ============================================================
``spikeview:config``       string  TOML record of the frame: source, method, tick rate, window,
                                   centre tick, frame index, ``[params]``, ``[export]``
``spikeview:source``       string  source file
``spikeview:method``       string  reconstruction method
``spikeview:tickRate``     float   readouts per second (Hz)
``spikeview:tickStart``    int     first tick of the frame's window ``[a, b)`` (when known)
``spikeview:tickStop``     int     end tick ``b`` (exclusive, when known)
``spikeview:centreTick``   int     centre tick (when known)
``spikeview:frameIndex``   int     index of the frame in the export (0-based)
``ImageDescription``       string  one-line human summary
``Software``               string  ``spikeview <version>``
=========================  ======  ============================================================
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spikeview.export import _oiio
from spikeview.export.base import SequenceExporter


def frame_attributes(record: dict[str, Any], description: str, *, typed: bool) -> list[_oiio.Attribute]:
    """The ``spikeview:*`` attributes (plus ``ImageDescription``/``Software``) for one frame record.

    With ``typed=False`` every value is written as a string (PNG text chunks hold only text).
    """
    import tomli_w

    def attr(name: str, type_name: str, value: Any) -> _oiio.Attribute:
        return (name, type_name, value) if typed else (name, "string", str(value))

    attrs = [
        attr(_oiio.CONFIG_ATTRIBUTE, "string", tomli_w.dumps(record)),
        attr("spikeview:source", "string", record["source"]),
        attr("spikeview:method", "string", record["method"]),
        attr("spikeview:tickRate", "float", float(record["tick_rate"])),
    ]
    if "window" in record:
        attrs.append(attr("spikeview:tickStart", "int", int(record["window"][0])))
        attrs.append(attr("spikeview:tickStop", "int", int(record["window"][1])))
    if "centre_tick" in record:
        attrs.append(attr("spikeview:centreTick", "int", int(record["centre_tick"])))
    attrs.append(attr("spikeview:frameIndex", "int", int(record["frame_index"])))
    attrs.append(("ImageDescription", "string", description))
    attrs.append(("Software", "string", f"spikeview {record['spikeview_version']}"))
    return attrs


class ExrExporter(SequenceExporter):
    """Half-float linear OpenEXR files, one per frame (see module docstring)."""

    format = "exr"

    def _write_file(self, tmp: Path, frame: np.ndarray, record: dict[str, Any]) -> None:
        if self.mono:
            pixels, names = frame[:, :, None], ("Y",)
        else:
            pixels, names = frame, ("R", "G", "B")
        attrs = frame_attributes(record, self.describe(record), typed=True)
        attrs += [("compression", "string", self.config.compression), ("oiio:ColorSpace", "string", "lin_rec709")]
        # OpenImageIO converts the float32 pixels to half while writing (round to nearest)
        _oiio.write_image(tmp, self.frame_path(record["frame_index"]), pixels, "half", names, attrs)
