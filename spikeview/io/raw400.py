"""Raw 400×250 camera streams (tagged rows of 416 bits).

A frame is 250 rows of 416 bits (52 bytes), LSB first; the last 16 bits of each row are not
pixels. Decoded at width 416, columns 400–415 dropped. Stored upside down like plain files
(``flip_vertical=True`` by default). The 1000×1000 camera's format is :mod:`spikeview.io.raw1m`.

Unlike raw 1000×1000 tags, what the camera writes into the 16 non-pixel bits is not known, so a
file cannot be recognised by them. What can be checked is where the frames repeat: a plain
400×250 ``.dat`` (12,500-byte frames, no tag bits) read as raw 400×250 is 50-byte rows cut at 52
bytes, and its spikes repeat every 12,500 bytes, not every 13,000 (:func:`plain_400x250_evidence`);
such a file is refused instead of decoded as a sheared picture.
"""

from __future__ import annotations

import os

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError, InputFileError
from spikeview.io._base import PackedFileSource, check_tick_rate, open_bytes, raw_writer
from spikeview.io.plain import check_frames
from spikeview.io.source import DEFAULT_TICK_RATE, StreamInfo

# ------------------------------------------------------------------------------ 400×250 layout
RAW400_WIDTH = 400
RAW400_HEIGHT = 250
RAW400_ROW_BITS = 416
RAW400_ROW_BYTES = RAW400_ROW_BITS // 8
RAW400_FRAME_BYTES = RAW400_ROW_BYTES * RAW400_HEIGHT  # 13,000
#: bytes of a plain 400×250 frame (no tag bits): the file that is most easily mistaken for a raw one
PLAIN400_FRAME_BYTES = RAW400_WIDTH * RAW400_HEIGHT // 8  # 12,500
#: the frames must keep this many times more of the scene at 12,500 bytes than at 13,000 to count as
#: plain (raw streams keep under 0.05 times as much at 12,500; a smooth plain scene 2.2 times as much)
PLAIN400_SIGNAL_RATIO = 1.5
#: ... and at least this share of the per-byte spike count variance (Bernoulli noise: below 0.003)
PLAIN400_SIGNAL_FLOOR = 0.05


def plain_400x250_evidence(buf: np.ndarray) -> str | None:
    """Why the bytes ``buf`` are a plain 400×250 stream rather than a raw one, or ``None`` when nothing says so.

    Two measures from :mod:`spikeview.io.geometry`, each at the plain (12,500-byte) and the raw
    (13,000-byte) frame size: the integrate-and-fire signature from tick to tick
    (:func:`~spikeview.io.geometry.tick_correlation`: a pixel rarely fires on two consecutive
    ticks) and how much of the scene survives folding the stream at that size
    (:func:`~spikeview.io.geometry.frame_signal`). Either one clearly at 12,500 bytes and not at
    13,000 is evidence. Files without a scene or a signature (black, random) give none either way.
    """
    from spikeview.io.geometry import TICK_EVIDENCE, frame_signal, read_block, tick_correlation

    if buf.size < 2 * RAW400_FRAME_BYTES:
        return None
    t_plain = tick_correlation(buf, PLAIN400_FRAME_BYTES)
    t_raw = tick_correlation(buf, RAW400_FRAME_BYTES)
    if t_plain < -TICK_EVIDENCE and t_raw > 0.25 * t_plain:
        return (f"its pixels repeat every {PLAIN400_FRAME_BYTES} bytes, not every {RAW400_FRAME_BYTES} "
                f"(tick-to-tick correlation {t_plain:.2f} against {t_raw:.2f})")
    block = read_block(buf)
    s_plain = frame_signal(block, PLAIN400_FRAME_BYTES, buf)
    s_raw = frame_signal(block, RAW400_FRAME_BYTES, buf)
    if s_plain > PLAIN400_SIGNAL_RATIO * s_raw and s_plain > PLAIN400_SIGNAL_FLOOR * float(block.var()):
        return (f"its scene repeats every {PLAIN400_FRAME_BYTES} bytes, not every {RAW400_FRAME_BYTES} "
                f"(folded there it keeps {s_plain:.3g} against {s_raw:.3g} spikes² per byte)")
    return None


# ------------------------------------------------------------------------- 400×250 reading/writing
class Raw400Source(PackedFileSource):
    """A raw 400×250 camera stream (rows of 416 bits; the last 16 bits of each row are dropped).

    Args:
        path: the raw file.
        flip_vertical: stored rows are upside down (default ``True``, as for plain files).
        flip_horizontal: stored columns are mirrored (default ``False``).
        cfa: CFA after the flips, or ``None`` (these cameras are monochrome).
        tick_rate: readouts per second (Hz).
        check_layout: refuse a file whose spikes repeat at the plain 400×250 frame size
            (:func:`plain_400x250_evidence`); ``False`` reads it as raw regardless.

    Raises:
        InputFileError: the file is smaller than one frame, or is a plain 400×250 file.
    """

    def __init__(self, path: str | os.PathLike[str], *, flip_vertical: bool = True, flip_horizontal: bool = False,
                 cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE, check_layout: bool = True):
        tick_rate = check_tick_rate(tick_rate)
        cfa = parse_cfa(cfa)
        path, buf = open_bytes(path, "raw 400x250")
        n, rem = divmod(buf.size, RAW400_FRAME_BYTES)
        if n == 0:
            raise GeometryError(f"{path}: the file ({buf.size} bytes) is smaller than one raw 400x250 frame "
                                f"({RAW400_FRAME_BYTES} bytes); check --format.")
        why = plain_400x250_evidence(buf) if check_layout else None
        if why is not None:
            raise InputFileError(f"{path}: has no raw 400x250 rows of 416 bits, as {why}: it looks like a plain "
                                 f"400x250 .dat; drop --format raw400 or use --format plain.")
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
