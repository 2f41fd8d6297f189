"""From camera bytes to packed frames: stream decoders, and ROI/decimation after decoding.

Every live source hands its ring buffer and its recorder **packed frames in stored orientation**:
``H·W/8`` bytes per frame, pixel ``p = row·W + col`` in bit ``p % 8`` of byte ``p // 8`` (the plain
``.dat`` packing, least significant bit first), rows and columns as the sensor sends them. The
source's :class:`~spikeview.io.source.StreamInfo` flips turn them into display orientation when
they are read, and a recording is a plain ``.dat`` file whose sidecar carries the same flips, so
recording never unpacks or flips anything.

* :class:`Raw1MStream` decodes the tagged 1000×1000 stream with
  :class:`~spikeview.io.raw1m.Raw1MDecoder` (resynchronises after corruption and counts what it
  skipped). Without ROI/decimation the tag bits are stripped straight on the bytes
  (:func:`raw1m_to_packed`): no unpacking. Dropped frames are *estimated* from the stray bytes
  between valid frames: the raw stream carries no frame counter, so frames lost without a trace
  (exactly ``k × 128,000`` bytes missing) cannot be counted, and a loss of that size starting
  mid-frame joins two frames into one that passes every tag check.
* :class:`PlainStream` cuts a plain packed stream into frames. Plain streams carry no tags, so
  lost bytes cannot be detected: a camera sending plain frames must not drop data.
* :class:`FrameShaper` applies the ROI, the spatial decimation and the frame step.

**ROI and decimation happen on the host, after decoding.** The full sensor (2.5 GB/s) is more
than a USB 3 link carries (about 400 MB/s in practice), so a real capture needs the camera itself
to send less; the command that sets a device-side ROI is vendor-specific and not public, so
spikeview cannot send it. What the host-side ROI/decimation saves is everything after the decoder:
ring memory, display work, recording bandwidth and disk space.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from spikeview.errors import ParameterError
from spikeview.io.raw1m import (
    RAW1M_BLOCK_BYTES,
    RAW1M_FRAME_BYTES,
    RAW1M_HEIGHT,
    RAW1M_WIDTH,
    Raw1MDecoder,
    SyncStats,
)

#: bytes of one 1000×1000 frame once the tag bits are stripped (plain packing)
RAW1M_PACKED_BYTES = RAW1M_WIDTH * RAW1M_HEIGHT // 8  # 125,000


def raw1m_to_packed(raw: np.ndarray | bytes) -> np.ndarray:
    """Strip the tag bits of synchronised raw 1000×1000 frames without unpacking them.

    Each 64-byte half-row holds 500 pixels (bits 0–499) and a tag; a plain packed row is the
    1000 pixels back to back, so the right half-row is shifted by 4 bits (500 = 62·8 + 4).

    Args:
        raw: ``n × 128,000`` bytes, each frame starting at its (channel 0, line 500) block.

    Returns:
        ``(n, 125,000)`` uint8: the frames in plain packing, stored orientation (no flips), equal
        to ``pack_frames(decode_raw1m_frames(raw), flip_vertical=False)``.
    """
    buf = np.frombuffer(raw, dtype=np.uint8) if not isinstance(raw, np.ndarray) else raw.reshape(-1)
    if buf.size % RAW1M_FRAME_BYTES:
        raise ParameterError(f"raw1m data of {buf.size} bytes is not a whole number of {RAW1M_FRAME_BYTES}-byte frames.")
    n = buf.size // RAW1M_FRAME_BYTES
    return strip_raw1m_rows(buf.reshape(n * RAW1M_HEIGHT, 2 * RAW1M_BLOCK_BYTES)).reshape(n, RAW1M_PACKED_BYTES)


def strip_raw1m_rows(rows: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Raw 1000×1000 rows ``(m, 128)`` (two tagged half-rows each) → plain packed rows ``(m, 125)`` uint8.

    One pass over the bytes (numba, compiled on first use): ten times the speed of the same
    arithmetic as numpy expressions, which made tag stripping the slowest step of live decoding.
    """
    src = np.ascontiguousarray(rows, dtype=np.uint8).reshape(-1, 2 * RAW1M_BLOCK_BYTES)
    if out is None:
        out = np.empty((src.shape[0], RAW1M_WIDTH // 8), dtype=np.uint8)
    _strip_kernel()(src, out)
    return out


_KERNEL = None


def _strip_kernel():  # numba is imported on first use (``import spikeview.live`` stays light)
    global _KERNEL
    if _KERNEL is None:
        from numba import njit

        @njit(cache=True, nogil=True)
        def strip(src, out):  # pragma: no cover - compiled
            for r in range(src.shape[0]):
                for j in range(62):  # left half-row: pixels 0-495 are whole bytes
                    out[r, j] = src[r, j]
                # byte 62: pixels 496-499 (low nibble of the left block) and 500-503 (right block)
                out[r, 62] = (src[r, 62] & 0x0F) | ((src[r, 64] << 4) & 0xFF)
                for j in range(62):  # right half-row shifted by 4 bits
                    out[r, 63 + j] = (src[r, 64 + j] >> 4) | ((src[r, 65 + j] << 4) & 0xFF)

        _KERNEL = strip
    return _KERNEL


def unpack_frames(packed: np.ndarray, height: int, width: int) -> np.ndarray:
    """Packed frames ``(n, H·W/8)`` → ``(n, H, W)`` uint8 0/1 (stored orientation)."""
    n = packed.shape[0]
    bits = np.unpackbits(packed.reshape(n, -1), axis=1, count=height * width, bitorder="little")
    return bits.reshape(n, height, width)


class FrameShaper:
    """ROI, spatial decimation and frame step, applied to decoded frames in stored orientation.

    Args:
        height, width: decoded frame size (stored orientation).
        roi: ``[top, left, height, width]`` in stored-frame pixels (rows and columns as the sensor
            sends them, before any flip), or ``None`` for the whole frame.
        decimate: keep every ``decimate``-th pixel in each direction (≥ 1). Colour sensors keep
            every ``decimate``-th 2×2 Bayer cell instead, so the output is still a Bayer mosaic.
        frame_step: keep every ``frame_step``-th frame (≥ 1); the tick rate drops accordingly.
        colour: the sensor has a CFA. Then the ROI's top, left, height and width must be even
            and the ROI size a multiple of ``2·decimate``, so the output keeps the CFA name
            (after the flips) of the full frame.

    Attributes:
        out_height, out_width: output frame size; ``out_height·out_width`` is a multiple of 8.
        frame_bytes: bytes of one packed output frame.
        identity: no ROI and no decimation (frames pass through without unpacking).
    """

    def __init__(self, height: int, width: int, *, roi: Sequence[int] | None = None, decimate: int = 1,
                 frame_step: int = 1, colour: bool = False):
        self.height, self.width = int(height), int(width)
        self.decimate, self.frame_step, self.colour = int(decimate), int(frame_step), bool(colour)
        if self.decimate < 1:
            raise ParameterError(f"decimate must be at least 1, got {decimate}; use 1 to keep every pixel.")
        if self.frame_step < 1:
            raise ParameterError(f"frame_step must be at least 1, got {frame_step}; use 1 to keep every frame.")
        if roi is None:
            top, left, h, w = 0, 0, self.height, self.width
        else:
            if len(roi) != 4:
                raise ParameterError(f"roi must be [top, left, height, width], got {list(roi)}; give four numbers.")
            top, left, h, w = (int(v) for v in roi)
            if top < 0 or left < 0 or h < 1 or w < 1 or top + h > self.height or left + w > self.width:
                raise ParameterError(f"roi {[top, left, h, w]} does not fit in the {self.width}x{self.height} frame; "
                                     f"give [top, left, height, width] inside it.")
        step = 2 * self.decimate if self.colour else self.decimate
        if self.colour and (top % 2 or left % 2):
            raise ParameterError(f"roi top and left must be even on a colour sensor (got {top}, {left}) so the Bayer "
                                 f"pattern keeps its phase; round them down to even numbers.")
        if h % step or w % step:
            what = f"2·decimate = {step}" if self.colour else f"decimate = {step}"
            raise ParameterError(f"roi size {w}x{h} is not a multiple of {what}; shrink the ROI to a multiple of {step}.")
        self.roi = (top, left, h, w)
        self.out_height, self.out_width = h // self.decimate, w // self.decimate
        if (self.out_height * self.out_width) % 8:
            raise ParameterError(f"the output frame {self.out_width}x{self.out_height} has "
                                 f"{self.out_height * self.out_width} pixels, not a multiple of 8, so it cannot be packed; "
                                 f"change the ROI or the decimation.")
        self.frame_bytes = self.out_height * self.out_width // 8
        self.identity = roi is None or (top, left, h, w) == (0, 0, self.height, self.width)
        self.identity = self.identity and self.decimate == 1
        self._rows = self._index(top, h)
        self._cols = self._index(left, w)
        if self.decimate == 1:  # slices select without a gather
            self._rows, self._cols = slice(top, top + h), slice(left, left + w)
        self._phase = 0  # frames seen modulo frame_step

    def _index(self, start: int, length: int) -> np.ndarray:
        k = np.arange(length)
        if self.colour:  # whole 2×2 cells: keep cells 0, d, 2d … (both rows/columns of each)
            keep = (k // 2) % self.decimate == 0
        else:
            keep = k % self.decimate == 0
        return start + k[keep]

    def select(self, n: int) -> np.ndarray:
        """Indices of the frames to keep among the next ``n`` frames (frame step; stateful)."""
        if self.frame_step == 1:
            return np.arange(n)
        first = (-self._phase) % self.frame_step
        self._phase = (self._phase + n) % self.frame_step
        return np.arange(first, n, self.frame_step)

    def settings(self) -> dict[str, object]:
        """The settings for a sidecar's ``[recording]`` table."""
        return {"roi": list(self.roi), "decimate": self.decimate, "frame_step": self.frame_step,
                "sensor_width": self.width, "sensor_height": self.height}

    def shape(self, frames: np.ndarray) -> np.ndarray:
        """Decoded ``(n, H, W)`` 0/1 frames (stored orientation) → packed ``(n, frame_bytes)`` output frames."""
        if not self.identity:
            if self.decimate == 1:
                frames = frames[:, self._rows, self._cols]
            else:  # take, not fancy indexing: its output is contiguous (no transposed copy)
                frames = np.take(np.take(frames, self._rows, axis=1), self._cols, axis=2)
        n = frames.shape[0]
        return np.packbits(np.ascontiguousarray(frames).reshape(n, -1), axis=1, bitorder="little")

    @property
    def rows(self) -> np.ndarray | slice:
        """Stored rows the output keeps (ROI and decimation), in order: an index array or a slice."""
        return self._rows

    def shape_rows(self, rows: np.ndarray) -> np.ndarray:
        """The kept rows (:attr:`rows`), still packed ``(n, len(rows), ceil(W/8))`` → packed output frames.

        Cheaper than :meth:`shape` for a small ROI: only its rows are unpacked.
        """
        n = rows.shape[0]
        _top, left, _h, w = self.roi
        if self.decimate == 1 and left % 8 == 0 and w % 8 == 0:  # byte-aligned columns: no unpacking at all
            return np.ascontiguousarray(rows[:, :, left // 8:(left + w) // 8]).reshape(n, -1)
        bits = np.unpackbits(rows, axis=2, count=self.width, bitorder="little")
        bits = bits[:, :, self._cols] if self.decimate == 1 else np.take(bits, self._cols, axis=2)
        return np.packbits(np.ascontiguousarray(bits).reshape(n, -1), axis=1, bitorder="little")


class Raw1MStream:
    """Tagged 1000×1000 byte stream → packed output frames (see the module docstring).

    Args:
        shaper: ROI/decimation/frame step for 1000×1000 frames.
        tag_check: ``"sequence"`` or ``"lenient"`` (see :class:`~spikeview.io.raw1m.Raw1MSource`).
    """

    height, width = RAW1M_HEIGHT, RAW1M_WIDTH

    def __init__(self, shaper: FrameShaper, tag_check: str = "sequence"):
        if (shaper.height, shaper.width) != (RAW1M_HEIGHT, RAW1M_WIDTH):
            raise ParameterError("a raw1m stream has 1000x1000 frames; build its FrameShaper for 1000x1000.")
        self.shaper = shaper
        self.decoder = Raw1MDecoder(tag_check=tag_check)

    def feed(self, chunk: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
        """Add a chunk of any size; returns the packed output frames it completes ``(k, frame_bytes)``."""
        raws = self.decoder.feed_raw(chunk)
        keep = self.shaper.select(len(raws))
        if keep.size == 0:
            return np.zeros((0, self.shaper.frame_bytes), dtype=np.uint8)
        if self.shaper.identity:  # strip the tags frame by frame, straight into the output
            out = np.empty((keep.size, RAW1M_PACKED_BYTES), dtype=np.uint8)
            for j, i in enumerate(keep):
                strip_raw1m_rows(np.frombuffer(raws[i], dtype=np.uint8).reshape(RAW1M_HEIGHT, -1),
                                 out[j].reshape(RAW1M_HEIGHT, -1))
            return out
        raw = np.frombuffer(b"".join(raws[i] for i in keep), dtype=np.uint8)
        # ROI/decimation: strip the tags of the ROI's rows only, unpack those, crop the columns
        rows = raw.reshape(keep.size, RAW1M_HEIGHT, 2 * RAW1M_BLOCK_BYTES)[:, self.shaper.rows]
        packed_rows = strip_raw1m_rows(rows.reshape(-1, 2 * RAW1M_BLOCK_BYTES)).reshape(keep.size, -1, RAW1M_WIDTH // 8)
        return self.shaper.shape_rows(packed_rows)

    @property
    def stats(self) -> SyncStats:
        """Synchronisation counters (frames, skipped bytes, estimated dropped frames, resyncs)."""
        return self.decoder.stats

    @property
    def bytes_in(self) -> int:
        return self.decoder.bytes_in

    def finish(self) -> SyncStats:
        """End of stream: what is still buffered counts as trailing bytes."""
        return self.decoder.finish()


class PlainStream:
    """Plain packed byte stream (``H·W/8`` bytes per frame, no tags) → packed output frames.

    A plain stream has nothing to synchronise on: the first byte must start a frame, and bytes
    lost in transit shift every later frame. Counters: ``frames``, and ``trailing_bytes`` after
    :meth:`finish`.
    """

    def __init__(self, shaper: FrameShaper):
        self.shaper = shaper
        self.height, self.width = shaper.height, shaper.width
        self.in_frame_bytes = self.height * self.width // 8
        if (self.height * self.width) % 8:
            raise ParameterError(f"a plain {self.width}x{self.height} frame is not a whole number of bytes; "
                                 f"check width and height.")
        self._buf = bytearray()
        self._stats = SyncStats()
        self.bytes_in = 0

    def feed(self, chunk: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
        view = memoryview(np.ascontiguousarray(chunk).reshape(-1) if isinstance(chunk, np.ndarray) else chunk).cast("B")
        self.bytes_in += len(view)
        self._buf += view
        n = len(self._buf) // self.in_frame_bytes
        if n == 0:
            return np.zeros((0, self.shaper.frame_bytes), dtype=np.uint8)
        arr = np.frombuffer(self._buf, dtype=np.uint8, count=n * self.in_frame_bytes).reshape(n, -1)
        data = arr.copy() if self.shaper.frame_step == 1 else arr[self.shaper.select(n)]
        del arr  # release the export before resizing the bytearray
        del self._buf[:n * self.in_frame_bytes]
        self._stats.frames += n
        if self.shaper.identity:
            return data
        if self.width % 8 == 0:  # byte-aligned rows: unpack only the ROI's rows
            rows = data.reshape(data.shape[0], self.height, self.width // 8)[:, self.shaper.rows]
            return self.shaper.shape_rows(rows)
        return self.shaper.shape(unpack_frames(data, self.height, self.width))

    @property
    def stats(self) -> SyncStats:
        return SyncStats(**self._stats.as_dict())

    def finish(self) -> SyncStats:
        if self._stats.frames:
            self._stats.trailing_bytes += len(self._buf)
        else:
            self._stats.leading_bytes += len(self._buf)
        self._buf = bytearray()
        return self.stats
