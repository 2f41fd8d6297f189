"""The live ring buffer: wrap-around, overruns, the display's newest window, no torn reads."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from spikeview.live.ring import FrameRing, RingOverrun

FB = 16  # bytes per packed frame in these tests


def frames_for(ticks: range | np.ndarray) -> np.ndarray:
    """Frame of tick t: every byte is t mod 251 (a prime, so neighbours differ even after wrapping)."""
    t = np.asarray(list(ticks), dtype=np.int64)
    return np.repeat((t % 251).astype(np.uint8)[:, None], FB, axis=1)


def test_push_and_get_across_the_wrap():
    ring = FrameRing(FB, capacity=5)
    ring.push(frames_for(range(3)))
    ring.push(frames_for(range(3, 8)))  # wraps: holds ticks 3..7
    assert (ring.total, ring.oldest, len(ring)) == (8, 3, 5)
    np.testing.assert_array_equal(ring.get(3, 8), frames_for(range(3, 8)))
    np.testing.assert_array_equal(ring.get(6, 8), frames_for(range(6, 8)))
    assert ring.get(5, 5).shape == (0, FB)


def test_reading_overwritten_ticks_raises_and_counts():
    ring = FrameRing(FB, capacity=4)
    ring.push(frames_for(range(10)))
    with pytest.raises(RingOverrun, match=r"\[2, 7\).*holds ticks \[6, 10\)"):
        ring.get(2, 7)
    assert ring.overruns == 1
    with pytest.raises(RingOverrun):  # not there yet: an error, but not an overrun
        ring.get(8, 11)
    assert ring.overruns == 1


def test_push_more_than_capacity_keeps_the_newest():
    ring = FrameRing(FB, capacity=3)
    ring.push(frames_for(range(7)))
    assert ring.total == 7
    np.testing.assert_array_equal(ring.get(4, 7), frames_for(range(4, 7)))


def test_latest_is_the_newest_window():
    ring = FrameRing(FB, capacity=6)
    a, got = ring.latest(4)
    assert (a, got.shape) == (0, (0, FB))
    ring.push(frames_for(range(3)))
    a, got = ring.latest(4)  # fewer than asked while the ring fills
    assert a == 0
    np.testing.assert_array_equal(got, frames_for(range(3)))
    ring.push(frames_for(range(3, 20)))
    a, got = ring.latest(4)
    assert a == 16
    np.testing.assert_array_equal(got, frames_for(range(16, 20)))
    a, got = ring.latest(100)  # capped at what the ring holds
    assert a == 14 and got.shape[0] == 6


def test_read_since_counts_frames_missed_by_a_slow_reader():
    ring = FrameRing(FB, capacity=4)
    ring.push(frames_for(range(3)))
    a, got = ring.read_since(0)
    assert a == 0 and got.shape[0] == 3 and ring.overrun_frames == 0
    ring.push(frames_for(range(3, 10)))  # the reader at tick 3 is now 3 frames behind the oldest (6)
    a, got = ring.read_since(3)
    assert a == 6 and ring.overrun_frames == 3
    np.testing.assert_array_equal(got, frames_for(range(6, 10)))
    a, got = ring.read_since(10, max_frames=2)
    assert a == 10 and got.shape[0] == 0


def test_bad_arguments():
    with pytest.raises(ValueError, match="capacity"):
        FrameRing(FB, 0)
    ring = FrameRing(FB, 2)
    with pytest.raises(ValueError, match=r"\(n, 16\)"):
        ring.push(np.zeros((1, FB + 1), np.uint8))
    with pytest.raises(ValueError, match="window"):
        ring.latest(-1)


def test_concurrent_reads_are_never_torn():
    """A producer wraps a small ring many times while readers copy: every frame they get is the frame of its tick."""
    ring = FrameRing(FB, capacity=8)
    stop = threading.Event()
    errors: list[str] = []

    def producer() -> None:
        t = 0
        while not stop.is_set() and t < 200_000:
            ring.push(frames_for(range(t, t + 3)))
            t += 3

    def reader() -> None:
        for _ in range(3000):
            a, got = ring.latest(5)
            if not np.array_equal(got, frames_for(range(a, a + got.shape[0]))):
                errors.append(f"latest torn at {a}")
            b = ring.total
            try:
                part = ring.get(max(b - 6, 0), b)
            except RingOverrun:
                continue
            if not np.array_equal(part, frames_for(range(max(b - 6, 0), b))):
                errors.append(f"get torn at {b}")

    threads = [threading.Thread(target=producer)] + [threading.Thread(target=reader) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads[1:]:
        t.join(timeout=60)
    stop.set()
    threads[0].join(timeout=60)
    assert not any(t.is_alive() for t in threads)
    assert errors == []
    assert ring.total > 8  # the producer did wrap the ring
