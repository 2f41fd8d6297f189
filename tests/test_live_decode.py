"""Live decoding: tag stripping on the bytes, ROI/decimation/frame step, chunked stream decoders."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import ParameterError
from spikeview.io import decode_raw1m_frames, encode_raw1m, pack_frames
from spikeview.live.decode import FrameShaper, PlainStream, Raw1MStream, raw1m_to_packed, unpack_frames


@pytest.fixture(scope="module")
def frames() -> np.ndarray:
    rng = np.random.default_rng(5)
    return rng.integers(0, 2, (3, 1000, 1000), dtype=np.uint8)


def test_raw1m_to_packed_matches_unpack_then_pack(frames):
    raw = encode_raw1m(frames)
    got = raw1m_to_packed(raw)
    want = pack_frames(decode_raw1m_frames(raw), flip_vertical=False)
    assert got.shape == (3, 125_000)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(unpack_frames(got, 1000, 1000), frames)


def test_raw1m_to_packed_rejects_partial_frames():
    with pytest.raises(ParameterError, match="whole number"):
        raw1m_to_packed(np.zeros(1000, np.uint8))


def test_shaper_roi_and_decimation_mono():
    rng = np.random.default_rng(1)
    x = rng.integers(0, 2, (2, 40, 48), dtype=np.uint8)
    s = FrameShaper(40, 48, roi=[4, 8, 32, 24], decimate=2)
    assert (s.out_height, s.out_width, s.identity) == (16, 12, False)
    got = unpack_frames(s.shape(x), 16, 12)
    np.testing.assert_array_equal(got, x[:, 4:36:2, 8:32:2])


def test_shaper_decimation_keeps_bayer_cells():
    rng = np.random.default_rng(2)
    x = rng.integers(0, 2, (1, 16, 16), dtype=np.uint8)
    s = FrameShaper(16, 16, decimate=2, colour=True)
    got = unpack_frames(s.shape(x), 8, 8)[0]
    rows = np.array([0, 1, 4, 5, 8, 9, 12, 13])  # cells 0, 2, 4, 6: both rows of each
    np.testing.assert_array_equal(got, x[0][rows][:, rows])


@pytest.mark.parametrize("kwargs, match", [
    ({"roi": [1, 0, 8, 8], "colour": True}, "even"),
    ({"roi": [0, 0, 6, 8], "decimate": 2, "colour": True}, "multiple of 4"),
    ({"roi": [0, 0, 3, 3]}, "multiple of 8"),
    ({"roi": [10, 0, 16, 8]}, "does not fit"),
    ({"decimate": 0}, "at least 1"),
    ({"frame_step": 0}, "at least 1"),
])
def test_shaper_rejects_settings_with_a_fix(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        FrameShaper(16, 16, **kwargs)


def test_frame_step_is_continuous_across_chunks():
    s = FrameShaper(8, 8, frame_step=3)
    picked = [i for n, base in ((2, 0), (4, 2), (5, 6)) for i in (base + s.select(n)).tolist()]
    assert picked == [0, 3, 6, 9]


def test_raw1m_stream_in_odd_chunks_with_frame_step(frames):
    raw = encode_raw1m(frames)
    stream = Raw1MStream(FrameShaper(1000, 1000, frame_step=2))
    out = [stream.feed(raw[i:i + 77_777]) for i in range(0, len(raw), 77_777)]
    got = np.concatenate(out)
    np.testing.assert_array_equal(got, pack_frames(frames[::2], flip_vertical=False))
    assert stream.stats.frames == 3


def test_raw1m_stream_with_roi(frames):
    raw = encode_raw1m(frames[:1])
    stream = Raw1MStream(FrameShaper(1000, 1000, roi=[10, 500, 16, 32]))
    got = unpack_frames(stream.feed(raw), 16, 32)
    np.testing.assert_array_equal(got, frames[:1, 10:26, 500:532])


def test_plain_stream_cuts_frames_and_reports_the_rest():
    rng = np.random.default_rng(3)
    x = rng.integers(0, 2, (5, 16, 24), dtype=np.uint8)
    data = pack_frames(x, flip_vertical=True).tobytes() + b"\x01\x02\x03"
    stream = PlainStream(FrameShaper(16, 24))
    got = np.concatenate([stream.feed(data[i:i + 50]) for i in range(0, len(data), 50)])
    np.testing.assert_array_equal(got, pack_frames(x, flip_vertical=True))
    assert stream.finish().trailing_bytes == 3


@pytest.mark.parametrize("width", [24, 20])  # byte-aligned rows (only ROI rows unpacked) and not
def test_plain_stream_with_roi(width):
    rng = np.random.default_rng(width)
    x = rng.integers(0, 2, (3, 10, width), dtype=np.uint8)
    stream = PlainStream(FrameShaper(10, width, roi=[2, 4, 4, 12]))
    got = unpack_frames(stream.feed(pack_frames(x, flip_vertical=False)), 4, 12)
    np.testing.assert_array_equal(got, x[:, 2:6, 4:16])
