""".npy/.npz spike arrays: layouts, dtype and value checks, keys, flips."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import GeometryError, InputFileError, ParameterError
from spikeview.io import NpySource, read_sidecar, write_array
from spikeview.io.arrays import decide_layout


@pytest.fixture
def spikes() -> np.ndarray:
    rng = np.random.default_rng(21)
    return (rng.random((12, 10, 16)) < 0.3).astype(np.uint8)  # (T, H, W)


def test_thw_npy_is_memory_mapped(tmp_path, spikes):
    path = tmp_path / "a.npy"
    np.save(path, spikes)
    src = NpySource(path, layout="thw")
    assert isinstance(src._arr, np.memmap)
    assert src.shape == (12, 10, 16) and src.info.format == "npz" and src.info.warnings == []
    np.testing.assert_array_equal(src.read(2, 9), spikes[2:9])
    np.testing.assert_array_equal(src.count(0, 12), spikes.sum(axis=0))


def test_hwt_by_layout_or_by_size(tmp_path, spikes):
    path = tmp_path / "b.npy"
    np.save(path, np.ascontiguousarray(spikes.transpose(1, 2, 0)))  # (H, W, T) = (10, 16, 12)
    np.testing.assert_array_equal(NpySource(path, layout="hwt").read(0, 12), spikes)
    by_size = NpySource(path, width=16, height=10)
    assert by_size.info.warnings == []  # only (H, W, T) fits 16x10 frames: nothing was guessed
    np.testing.assert_array_equal(by_size.read(3, 5), spikes[3:5])
    guessed = NpySource(path)  # neither: the default (T, H, W) rule, stated in the warnings
    assert guessed.shape == (10, 16, 12)
    assert "read as (T, H, W)" in guessed.info.warnings[0] and "b.npy" not in guessed.info.warnings[0]  # shown beside the name


def test_known_sensor_size_decides_layout():
    assert decide_layout((7, 250, 400))[0] == "thw"
    assert decide_layout((250, 400, 7))[0] == "hwt"
    assert decide_layout((1000, 1000, 3))[0] == "hwt"
    lay, note = decide_layout((9, 9, 9), width=9, height=9)
    assert lay == "thw" and "either way" in note
    assert decide_layout((9, 9, 9), layout="HWT") == ("hwt", None)
    with pytest.raises(ParameterError, match="layout"):
        decide_layout((9, 9, 9), layout="tyx")
    with pytest.raises(GeometryError) as e:
        decide_layout((4, 5, 6), width=7, height=8)
    assert (6, 5) in e.value.candidates and (5, 4) in e.value.candidates


def test_npz_keys(tmp_path, spikes):
    one = tmp_path / "one.npz"
    np.savez(one, whatever=spikes)
    np.testing.assert_array_equal(NpySource(one, layout="thw").read(0, 12), spikes)
    many = tmp_path / "many.npz"
    np.savez_compressed(many, gt=np.zeros(3), spikes=spikes.astype(bool))
    src = NpySource(many, layout="thw")
    assert src.info.extra["npz_key"] == "spikes"
    np.testing.assert_array_equal(src.read(0, 12), spikes)
    odd = tmp_path / "odd.npz"
    np.savez(odd, a=spikes, b=spikes)
    with pytest.raises(InputFileError, match="odd.npz.*holds arrays a, b"):
        NpySource(odd)
    np.testing.assert_array_equal(NpySource(odd, key="b", layout="thw").read(0, 1), spikes[:1])
    with pytest.raises(InputFileError, match="no array named 'c'"):
        NpySource(odd, key="c")


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros((4, 4), np.uint8), "3-D"),
        (np.zeros((2, 4, 4, 1), np.uint8), "3-D"),
        (np.zeros((2, 4, 4), np.int16), "dtype int16"),
        (np.zeros((2, 4, 4), np.float32), "dtype float32"),
        (np.full((2, 4, 4), 2, np.uint8), "values other than 0 and 1"),
        (np.zeros((0, 4, 4), np.uint8), "empty"),
    ],
)
def test_bad_arrays_are_clear_errors(tmp_path, array, match):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    with pytest.raises(InputFileError, match=f"bad.npy.*{match}"):
        NpySource(path, layout="thw")


def test_late_bad_values_fail_when_read(tmp_path, monkeypatch):
    from spikeview.io import arrays

    monkeypatch.setattr(arrays, "_OPEN_CHECK_ELEMENTS", 10 * 16 * 16)  # opening checks the first 10 frames only
    arr = np.zeros((200, 16, 16), np.uint8)
    arr[-1, 3, 3] = 7
    path = tmp_path / "late.npy"
    np.save(path, arr)
    src = NpySource(path, layout="thw")
    np.testing.assert_array_equal(src.read(0, 5), arr[:5])
    with pytest.raises(InputFileError, match="tick 199"):
        src.read(190, 200)


def test_damaged_files(tmp_path, spikes):
    good = tmp_path / "g.npy"
    np.save(good, spikes)
    cut = tmp_path / "cut.npy"
    cut.write_bytes(good.read_bytes()[:300])
    with pytest.raises(InputFileError, match="cut.npy: the .npy file looks truncated or damaged"):
        NpySource(cut)
    zipped = tmp_path / "z.npz"
    np.savez_compressed(zipped, spk=spikes)
    cutz = tmp_path / "cutz.npz"
    cutz.write_bytes(zipped.read_bytes()[: zipped.stat().st_size // 2])
    from spikeview.io import open_source

    with pytest.raises(InputFileError, match="cutz.npz: the .npz file looks truncated or damaged"):
        open_source(cutz)
    text = tmp_path / "t.npy"
    text.write_text("hello")
    with pytest.raises(InputFileError, match="t.npy"):
        NpySource(text)


def test_flips_and_wrong_dims(tmp_path, spikes):
    path = tmp_path / "f.npy"
    np.save(path, spikes)
    src = NpySource(path, layout="thw", flip_vertical=True, flip_horizontal=True)
    np.testing.assert_array_equal(src.read(0, 2), spikes[:2, ::-1, ::-1])
    with pytest.raises(GeometryError, match="f.npy"):
        NpySource(path, width=11, height=10)
    with pytest.raises(GeometryError, match="f.npy"):
        NpySource(path, layout="hwt", width=16, height=10)


def test_write_array_round_trip(tmp_path, spikes):
    for name in ("w.npy", "w.npz"):
        path = write_array(tmp_path / name, spikes.astype(bool), cfa="RGGB", extra_tables={"simulation": {"seed": 3}})
        side = read_sidecar(path)
        assert side.stream.format == "npz" and side.stream.cfa == "RGGB" and side.tables["simulation"] == {"seed": 3}
        src = NpySource(path, layout="thw", cfa="RGGB")
        np.testing.assert_array_equal(src.read(0, 12), spikes)
        src.close()
        with pytest.raises(ParameterError, match="closed"):
            src.read(0, 1)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_layout_note_only_when_the_order_is_ambiguous(tmp_path, cfa):
    """(T, H, W) with time the longest axis (or a known sensor frame) is read without a note; an
    order open to doubt keeps the --layout hwt hint, stronger when the last axis is the longest."""
    rng = np.random.default_rng(4)
    clear = tmp_path / "clear.npy"
    np.save(clear, (rng.random((100, 8, 12)) < 0.3).astype(np.uint8))
    src = NpySource(clear, cfa=cfa)
    assert src.shape == (100, 8, 12) and src.info.warnings == []
    assert src.info.cfa == (None if cfa is None else "RGGB")
    assert decide_layout((7, 250, 400)) == ("thw", None)
    odd = tmp_path / "odd.npy"  # (64, 48, 100): read as 64 ticks, but time may well be the last axis
    np.save(odd, (rng.random((64, 48, 100)) < 0.3).astype(np.uint8))
    note = NpySource(odd, cfa=cfa).info.warnings
    assert len(note) == 1 and "--layout hwt" in note[0] and "last axis is the longest" in note[0]
    lay, note = decide_layout((40, 48, 30))  # no axis stands out as time
    assert lay == "thw" and "--layout hwt" in note and "longest" not in note
