"""Raw camera streams: 400x250 tagged rows, 1000x1000 tagged half-rows, synchronisation, incremental decoding."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import InputFileError, ParameterError
from spikeview.io import (
    Raw1MDecoder,
    Raw1MSource,
    Raw400Source,
    decode_raw1m_frames,
    encode_raw1m,
    encode_raw400,
    raw1m_tag_sequence,
)
from spikeview.io.raw1m import RAW1M_FRAME_BYTES, RAW1M_START_TAG, raw1m_tag, scan_raw1m

FRAME = RAW1M_FRAME_BYTES


@pytest.fixture(scope="module")
def frames1m() -> np.ndarray:
    rng = np.random.default_rng(2024)
    return (rng.random((4, 1000, 1000)) < 0.3).astype(np.uint8)


@pytest.fixture(scope="module")
def stream1m(frames1m) -> bytes:
    return encode_raw1m(frames1m)


def _tag_words(data: bytes, start: int = 0) -> np.ndarray:
    b = np.frombuffer(data, np.uint8)[start:start + FRAME].reshape(2000, 64)
    return (b[:, 62].astype(np.uint16) | (b[:, 63].astype(np.uint16) << 8)) & 0xFFF0


# ------------------------------------------------------------------------------- tag layout
def test_tag_sequence_facts():
    seq = raw1m_tag_sequence()
    assert seq.shape == (2000,) and seq.dtype == np.uint16
    assert len(np.unique(seq)) == 2000  # 4 channels x 500 lines, each once
    channel, line = seq >> 14, (seq >> 4) & 0x3FF
    assert (channel[0], line[0]) == (0, 500)  # frame start (SpikeCV's SPSParser)
    assert (channel[-1], line[-1]) == (3, 500)  # frame end (SpikeCV's SPSParser)
    assert set(channel.tolist()) == {0, 1, 2, 3}
    assert line.min() == 1 and line.max() == 500
    assert RAW1M_START_TAG == raw1m_tag(0, 500) == 500 << 4
    with pytest.raises(ParameterError):
        raw1m_tag(4, 1)


def test_encoded_bytes_have_the_documented_layout():
    frame = np.zeros((1, 1000, 1000), np.uint8)
    frame[0, 0, 0] = 1  # row 0, left half, pixel 0 -> byte 0 bit 0
    frame[0, 0, 499] = 1  # last pixel of the left half: bit 499 = byte 62 bit 3 (below the tag)
    frame[0, 0, 500] = 1  # first pixel of the right half: block 1 -> byte 64 bit 0
    frame[0, 1, 3] = 1  # row 1 -> block 2 (byte 128), bit 3
    data = encode_raw1m(frame)
    assert len(data) == FRAME
    raw = np.frombuffer(data, np.uint8)
    assert raw[0] == 0b1 and raw[64] == 0b1 and raw[128] == 0b1000
    assert raw[62] & 0x0F == 0b1000
    np.testing.assert_array_equal(_tag_words(data), raw1m_tag_sequence())
    # pixel bits 500..511 of each half-row are tag bits, never pixels
    np.testing.assert_array_equal(decode_raw1m_frames(data), frame)


# ---------------------------------------------------------------------------- 1000x1000 reader
@pytest.mark.parametrize("flip_v, flip_h", [(False, False), (True, False), (True, True)])
def test_raw1m_round_trip_and_count(tmp_path, frames1m, flip_v, flip_h):
    path = tmp_path / "cap.raw"
    path.write_bytes(encode_raw1m(frames1m, flip_vertical=flip_v, flip_horizontal=flip_h))
    with Raw1MSource(path, flip_vertical=flip_v, flip_horizontal=flip_h) as src:
        assert src.shape == (4, 1000, 1000) and src.info.format == "raw1m"
        np.testing.assert_array_equal(src.read(1, 3), frames1m[1:3])
        np.testing.assert_array_equal(src.count(0, 4), frames1m.sum(axis=0))
        assert src.info.warnings == []
        assert src.info.extra["sync"] == {"frames": 4, "leading_bytes": 0, "skipped_bytes": 0, "skipped_frames": 0,
                                          "resyncs": 0, "trailing_bytes": 0}


def test_flip_settings_change_orientation(tmp_path, frames1m, stream1m):
    path = tmp_path / "o.raw"
    path.write_bytes(stream1m)
    np.testing.assert_array_equal(Raw1MSource(path, flip_vertical=True).read(0, 1)[0], frames1m[0, ::-1])


def test_sync_from_random_offset(tmp_path, frames1m, stream1m):
    rng = np.random.default_rng(5)
    for _ in range(3):
        lead = int(rng.integers(1, FRAME))
        # starting mid-stream: the tail of a previous frame (real tags and pixels) comes first
        data = stream1m[FRAME - lead:FRAME] + stream1m[FRAME:]
        path = tmp_path / "mid.raw"
        path.write_bytes(data)
        src = Raw1MSource(path)
        assert src.n_frames == 3
        assert src.info.extra["sync"]["leading_bytes"] == lead
        np.testing.assert_array_equal(src.read(0, 3), frames1m[1:])
        assert any(f"skipped {lead} bytes before the first" in w for w in src.info.warnings)


def test_resync_after_corrupted_tag_and_dropped_bytes(tmp_path, frames1m, stream1m):
    data = bytearray(stream1m)
    data[FRAME + 64 * 700 + 63] ^= 0x40  # corrupt one tag in frame 1 -> frame 1 is skipped
    drop_at, drop_n = 2 * FRAME + 5000, 1000  # lose 1000 bytes inside frame 2 -> frame 2 is skipped
    del data[drop_at:drop_at + drop_n]
    data += stream1m[:777]  # a truncated frame at the end
    path = tmp_path / "bad.raw"
    path.write_bytes(bytes(data))
    src = Raw1MSource(path)
    np.testing.assert_array_equal(src.read(0, src.n_frames), frames1m[[0, 3]])
    sync = src.info.extra["sync"]
    assert sync == {"frames": 2, "leading_bytes": 0, "skipped_bytes": FRAME + FRAME - drop_n, "skipped_frames": 2,
                    "resyncs": 1, "trailing_bytes": 777}
    text = " ".join(src.info.warnings)
    assert "lost synchronisation 1 time(s)" in text and f"skipped {2 * FRAME - drop_n} corrupt bytes" in text
    assert "last 777 bytes" in text
    np.testing.assert_array_equal(src.frame_offsets, [0, 3 * FRAME - drop_n])
    np.testing.assert_array_equal(src.count(0, 2), frames1m[[0, 3]].sum(axis=0))


def test_inserted_garbage_is_skipped_without_losing_frames(tmp_path, frames1m, stream1m):
    rng = np.random.default_rng(9)
    junk = rng.integers(0, 256, 3001, dtype=np.uint8).tobytes()
    path = tmp_path / "ins.raw"
    path.write_bytes(stream1m[:2 * FRAME] + junk + stream1m[2 * FRAME:])
    src = Raw1MSource(path)
    np.testing.assert_array_equal(src.read(0, 4), frames1m)
    assert src.info.extra["sync"]["skipped_bytes"] == 3001
    assert src.info.extra["sync"]["skipped_frames"] == 0  # nothing lost, only garbage
    assert src.info.extra["sync"]["resyncs"] == 1


def test_no_frame_is_a_clear_error(tmp_path):
    rng = np.random.default_rng(1)
    path = tmp_path / "noise.raw"
    path.write_bytes(rng.integers(0, 256, FRAME + 100, dtype=np.uint8).tobytes())
    with pytest.raises(InputFileError, match="noise.raw.*no complete raw 1000x1000 frame"):
        Raw1MSource(path)
    small = tmp_path / "small.raw"
    small.write_bytes(b"\x00" * 100)
    with pytest.raises(InputFileError, match="smaller than one raw 1000x1000 frame"):
        Raw1MSource(small)
    with pytest.raises(ParameterError, match="tag_check"):
        Raw1MSource(path, tag_check="loose")


def test_lenient_tag_check_accepts_another_tag_order(tmp_path, frames1m):
    seq = raw1m_tag_sequence()
    other = np.concatenate([seq[:1], seq[1:][::-1]])  # same start tag, different order
    path = tmp_path / "alt.raw"
    path.write_bytes(encode_raw1m(frames1m[:2], tag_sequence=other))
    with pytest.raises(InputFileError):
        Raw1MSource(path)  # exact sequence check
    src = Raw1MSource(path, tag_check="lenient")
    np.testing.assert_array_equal(src.read(0, 2), frames1m[:2])


# ------------------------------------------------------------------------------ incremental
def test_decoder_random_chunks_matches_file_scan(tmp_path, frames1m, stream1m):
    rng = np.random.default_rng(77)
    data = bytearray(rng.integers(0, 256, 4321, dtype=np.uint8).tobytes()) + stream1m
    data[4321 + FRAME + 64 * 3 + 62] ^= 0x10  # corrupt frame 1
    data += stream1m[:FRAME // 2]
    data = bytes(data)
    path = tmp_path / "inc.raw"
    path.write_bytes(data)
    src = Raw1MSource(path)
    expected = src.read(0, src.n_frames)
    for trial in range(2):
        dec = Raw1MDecoder()
        got, pos = [], 0
        while pos < len(data):
            n = int(rng.integers(1, 3 * FRAME // 2)) if trial else int(rng.integers(1, 5000))
            got.append(dec.feed(data[pos:pos + n]))
            pos += n
        stats = dec.finish()
        got = np.concatenate(got)
        np.testing.assert_array_equal(got, expected)
        assert stats.as_dict() == src.info.extra["sync"]
        assert dec.bytes_in == len(data)
    assert src.info.extra["sync"]["leading_bytes"] == 4321


def test_decoder_raw_frames_and_flips(frames1m, stream1m):
    dec = Raw1MDecoder(flip_vertical=True)
    raws = dec.feed_raw(stream1m[:FRAME + 10])
    assert raws == [stream1m[:FRAME]]
    assert dec.buffered_bytes == 10
    out = dec.feed(np.frombuffer(stream1m[FRAME + 10:2 * FRAME], np.uint8))
    np.testing.assert_array_equal(out, frames1m[1:2, ::-1])
    assert dec.stats.frames == 2
    dec.reset()
    assert dec.stats.frames == 0 and dec.buffered_bytes == 0


def test_scan_matches_offsets(stream1m):
    buf = np.frombuffer(b"\x07" * 99 + stream1m, np.uint8)
    offsets, stats = scan_raw1m(buf)
    np.testing.assert_array_equal(offsets, 99 + FRAME * np.arange(4))
    assert stats.leading_bytes == 99 and stats.frames == 4


# ------------------------------------------------------------------------------ 400x250 reader
def test_raw400_round_trip_ignores_tag_columns(tmp_path):
    rng = np.random.default_rng(4)
    frames = (rng.random((5, 250, 400)) < 0.4).astype(np.uint8)
    data = np.frombuffer(encode_raw400(frames), np.uint8).copy().reshape(5, 250, 52)
    assert data[:, :, 50:].max() == 0  # bits 400..415 of each row are not pixels
    data[:, :, 50:] = rng.integers(0, 256, (5, 250, 2), dtype=np.uint8)  # whatever the camera puts there
    path = tmp_path / "c.raw"
    path.write_bytes(data.tobytes() + b"\x01\x02\x03")
    src = Raw400Source(path)
    assert src.shape == (5, 250, 400) and src.info.flip_vertical
    np.testing.assert_array_equal(src.read(0, 5), frames)
    np.testing.assert_array_equal(src.count(1, 5), frames[1:].sum(axis=0))
    assert "last 3 bytes" in src.info.warnings[0]


def test_raw400_bit_positions(tmp_path):
    frame = np.zeros((1, 250, 400), np.uint8)
    frame[0, 0, 9] = 1  # top row; stored upside down -> stored row 249 -> byte 249*52 + 1, bit 1
    data = np.frombuffer(encode_raw400(frame), np.uint8)
    assert np.flatnonzero(data).tolist() == [249 * 52 + 1] and data[249 * 52 + 1] == 0b10
    path = tmp_path / "bit.raw"
    path.write_bytes(data.tobytes())
    src = Raw400Source(path, flip_vertical=False, flip_horizontal=True)
    assert list(zip(*np.nonzero(src.read(0, 1)[0]))) == [(249, 400 - 1 - 9)]
