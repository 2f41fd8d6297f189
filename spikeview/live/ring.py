"""A bounded ring of packed frames between one acquisition thread and any number of readers.

The producer (the acquisition thread) never waits on a reader: :meth:`FrameRing.push` overwrites
the oldest frames. Readers copy out of the ring *without* holding the lock during the copy (a
1000×1000 window of 1000 ticks is 125 MB; holding the producer that long would make the device
drop data), and check afterwards that the producer did not overwrite what they copied:

* :meth:`FrameRing.latest` (the display) always gets the most recent frames, so it never falls
  behind: it skips frames instead (display frames are dropped, acquired data never is — the
  recorder is fed by the acquisition thread directly, not through the ring);
* :meth:`FrameRing.get` reads ticks ``[a, b)`` and raises :class:`RingOverrun` when they were
  overwritten (counted in :attr:`FrameRing.overruns`);
* :meth:`FrameRing.read_since` serves a reader that wants every frame (a cursor); when it falls
  more than a ring behind, the frames it missed are counted in :attr:`FrameRing.overrun_frames`.

Frames are stored packed (``frame_bytes`` each, any packing: the ring only moves bytes). Ticks are
counted from the first frame ever pushed; the ring holds ticks ``[oldest, total)``.
"""

from __future__ import annotations

import threading

import numpy as np

from spikeview.errors import ParameterError


class RingOverrun(ParameterError):
    """Ticks asked of a live stream were overwritten in its ring buffer (the message says which)."""


class FrameRing:
    """Bounded, thread-safe ring of packed frames (one producer, many readers).

    Args:
        frame_bytes: bytes of one packed frame.
        capacity: frames held (≥ 1); the oldest are overwritten first.

    Attributes:
        overruns: reads (:meth:`get`) that asked for frames already overwritten.
        overrun_frames: frames a cursor reader (:meth:`read_since`) missed because it fell more
            than a ring behind.
    """

    def __init__(self, frame_bytes: int, capacity: int):
        frame_bytes, capacity = int(frame_bytes), int(capacity)
        if frame_bytes < 1 or capacity < 1:
            raise ParameterError(f"A ring buffer needs frame_bytes ≥ 1 and capacity ≥ 1, got {frame_bytes} and {capacity}; "
                                 f"raise the buffer size.")
        self.frame_bytes = frame_bytes
        self.capacity = capacity
        self._buf = np.zeros((capacity, frame_bytes), dtype=np.uint8)
        self._lock = threading.Lock()
        self._total = 0  # frames pushed and readable
        self._reserved = 0  # frames pushed or being written (slots of frames < reserved - capacity may be overwritten)
        self.overruns = 0
        self.overrun_frames = 0

    # ------------------------------------------------------------------------------------ state
    @property
    def total(self) -> int:
        """Frames pushed so far (the tick after the newest)."""
        return self._total

    @property
    def oldest(self) -> int:
        """The oldest tick still held."""
        return max(0, self._total - self.capacity)

    def __len__(self) -> int:
        return min(self._total, self.capacity)

    # ------------------------------------------------------------------------------------ writing
    def push(self, frames: np.ndarray) -> int:
        """Append packed frames ``(n, frame_bytes)`` uint8 (never blocks on readers); returns the new total.

        Only one thread may push. When ``n`` exceeds the capacity only the last ``capacity``
        frames are stored (the others would be overwritten at once), but all ``n`` are counted.
        """
        frames = np.asarray(frames, dtype=np.uint8)
        if frames.ndim != 2 or frames.shape[1] != self.frame_bytes:
            raise ParameterError(f"push() takes packed frames of shape (n, {self.frame_bytes}), got {frames.shape}; "
                                 f"pack the frames first.")
        n = frames.shape[0]
        if n == 0:
            return self._total
        start = self._total
        end = start + n
        if n > self.capacity:
            frames = frames[-self.capacity:]
            start = end - self.capacity
        with self._lock:
            self._reserved = end  # readers that copy these slots now will notice
        i = start % self.capacity
        m = frames.shape[0]
        first = min(m, self.capacity - i)
        self._buf[i:i + first] = frames[:first]
        if first < m:
            self._buf[:m - first] = frames[first:]
        with self._lock:
            self._total = end
        return end

    # ------------------------------------------------------------------------------------ reading
    def _copy(self, a: int, b: int) -> np.ndarray:
        out = np.empty((b - a, self.frame_bytes), dtype=np.uint8)
        i = a % self.capacity
        first = min(b - a, self.capacity - i)
        out[:first] = self._buf[i:i + first]
        if first < b - a:
            out[first:] = self._buf[:b - a - first]
        return out

    def _intact(self, a: int) -> bool:
        with self._lock:
            return a >= self._reserved - self.capacity

    def get(self, a: int, b: int) -> np.ndarray:
        """Copy of the packed frames of ticks ``[a, b)``: ``(b - a, frame_bytes)`` uint8.

        Raises:
            RingOverrun: some of the ticks were overwritten (or are not there yet).
        """
        a, b = int(a), int(b)
        with self._lock:
            total, oldest = self._total, max(0, self._total - self.capacity)
        if a < oldest or b > total or a > b:
            if a < oldest:
                self._count_overrun()
            raise RingOverrun(self._gone_message(a, b, oldest, total))
        out = self._copy(a, b)
        if not self._intact(a):
            self._count_overrun()
            with self._lock:
                oldest, total = max(0, self._total - self.capacity), self._total
            raise RingOverrun(self._gone_message(a, b, oldest, total))
        return out

    def _count_overrun(self) -> None:
        with self._lock:
            self.overruns += 1

    @staticmethod
    def _gone_message(a: int, b: int, oldest: int, total: int) -> str:
        return (f"Ticks [{a}, {b}) are not in the live buffer, which now holds ticks [{oldest}, {total}): read a more "
                f"recent range, enlarge the buffer, or record to keep every tick.")

    def latest(self, window: int) -> tuple[int, np.ndarray]:
        """The most recent ``window`` frames (fewer while the ring holds fewer): ``(first_tick, frames)``.

        Never raises for lack of data and never falls behind: when the producer overwrites the
        copy meanwhile, the newest window is copied again.
        """
        window = int(window)
        if window < 0:
            raise ParameterError(f"window must be ≥ 0 ticks, got {window}; pass the number of recent ticks wanted.")
        while True:
            with self._lock:
                total = self._total
            n = min(window, total, self.capacity)
            a = total - n
            out = self._copy(a, total)
            if self._intact(a):
                return a, out

    def read_since(self, cursor: int, max_frames: int | None = None) -> tuple[int, np.ndarray]:
        """Every frame from tick ``cursor`` on (for a reader that wants them all): ``(first_tick, frames)``.

        When ``cursor`` is older than the ring, the missed frames are counted in
        :attr:`overrun_frames` and reading resumes at the oldest frame held. The next cursor is
        ``first_tick + len(frames)``.
        """
        cursor = int(cursor)
        while True:
            with self._lock:
                total, oldest = self._total, max(0, self._total - self.capacity)
            a = max(cursor, oldest)
            b = total if max_frames is None else min(total, a + int(max_frames))
            out = self._copy(a, max(a, b))
            if self._intact(a):
                if a > cursor:
                    with self._lock:
                        self.overrun_frames += a - cursor
                return a, out
            # overwritten while copying: try again from the (new) oldest frame
