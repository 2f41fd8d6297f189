"""Plain packed .dat files: bit order, flips, round trips, partial frames, fast counting."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import GeometryError, InputFileError, ParameterError, SpikeviewError
from spikeview.io import PlainDatSource, PlainDatWriter, pack_frames, read_sidecar, write_plain
from spikeview.io.source import SpikeSource


def _spikes(rng: np.random.Generator, t: int, h: int, w: int, p: float = 0.3) -> np.ndarray:
    return (rng.random((t, h, w)) < p).astype(np.uint8)


def _reference_count(spikes: np.ndarray, a: int, b: int) -> np.ndarray:
    return spikes[a:b].sum(axis=0, dtype=np.int64)


# ----------------------------------------------------------------------------- conventions
@pytest.mark.parametrize(
    "flip_v, flip_h, expected",
    [
        # byte 5, bit 2 -> stored pixel 5*8+2 = 42 -> stored (row 2, col 10) of a 16-wide frame
        (False, False, (2, 10)),
        (True, False, (8 - 1 - 2, 10)),  # rows stored upside down: row 2 of 8 is displayed at row 5
        (False, True, (2, 16 - 1 - 10)),
        (True, True, (5, 5)),
    ],
)
def test_single_bit_lands_at_the_documented_pixel(tmp_path, flip_v, flip_h, expected):
    data = bytearray(16)  # one 16x8 frame
    data[5] = 0b0000_0100
    path = tmp_path / "one.dat"
    path.write_bytes(bytes(data))
    with PlainDatSource(path, 16, 8, flip_vertical=flip_v, flip_horizontal=flip_h) as src:
        frame = src.read(0, 1)[0]
        count = src.count(0, 1)
    assert frame.dtype == np.uint8 and frame.shape == (8, 16)
    assert list(zip(*np.nonzero(frame))) == [expected]
    assert list(zip(*np.nonzero(count))) == [expected]


def test_lsb_first_bit_order(tmp_path):
    # 0x01 in byte 0 is stored pixel 0 (LSB first); MSB first would put it at column 7
    path = tmp_path / "lsb.dat"
    path.write_bytes(bytes([0x01, 0x80]) + bytes(6))  # 8x8 frame, 8 bytes
    frame = PlainDatSource(path, 8, 8, flip_vertical=False).read(0, 1)[0]
    assert frame[0, 0] == 1 and frame[0, 7] == 0
    assert frame[1, 7] == 1 and frame[1, 0] == 0  # 0x80 in byte 1 is stored pixel 15 = (row 1, col 7)
    assert frame.sum() == 2


def test_default_is_vertical_flip(tmp_path):
    path = tmp_path / "top.dat"
    path.write_bytes(bytes([0xFF]) + bytes(7))  # first stored row all ones
    src = PlainDatSource(path, 8, 8)
    assert src.info.flip_vertical is True
    np.testing.assert_array_equal(src.read(0, 1)[0, 7], np.ones(8, np.uint8))  # shown at the bottom
    assert src.read(0, 1)[0, :7].sum() == 0


def test_pack_frames_matches_hand_built_bytes():
    frame = np.zeros((1, 8, 16), np.uint8)
    frame[0, 5, 10] = 1  # display (5, 10) with the default flip is stored (2, 10) = pixel 42
    packed = pack_frames(frame)
    expected = np.zeros(16, np.uint8)
    expected[5] = 0b0000_0100
    np.testing.assert_array_equal(packed[0], expected)


# ------------------------------------------------------------------------------ round trips
@pytest.mark.parametrize("flip_v, flip_h", [(True, False), (False, False), (True, True), (False, True)])
@pytest.mark.parametrize("shape", [(23, 16, 24), (5, 10, 12), (3, 64, 64)])  # 12x10: rows not byte aligned
def test_write_read_round_trip_is_exact(tmp_path, shape, flip_v, flip_h):
    rng = np.random.default_rng(7)
    spikes = _spikes(rng, *shape)
    path = write_plain(tmp_path / "s.dat", spikes, flip_vertical=flip_v, flip_horizontal=flip_h, cfa="GRBG")
    assert path.stat().st_size == shape[0] * shape[1] * shape[2] // 8
    with PlainDatSource(path, shape[2], shape[1], flip_vertical=flip_v, flip_horizontal=flip_h, cfa="GRBG") as src:
        np.testing.assert_array_equal(src.read(0, shape[0]), spikes)
        np.testing.assert_array_equal(src.read(1, 3), spikes[1:3])
        np.testing.assert_array_equal(src.count(1, shape[0]), spikes[1:].sum(0))
        assert src.cfa == "GRBG"
    side = read_sidecar(path)
    assert side is not None and side.stream is not None
    assert (side.stream.format, side.stream.width, side.stream.height) == ("plain", shape[2], shape[1])
    assert (side.stream.flip_vertical, side.stream.flip_horizontal, side.stream.cfa) == (flip_v, flip_h, "GRBG")


def test_bool_input_and_rejects_non_binary(tmp_path):
    rng = np.random.default_rng(1)
    spikes = rng.random((4, 8, 8)) < 0.5
    path = write_plain(tmp_path / "b.dat", spikes, sidecar=False)
    np.testing.assert_array_equal(PlainDatSource(path, 8, 8).read(0, 4), spikes.astype(np.uint8))
    assert not (tmp_path / "b.dat.toml").exists()
    with pytest.raises(ParameterError, match="other than 0 and 1"):
        write_plain(tmp_path / "c.dat", spikes.astype(np.uint8) * 2)
    with pytest.raises(ParameterError, match="dtype"):
        write_plain(tmp_path / "c.dat", spikes.astype(np.float32))
    assert not (tmp_path / "c.dat").exists()


def test_streaming_writer_frames_and_packed_bytes(tmp_path):
    rng = np.random.default_rng(3)
    spikes = _spikes(rng, 12, 16, 16)
    path = tmp_path / "rec.dat"
    with PlainDatWriter(path, 16, 16, cfa="BGGR", extra_tables={"recording": {"dropped": 0}}) as wr:
        wr.write(spikes[:5])
        wr.write(spikes[5])  # a single (H, W) frame
        wr.write_packed(pack_frames(spikes[6:10]).tobytes())
        wr.write_packed(pack_frames(spikes[10:]))
        wr.set_table("recording", {"dropped": 3, "frames": 12})
        assert wr.n_frames == 12
        with pytest.raises(ParameterError, match="whole number"):
            wr.write_packed(b"\x00" * 5)
        with pytest.raises(ParameterError, match="16x16"):
            wr.write(spikes[:, :8])
    wr.close()  # twice is fine
    with pytest.raises(ParameterError, match="closed"):
        wr.write(spikes[:1])
    np.testing.assert_array_equal(PlainDatSource(path, 16, 16).read(0, 12), spikes)
    side = read_sidecar(path)
    assert side.stream.cfa == "BGGR" and side.tables["recording"] == {"dropped": 3, "frames": 12}


def test_writer_append(tmp_path):
    rng = np.random.default_rng(4)
    spikes = _spikes(rng, 6, 8, 8)
    path = tmp_path / "app.dat"
    with PlainDatWriter(path, 8, 8) as wr:
        wr.write(spikes[:2])
    with PlainDatWriter(path, 8, 8, append=True) as wr:
        assert wr.n_frames == 2
        wr.write(spikes[2:])
    np.testing.assert_array_equal(PlainDatSource(path, 8, 8).read(0, 6), spikes)


def test_writer_missing_folder_is_an_error(tmp_path):
    with pytest.raises(SpikeviewError, match="folder does not exist"):
        PlainDatWriter(tmp_path / "nope" / "x.dat", 8, 8)


# ------------------------------------------------------------------------------ bad inputs
def test_trailing_partial_frame_is_reported(tmp_path):
    path = tmp_path / "p.dat"
    path.write_bytes(bytes(16 * 3 + 5))  # three 16x8 frames + 5 bytes
    src = PlainDatSource(path, 16, 8)
    assert src.n_frames == 3
    assert len(src.info.warnings) == 1
    assert "last 5 bytes" in src.info.warnings[0] and "p.dat" not in src.info.warnings[0]  # shown beside the name


def test_errors_name_the_file(tmp_path):
    empty = tmp_path / "empty.dat"
    empty.write_bytes(b"")
    with pytest.raises(InputFileError, match="empty.dat.*empty"):
        PlainDatSource(empty, 8, 8)
    small = tmp_path / "small.dat"
    small.write_bytes(bytes(7))
    with pytest.raises(InputFileError, match="small.dat.*smaller than one 8x8 frame"):
        PlainDatSource(small, 8, 8)
    odd = tmp_path / "odd.dat"
    odd.write_bytes(bytes(100))
    with pytest.raises(GeometryError, match="odd.dat.*not a multiple of 8"):
        PlainDatSource(odd, 5, 3)
    with pytest.raises(InputFileError, match="not found"):
        PlainDatSource(tmp_path / "missing.dat", 8, 8)
    with pytest.raises(InputFileError, match="folder"):
        PlainDatSource(tmp_path, 8, 8)
    with pytest.raises(ParameterError, match="width"):
        PlainDatSource(small, 0, 8)


def test_read_after_close_and_range_errors(tmp_path):
    path = write_plain(tmp_path / "c.dat", np.zeros((3, 8, 8), np.uint8))
    src = PlainDatSource(path, 8, 8)
    with pytest.raises(ParameterError, match=r"\[0, 3\)"):
        src.read(2, 4)
    src.close()
    with pytest.raises(ParameterError, match="closed"):
        src.read(0, 1)
    with pytest.raises(ParameterError, match="closed"):
        src.count(0, 1)


# ---------------------------------------------------------------------------- fast counting
@pytest.fixture(params=[1, 2], ids=["1thread", "2threads"])
def threads(request):
    from spikeview.io import _packed

    _packed.set_threads(request.param)
    yield request.param
    _packed.set_threads(None)


@pytest.mark.parametrize("flip_v, flip_h", [(True, False), (False, True)])
def test_fast_count_equals_unpack_and_sum(tmp_path, threads, flip_v, flip_h):
    rng = np.random.default_rng(11)
    spikes = _spikes(rng, 600, 24, 32, p=0.4)
    path = write_plain(tmp_path / "f.dat", spikes, flip_vertical=flip_v, flip_horizontal=flip_h)
    src = PlainDatSource(path, 32, 24, flip_vertical=flip_v, flip_horizontal=flip_h)
    # edges, tiny windows, the 15/16 and 255/256 boundaries of the bit-plane kernel, several passes
    ranges = [(0, 1), (599, 600), (0, 600), (5, 5), (3, 18), (3, 19), (10, 265), (10, 266), (0, 511)]
    ranges += [tuple(sorted(rng.integers(0, 601, 2))) for _ in range(8)]
    for a, b in ranges:
        got = src.count(a, b)
        assert got.shape == (24, 32) and got.dtype == np.uint16
        np.testing.assert_array_equal(got, _reference_count(spikes, a, b), err_msg=f"[{a}, {b})")
        assert SpikeSource.count(src, a, b).tolist() == got.tolist()  # the generic unpack-and-sum path


def test_count_windows_matches_count(tmp_path, threads):
    rng = np.random.default_rng(12)
    spikes = _spikes(rng, 103, 16, 40)
    path = write_plain(tmp_path / "w.dat", spikes)
    src = PlainDatSource(path, 40, 16)
    got = src.count_windows(3, 103, 10)
    assert got.shape == (10, 16, 40)
    expected = spikes[3:103].reshape(10, 10, 16, 40).sum(axis=1)
    np.testing.assert_array_equal(got, expected)
    out = np.empty((9, 16, 40), np.uint16)
    res = src.count_windows(0, 99, 11, out=out)  # the 0-tick remainder case; reuses ``out``
    assert res is out
    np.testing.assert_array_equal(out, spikes[:99].reshape(9, 11, 16, 40).sum(axis=1))
    assert src.count_windows(0, 7, 10).shape == (0, 16, 40)  # no whole window fits
    with pytest.raises(ParameterError, match="window"):
        src.count_windows(0, 10, 0)
    # the generic SpikeSource implementation gives the same (trailing ticks left out)
    np.testing.assert_array_equal(SpikeSource.count_windows(src, 3, 100, 10), expected[:9])


def test_count_unaligned_rows_and_long_windows_use_uint32(tmp_path):
    rng = np.random.default_rng(13)
    spikes = _spikes(rng, 70_000, 2, 4, p=0.5)  # 1 byte per frame, rows of 4 bits
    spikes[:, 1, 2] = 1  # 70,000 spikes: more than uint16 holds
    path = write_plain(tmp_path / "long.dat", spikes, flip_vertical=True)
    src = PlainDatSource(path, 4, 2)
    got = src.count(0, 70_000)
    assert got.dtype == np.uint32  # more than 65,535 ticks
    np.testing.assert_array_equal(got, spikes.sum(axis=0))
    assert got.max() > 65_535  # the value would have wrapped in uint16
    np.testing.assert_array_equal(src.count(100, 400), spikes[100:400].sum(0))


def test_count_kernel_random_layouts_match_reference(threads):
    """Random row sizes, unaligned frame offsets, column segments, flips, 0..600 frames per window."""
    from spikeview.io._packed import count_frames

    rng = np.random.default_rng(99)
    for trial in range(12):
        row_bytes, n_rows = int(rng.integers(1, 20)), int(rng.integers(1, 40))
        fb = row_bytes * n_rows
        buf = rng.integers(0, 256, fb * 50 + 13, dtype=np.uint8)
        offsets = rng.integers(0, buf.size - fb + 1, size=(int(rng.integers(1, 4)), int(rng.integers(0, 600))))
        w_store = row_bytes * 8
        cut = int(rng.integers(1, w_store + 1))
        if cut < w_store - 2:  # drop one column, like the raw formats drop their tag bits
            segs, width = np.array([[0, 0, cut], [cut + 1, cut, w_store - cut - 1]]), w_store - 1
        else:
            segs, width = np.array([[0, 0, cut]]), cut
        fv, fh = bool(trial % 2), bool(trial // 2 % 2)
        got = count_frames(buf, offsets, row_bytes=row_bytes, n_rows=n_rows, segments=segs, width=width,
                           flip_vertical=fv, flip_horizontal=fh)
        for w in range(offsets.shape[0]):
            total = np.zeros((n_rows, w_store), np.int64)
            for o in offsets[w]:
                total += np.unpackbits(buf[o:o + fb], bitorder="little").reshape(n_rows, w_store)
            exp = np.concatenate([total[:, s:s + n] for s, _, n in segs], axis=1)
            exp = exp[::-1] if fv else exp
            exp = exp[:, ::-1] if fh else exp
            np.testing.assert_array_equal(got[w], exp, err_msg=f"trial {trial}")


def test_pages_released_after_threshold_keep_reads_exact(tmp_path, monkeypatch):
    """Handing mapped pages back to the OS (bounded RSS on multi-GB files) must not change any value."""
    import spikeview.io._base as base

    rng = np.random.default_rng(11)
    spikes = (rng.random((40, 16, 24)) < 0.3).astype(np.uint8)
    path = tmp_path / "r.dat"
    write_plain(path, spikes)
    monkeypatch.setattr(base, "RELEASE_AFTER_BYTES", 1)  # release after every access
    src = PlainDatSource(path, 24, 16)
    assert base._mmap_of(src._buf) is not None
    for a in range(0, 30, 7):
        np.testing.assert_array_equal(src.read(a, a + 10), spikes[a:a + 10])
        np.testing.assert_array_equal(src.count(a, a + 10), spikes[a:a + 10].sum(0))
    assert src._touched == 0
