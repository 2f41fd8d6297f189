"""Raw 1000×1000 camera streams (tagged 64-byte half-rows).

A frame is 1000 rows of 1024 bits = 2000 blocks of 64 bytes (a half-row each), 128,000 bytes. The last 16-bit little-endian
word of each block carries a tag in its upper 12 bits: channel = bits 14–15, line = bits 4–13; its
lower 4 bits are the last 4 of the block's 500 pixels. So each half-row holds 500 pixels followed
by 12 tag bits, and a decoded row is bits ``[0:500]`` and ``[512:1012]`` of the 1024-bit row.
A frame starts at the block tagged (channel 0, line 500).

The readers synchronise on the tags: a frame is accepted only where the 2000 tags of its blocks
match :func:`raw1m_tag_sequence` (or, with ``tag_check="lenient"``, where it starts with the start
tag, every tag names a line in 1..500 and the start tag does not recur inside it). After a
corrupted or truncated frame they slide byte by byte to the next valid frame start; the skipped
bytes are counted (``info.extra["sync"]``) and reported (``info.warnings``).

Orientation of decoded raw frames differs between tools (some rotate 180°), so both flips are
settings; the 1000×1000 default is no flip (frames as stored, first stored row on top).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError, InputFileError, ParameterError
from spikeview.io._base import PackedFileSource, check_tick_rate, open_bytes, raw_writer
from spikeview.io.plain import check_frames
from spikeview.io.source import DEFAULT_TICK_RATE, StreamInfo

# ---------------------------------------------------------------------------- 1000×1000 layout
RAW1M_WIDTH = 1000
RAW1M_HEIGHT = 1000
RAW1M_HALF_PIXELS = 500
RAW1M_BLOCK_BYTES = 64
RAW1M_BLOCKS = 2 * RAW1M_HEIGHT
RAW1M_ROW_BYTES = 2 * RAW1M_BLOCK_BYTES
RAW1M_FRAME_BYTES = RAW1M_BLOCK_BYTES * RAW1M_BLOCKS  # 128,000
#: bits of the block's last word that are tag (the lower 4 are pixels)
RAW1M_TAG_MASK = 0xFFF0
#: ways of checking a candidate frame's tags
TAG_CHECKS = ("sequence", "lenient")


def raw1m_tag(channel: int, line: int) -> int:
    """The tag bits (upper 12 bits of a block's last word) for ``channel`` 0–3 and ``line`` 0–1023."""
    if not (0 <= channel <= 3 and 0 <= line <= 1023):
        raise ParameterError(f"raw1m tag needs channel 0-3 and line 0-1023, got channel {channel}, line {line}.")
    return (channel << 14) | (line << 4)


#: the tag of the block that starts a frame: channel 0, line 500
RAW1M_START_TAG = raw1m_tag(0, 500)


def raw1m_tag_sequence() -> np.ndarray:
    """The 2000 block tags of one 1000×1000 frame, in storage order: ``(2000,)`` uint16.

    Block ``k`` holds half ``k % 2`` (0 = left, pixels 0–499; 1 = right, pixels 500–999) of stored
    row ``k // 2``. The assumed tagging (**an assumption**: the public toolkits fix only the start
    tag (channel 0, line 500), the end tag (channel 3, line 500), and that channels are 0–3 and
    lines 1–500) is the one that fits those facts with 4 × 500 distinct tags:

    * rows 0–499 (top half): channel 0 (left) / 1 (right), line ``500 - row`` (500 → 1);
    * rows 500–999 (bottom half): channel 2 (left) / 3 (right), line ``row - 499`` (1 → 500).

    Everything that checks tags goes through this one function; if real captures turn out to
    differ, change it here (or open them with ``tag_check="lenient"``, which needs only the start
    tag and valid lines).
    """
    k = np.arange(RAW1M_BLOCKS)
    row, half = k // 2, k % 2
    top = row < RAW1M_HEIGHT // 2
    channel = np.where(top, half, 2 + half)
    line = np.where(top, 500 - row, row - 499)
    return ((channel << 14) | (line << 4)).astype(np.uint16)


# ------------------------------------------------------------------------- 1000×1000 encoding
def encode_raw1m(frames: np.ndarray, *, flip_vertical: bool = False, flip_horizontal: bool = False,
                 tag_sequence: np.ndarray | None = None) -> bytes:
    """Encode ``(T, 1000, 1000)`` 0/1 frames (display orientation) as a raw 1000×1000 stream.

    The flips are undone first, so :class:`Raw1MSource`/:class:`Raw1MDecoder` with the same flips
    return ``frames``. Each half-row's 500 pixels are followed by the 12 tag bits of
    ``tag_sequence`` (default :func:`raw1m_tag_sequence`).

    Returns:
        ``T × 128,000`` bytes.
    """
    arr = check_frames(frames, RAW1M_HEIGHT, RAW1M_WIDTH, "raw1m")
    tags = raw1m_tag_sequence() if tag_sequence is None else np.asarray(tag_sequence, dtype=np.uint16)
    if tags.shape != (RAW1M_BLOCKS,):
        raise ParameterError(f"tag_sequence must hold {RAW1M_BLOCKS} tags, got shape {tags.shape}.")
    if flip_vertical:
        arr = arr[:, ::-1]
    if flip_horizontal:
        arr = arr[:, :, ::-1]
    t = arr.shape[0]
    bits = np.zeros((t, RAW1M_HEIGHT, 2, RAW1M_BLOCK_BYTES * 8), dtype=np.uint8)
    bits[:, :, 0, :RAW1M_HALF_PIXELS] = arr[:, :, :RAW1M_HALF_PIXELS]
    bits[:, :, 1, :RAW1M_HALF_PIXELS] = arr[:, :, RAW1M_HALF_PIXELS:]
    blocks = np.packbits(bits.reshape(t * RAW1M_BLOCKS, -1), axis=1, bitorder="little")
    tag_rep = np.tile(tags & RAW1M_TAG_MASK, t)
    blocks[:, 62] |= (tag_rep & 0xFF).astype(np.uint8)
    blocks[:, 63] = (tag_rep >> 8).astype(np.uint8)
    return blocks.tobytes()


def decode_raw1m_frames(data: np.ndarray | bytes, *, flip_vertical: bool = False,
                        flip_horizontal: bool = False) -> np.ndarray:
    """Decode whole, already-synchronised raw 1000×1000 frames.

    Args:
        data: ``n × 128,000`` bytes, each frame starting at its (channel 0, line 500) block.

    Returns:
        ``(n, 1000, 1000)`` uint8 0/1, flips applied.
    """
    raw = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.reshape(-1)
    if raw.size % RAW1M_FRAME_BYTES:
        raise ParameterError(f"raw1m data of {raw.size} bytes is not a whole number of {RAW1M_FRAME_BYTES}-byte frames.")
    n = raw.size // RAW1M_FRAME_BYTES
    rows = np.unpackbits(raw.reshape(n, -1), axis=1, bitorder="little").reshape(n, RAW1M_HEIGHT, 2, -1)
    frames = rows[:, :, :, :RAW1M_HALF_PIXELS].reshape(n, RAW1M_HEIGHT, RAW1M_WIDTH)
    if flip_vertical:
        frames = frames[:, ::-1]
    if flip_horizontal:
        frames = frames[:, :, ::-1]
    return np.ascontiguousarray(frames)


# ------------------------------------------------------------------------ 1000×1000 synchronisation
class _TagChecker:
    """Decides whether the tags of (the first blocks of) candidate frames are right."""

    def __init__(self, tag_check: str = "sequence", tag_sequence: np.ndarray | None = None):
        if tag_check not in TAG_CHECKS:
            raise ParameterError(f"tag_check {tag_check!r} is unknown: use 'sequence' (exact tags) or 'lenient'.")
        self.mode = tag_check
        seq = raw1m_tag_sequence() if tag_sequence is None else np.asarray(tag_sequence, dtype=np.uint16)
        if seq.shape != (RAW1M_BLOCKS,):
            raise ParameterError(f"tag_sequence must hold {RAW1M_BLOCKS} tags, got shape {seq.shape}.")
        self.expected = seq & RAW1M_TAG_MASK
        self.start = int(self.expected[0]) if self.mode == "sequence" else RAW1M_START_TAG

    def ok(self, tags: np.ndarray) -> np.ndarray:
        """``(m, k)`` tags of the first ``k`` blocks of ``m`` candidates → ``(m,)`` bool."""
        k = tags.shape[1]
        if self.mode == "sequence":
            return np.all(tags == self.expected[:k], axis=1)
        line = (tags >> 4) & 0x3FF
        good = (line >= 1) & (line <= 500)
        good[:, 1:] &= tags[:, 1:] != RAW1M_START_TAG
        return (tags[:, 0] == RAW1M_START_TAG) & np.all(good, axis=1)

    def second_ok(self, tag1: np.ndarray) -> np.ndarray:
        """Quick filter on the second block's tag of many candidates."""
        if self.mode == "sequence":
            return tag1 == self.expected[1]
        line = (tag1 >> 4) & 0x3FF
        return (line >= 1) & (line <= 500) & (tag1 != RAW1M_START_TAG)


def _words(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return (lo.astype(np.uint16) | (hi.astype(np.uint16) << 8)) & RAW1M_TAG_MASK


def _frame_status(buf: np.ndarray, p: int, end: int, checker: _TagChecker) -> int:
    """1: a complete valid frame starts at ``p``; 0: it does not; -1: valid so far but incomplete before ``end``."""
    k = min(RAW1M_BLOCKS, (end - p) // RAW1M_BLOCK_BYTES)
    if k <= 0:
        return -1
    stop = p + k * RAW1M_BLOCK_BYTES
    tags = _words(buf[p + 62:stop:RAW1M_BLOCK_BYTES], buf[p + 63:stop:RAW1M_BLOCK_BYTES])
    if not checker.ok(tags[None, :])[0]:
        return 0
    return 1 if k == RAW1M_BLOCKS else -1


_SEARCH_CHUNK = 1 << 22
#: an incremental decoder waiting on a plausible frame start re-checks it after this many new bytes
_RECHECK_BYTES = 4096


def _find_start(buf: np.ndarray, lo: int, end: int, checker: _TagChecker) -> tuple[int | None, int]:
    """First ``p >= lo`` where a frame starts (complete: status 1) or may start (incomplete: -1).

    Returns ``(None, 0)`` when no position in ``[lo, end - 63)`` can start a frame.
    """
    start_lo = checker.start & 0xF0
    start_hi = checker.start >> 8
    first = lo + 62
    for s in range(first, end - 1, _SEARCH_CHUNK):
        e = min(s + _SEARCH_CHUNK, end - 1)
        lo_b = buf[s:e]
        hi_b = buf[s + 1:e + 1]
        q = np.flatnonzero((hi_b == start_hi) & ((lo_b & 0xF0) == start_lo)) + s
        if q.size == 0:
            continue
        # vectorised pre-filter on the second block's tag (where it is already in the buffer)
        q2 = q + RAW1M_BLOCK_BYTES
        have = q2 + 1 < end
        keep = ~have
        if have.any():
            qh = q2[have]
            keep[have] = checker.second_ok(_words(buf[qh], buf[qh + 1]))
        for qq in q[keep]:
            p = int(qq) - 62
            st = _frame_status(buf, p, end, checker)
            if st:
                return p, st
    return None, 0


def _run_length(buf: np.ndarray, s: int, end: int, checker: _TagChecker, batch: int = 64) -> int:
    """How many consecutive complete valid frames start at ``s``, ``s + 128000``, …"""
    count = 0
    cur = s
    while True:
        m = min(batch, (end - cur) // RAW1M_FRAME_BYTES)
        if m <= 0:
            return count
        blocks = buf[cur:cur + m * RAW1M_FRAME_BYTES].reshape(m, RAW1M_BLOCKS, RAW1M_BLOCK_BYTES)
        ok = checker.ok(_words(blocks[:, :, 62], blocks[:, :, 63]))
        if not ok.all():
            return count + int(np.argmin(ok))
        count += m
        cur += m * RAW1M_FRAME_BYTES


@dataclass
class SyncStats:
    """What synchronisation skipped (all counts in bytes unless named otherwise).

    Attributes:
        frames: complete frames found.
        leading_bytes: bytes before the first frame (a capture that starts mid-frame).
        skipped_bytes: bytes between frames that belong to no valid frame (corruption, drops).
        skipped_frames: estimated frames lost in those gaps (each gap rounded to whole frames).
        resyncs: how often synchronisation was lost and found again.
        trailing_bytes: bytes after the last complete frame.
    """

    frames: int = 0
    leading_bytes: int = 0
    skipped_bytes: int = 0
    skipped_frames: int = 0
    resyncs: int = 0
    trailing_bytes: int = 0

    def add_gap(self, gap: int) -> None:
        """Account a gap of ``gap`` bytes between two frames."""
        if gap > 0:
            self.skipped_bytes += gap
            self.skipped_frames += (gap + RAW1M_FRAME_BYTES // 2) // RAW1M_FRAME_BYTES
            self.resyncs += 1

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    def warnings(self, name: str = "") -> list[str]:
        """One sentence per kind of skipped data (empty when nothing was skipped).

        ``name`` (a file name) starts each sentence when given; a stream's ``info.warnings`` leave
        it out, since whatever shows them names the file already.
        """
        out = []
        if self.leading_bytes:
            out.append(f"{name + ': ' if name else ''}skipped {self.leading_bytes} bytes before the first complete frame "
                       f"(the capture starts mid-frame).")
        if self.skipped_bytes:
            out.append(f"{name + ': ' if name else ''}lost synchronisation {self.resyncs} time(s) and skipped {self.skipped_bytes} corrupt "
                       f"bytes (about {self.skipped_frames} frame(s)), so ticks after a gap are not evenly spaced in time.")
        if self.trailing_bytes:
            out.append(f"{name}: the last {self.trailing_bytes} bytes do not form a complete frame and are not read.")
        return out


def scan_raw1m(buf: np.ndarray, *, tag_check: str = "sequence",
               tag_sequence: np.ndarray | None = None) -> tuple[np.ndarray, SyncStats]:
    """Index the frames of a raw 1000×1000 stream held in ``buf`` (1-D uint8, e.g. a memmap).

    Vectorised over batches of frames; memory beyond the returned index is bounded by the batch
    size, so a memmap of any size is scanned without loading it.

    Returns:
        ``(offsets, stats)``: int64 byte offsets of every complete valid frame, in order, and the
        :class:`SyncStats`.
    """
    checker = _TagChecker(tag_check, tag_sequence)
    n = int(buf.size)
    stats = SyncStats()
    parts: list[np.ndarray] = []
    pos = 0
    while True:
        p, st = _find_start(buf, pos, n, checker)
        if p is None or st != 1:
            stats.trailing_bytes = n - pos if stats.frames else 0
            if not stats.frames:
                stats.leading_bytes = n
            break
        if stats.frames:
            stats.add_gap(p - pos)
        else:
            stats.leading_bytes = p - pos
        k = _run_length(buf, p, n, checker)
        parts.append(p + RAW1M_FRAME_BYTES * np.arange(k, dtype=np.int64))
        stats.frames += k
        pos = p + RAW1M_FRAME_BYTES * k
    offsets = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
    return offsets, stats


def looks_like_raw1m(buf: np.ndarray) -> bool:
    """Whether a complete tagged raw 1000×1000 frame starts within the first two frames of ``buf``."""
    end = min(int(buf.size), 3 * RAW1M_FRAME_BYTES)
    if end < RAW1M_FRAME_BYTES:
        return False
    p, st = _find_start(buf[:end], 0, end, _TagChecker())
    return p is not None and st == 1


class Raw1MSource(PackedFileSource):
    """A raw 1000×1000 camera stream, memory-mapped, with a frame index built by tag synchronisation.

    Args:
        path: the raw file.
        flip_vertical, flip_horizontal: flips applied after decoding (default none: frames as
            stored; tools disagree on the orientation of raw frames).
        cfa: CFA after the flips, or ``None``.
        tick_rate: readouts per second (Hz).
        tag_check: ``"sequence"`` (every block tag must match :func:`raw1m_tag_sequence`) or
            ``"lenient"`` (start tag, valid line numbers, no second start tag inside a frame).

    Ticks index the complete frames found; after a corrupted stretch (see ``info.warnings`` and
    ``info.extra["sync"]``) consecutive ticks are not evenly spaced in time.

    Raises:
        InputFileError: missing/empty file, or no complete tagged frame in it.
    """

    def __init__(self, path: str | os.PathLike[str], *, flip_vertical: bool = False, flip_horizontal: bool = False,
                 cfa: str | None = None, tick_rate: float = DEFAULT_TICK_RATE, tag_check: str = "sequence"):
        tick_rate = check_tick_rate(tick_rate)
        cfa = parse_cfa(cfa)
        path, buf = open_bytes(path, "raw 1000x1000")
        if buf.size < RAW1M_FRAME_BYTES:
            raise GeometryError(f"{path}: the file ({buf.size} bytes) is smaller than one raw 1000x1000 frame "
                                f"({RAW1M_FRAME_BYTES} bytes); check --format.")
        offsets, stats = scan_raw1m(buf, tag_check=tag_check)
        if offsets.size == 0:
            raise InputFileError(f"{path}: no complete raw 1000x1000 frame found (no run of 2000 blocks tagged from "
                                 f"channel 0 line 500); check --format, or try --tag-check lenient (tag_check='lenient').")
        self._buf = buf
        self._offsets = offsets
        self._row_bytes, self._n_rows = RAW1M_ROW_BYTES, RAW1M_HEIGHT
        self._segments = np.array([[0, 0, RAW1M_HALF_PIXELS], [RAW1M_BLOCK_BYTES * 8, RAW1M_HALF_PIXELS,
                                                              RAW1M_HALF_PIXELS]], dtype=np.int64)
        self.info = StreamInfo(width=RAW1M_WIDTH, height=RAW1M_HEIGHT, n_frames=int(offsets.size), tick_rate=tick_rate,
                               cfa=cfa, format="raw1m", flip_vertical=bool(flip_vertical),
                               flip_horizontal=bool(flip_horizontal), path=path, warnings=stats.warnings(),
                               extra={"sync": stats.as_dict()})

    @property
    def frame_offsets(self) -> np.ndarray:
        """Byte offset of every frame in the file (int64, read-only view)."""
        v = self._offsets.view()
        v.flags.writeable = False
        return v

    def _frame_offsets(self, a: int, b: int) -> np.ndarray:
        return self._offsets[a:b]


class Raw1MDecoder:
    """Incremental raw 1000×1000 decoder: feed byte chunks of any size, get complete frames.

    For live capture: chunks may split frames and blocks anywhere; data lost or corrupted in
    transit costs only the frames it touches. Counters (:attr:`stats`) match what
    :class:`Raw1MSource` reports for the same bytes once :meth:`finish` has been called.

    Args:
        flip_vertical, flip_horizontal: flips applied to decoded frames (see :class:`Raw1MSource`).
        tag_check: ``"sequence"`` or ``"lenient"`` (see :class:`Raw1MSource`).

    Example::

        dec = Raw1MDecoder()
        for chunk in usb_chunks:
            for frame in dec.feed(chunk):   # (1000, 1000) uint8 each
                ...
        dec.finish()
        print(dec.stats)
    """

    def __init__(self, *, flip_vertical: bool = False, flip_horizontal: bool = False, tag_check: str = "sequence"):
        self.flip_vertical = bool(flip_vertical)
        self.flip_horizontal = bool(flip_horizontal)
        self._checker = _TagChecker(tag_check)
        self.reset()

    def reset(self) -> None:
        """Forget buffered bytes and counters."""
        self._buf = bytearray()
        self._synced = False
        self._pending_gap = 0
        self._recheck_at = 0
        self._stats = SyncStats()
        self.bytes_in = 0

    @property
    def stats(self) -> SyncStats:
        """Counters so far (a copy). Bytes dropped since the last frame count as skipped only
        once a later frame confirms the gap, or as trailing after :meth:`finish`."""
        return SyncStats(**self._stats.as_dict())

    @property
    def buffered_bytes(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf) + self._pending_gap

    def feed_raw(self, data: bytes | bytearray | memoryview | np.ndarray) -> list[bytes]:
        """Add a chunk; return the complete frames it finishes as raw 128,000-byte ``bytes`` (file order)."""
        chunk = memoryview(np.ascontiguousarray(data).reshape(-1) if isinstance(data, np.ndarray) else data).cast("B")
        self.bytes_in += len(chunk)
        self._buf += chunk
        out: list[bytes] = []
        if len(self._buf) < self._recheck_at:
            return out  # still filling the frame of a plausible start: check again with more data
        self._recheck_at = 0
        arr = np.frombuffer(self._buf, dtype=np.uint8)
        n = arr.size
        pos = 0
        try:
            while True:
                if self._synced:
                    if n - pos < RAW1M_FRAME_BYTES:
                        break
                    if _frame_status(arr, pos, n, self._checker) == 1:
                        out.append(arr[pos:pos + RAW1M_FRAME_BYTES].tobytes())
                        self._stats.frames += 1
                        pos += RAW1M_FRAME_BYTES
                        continue
                    self._synced = False  # the frame at pos is corrupt: slide to the next start
                p, st = _find_start(arr, pos, n, self._checker)
                if p is None:
                    keep = max(pos, n - (RAW1M_BLOCK_BYTES - 1))  # a start tag may still arrive for these
                    self._pending_gap += keep - pos
                    pos = keep
                    break
                self._pending_gap += p - pos
                pos = p
                if st != 1:
                    # plausible start, frame not complete yet: recheck after a few more KiB
                    self._recheck_at = min(RAW1M_FRAME_BYTES, n - pos + _RECHECK_BYTES)
                    break
                if self._stats.frames:
                    self._stats.add_gap(self._pending_gap)
                else:
                    self._stats.leading_bytes += self._pending_gap
                self._pending_gap = 0
                self._synced = True
        finally:
            del arr  # release the export before resizing the bytearray
        del self._buf[:pos]
        return out

    def feed(self, data: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
        """Add a chunk; return the complete frames it finishes, decoded: ``(n, 1000, 1000)`` uint8 0/1."""
        frames = self.feed_raw(data)
        if not frames:
            return np.zeros((0, RAW1M_HEIGHT, RAW1M_WIDTH), dtype=np.uint8)
        return decode_raw1m_frames(b"".join(frames), flip_vertical=self.flip_vertical,
                                   flip_horizontal=self.flip_horizontal)

    def finish(self) -> SyncStats:
        """End of stream: bytes still held back count as trailing (or leading if no frame came). Returns :attr:`stats`."""
        rest = self._pending_gap + len(self._buf)
        if self._stats.frames:
            self._stats.trailing_bytes += rest
        else:
            self._stats.leading_bytes += rest
        self._pending_gap = 0
        self._recheck_at = 0
        self._buf = bytearray()
        self._synced = False
        return self.stats


#: ``write_raw1m(path, frames, *, flip_vertical=False, flip_horizontal=False, cfa=None, tick_rate, sidecar=True)``
write_raw1m = raw_writer("raw1m", encode_raw1m, RAW1M_WIDTH, RAW1M_HEIGHT, RAW1M_FRAME_BYTES, flip_vertical=False,
                         doc="Write ``(T, 1000, 1000)`` frames as a raw 1000×1000 file (with its sidecar); mainly for tests and mocks.")
