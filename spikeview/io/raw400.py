"""Raw 400×250 camera streams (tagged rows of 416 bits).

A frame is 250 rows of 416 bits (52 bytes), LSB first; the last 16 bits of each row are not
pixels. Decoded at width 416, columns 400–415 dropped. Stored upside down like plain files
(``flip_vertical=True`` by default). The 1000×1000 camera's format is :mod:`spikeview.io.raw1m`.
"""

from __future__ import annotations

import os

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError
from spikeview.io._base import PackedFileSource, check_tick_rate, open_bytes, raw_writer
from spikeview.io.plain import check_frames
from spikeview.io.source import DEFAULT_TICK_RATE, StreamInfo

# ------------------------------------------------------------------------------ 400×250 layout
RAW400_WIDTH = 400
RAW400_HEIGHT = 250
RAW400_ROW_BITS = 416
RAW400_ROW_BYTES = RAW400_ROW_BITS // 8
RAW400_FRAME_BYTES = RAW400_ROW_BYTES * RAW400_HEIGHT  # 13,000


# ------------------------------------------------------------------------- 400×250 reading/writing
class Raw400Source(PackedFileSource):
    """A raw 400×250 camera stream (rows of 416 bits; the last 16 bits of each row are dropped).

    Args:
        path: the raw file.
        flip_vertical: stored rows are upside down (default ``True``, as for plain files).
        flip_horizontal: stored columns are mirrored (default ``False``).
        cfa: CFA after the flips, or ``None`` (these cameras are monochrome).
        tick_rate: readouts per second (Hz).
    """

    def __init__(self, path: str | os.PathLike[str], *, flip_vertical: bool = True, flip_horizontal: bool = False,
                 cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE):
        tick_rate = check_tick_rate(tick_rate)
        cfa = parse_cfa(cfa)
        path, buf = open_bytes(path, "raw 400x250")
        n, rem = divmod(buf.size, RAW400_FRAME_BYTES)
        if n == 0:
            raise GeometryError(f"{path}: the file ({buf.size} bytes) is smaller than one raw 400x250 frame "
                                f"({RAW400_FRAME_BYTES} bytes); check --format.")
        self._buf = buf
        self._row_bytes, self._n_rows = RAW400_ROW_BYTES, RAW400_HEIGHT
        self._segments = np.array([[0, 0, RAW400_WIDTH]], dtype=np.int64)
        warnings = []
        if rem:
            warnings.append(f"the last {rem} bytes do not fill a whole raw 400x250 frame "
                            f"({RAW400_FRAME_BYTES} bytes) and are not read.")
        self.info = StreamInfo(width=RAW400_WIDTH, height=RAW400_HEIGHT, n_frames=n, tick_rate=tick_rate, cfa=cfa,
                               format="raw400", flip_vertical=bool(flip_vertical),
                               flip_horizontal=bool(flip_horizontal), path=path, warnings=warnings)

    def _frame_offsets(self, a: int, b: int) -> np.ndarray:
        return np.arange(a, b, dtype=np.int64) * RAW400_FRAME_BYTES


def encode_raw400(frames: np.ndarray, *, flip_vertical: bool = True, flip_horizontal: bool = False) -> bytes:
    """Encode ``(T, 250, 400)`` 0/1 frames (display orientation) as a raw 400×250 stream.

    The flips are undone before packing (a :class:`Raw400Source` with the same flips reads the
    frames back); the 16 non-pixel bits at the end of each row are written as zeros.
    """
    arr = check_frames(frames, RAW400_HEIGHT, RAW400_WIDTH, "raw400")
    if flip_vertical:
        arr = arr[:, ::-1]
    if flip_horizontal:
        arr = arr[:, :, ::-1]
    rows = np.zeros((arr.shape[0], RAW400_HEIGHT, RAW400_ROW_BITS), dtype=np.uint8)
    rows[:, :, :RAW400_WIDTH] = arr
    return np.packbits(rows.reshape(arr.shape[0], -1), axis=1, bitorder="little").tobytes()


#: ``write_raw400(path, frames, *, flip_vertical=True, flip_horizontal=False, cfa=None, tick_rate, sidecar=True)``
write_raw400 = raw_writer("raw400", encode_raw400, RAW400_WIDTH, RAW400_HEIGHT, RAW400_FRAME_BYTES, flip_vertical=True,
                          doc="Write ``(T, 250, 400)`` frames as a raw 400×250 file (with its sidecar); mainly for tests and mocks.")
