"""open_source: sidecars, override precedence, format/geometry detection, errors for people."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import GeometryError, InputFileError, ParameterError
from spikeview.io import (
    PlainDatSource,
    Raw1MSource,
    Raw400Source,
    StreamInfo,
    encode_raw1m,
    encode_raw400,
    open_source,
    pack_frames,
    plain_geometry_candidates,
    read_sidecar,
    sidecar_path,
    write_array,
    write_plain,
    write_sidecar,
)
from spikeview.io.sidecar import StreamSettings


def _spikes(seed: int, t: int, h: int, w: int) -> np.ndarray:
    return (np.random.default_rng(seed).random((t, h, w)) < 0.3).astype(np.uint8)


# ----------------------------------------------------------------------------------- sidecar
def test_sidecar_round_trip(tmp_path):
    data = tmp_path / "scene.dat"
    info = StreamInfo(width=64, height=32, n_frames=5, tick_rate=40000.0, cfa="BGGR", format="plain",
                      flip_vertical=True, flip_horizontal=False)
    tables = {"simulation": {"gain": 0.6, "seed": np.int64(3), "noise": [1.0, 2.0], "skip": None},
              "recording": {"dropped_frames": 2}}
    side = write_sidecar(data, info, tables)
    assert side == sidecar_path(data) == tmp_path / "scene.dat.toml"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.dat.toml"]  # no temporary file left
    back = read_sidecar(data)
    assert back.stream == StreamSettings(format="plain", width=64, height=32, cfa="BGGR", flip_vertical=True,
                                         flip_horizontal=False, tick_rate=40000.0)
    assert back.tables == {"simulation": {"gain": 0.6, "seed": 3, "noise": [1.0, 2.0]},
                           "recording": {"dropped_frames": 2}}
    assert read_sidecar(tmp_path / "other.dat") is None


@pytest.mark.parametrize(
    "text, match",
    [
        ("[stream\nwidth=", "not valid TOML"),
        ('[stream]\nformat = "plain"\nwidth = 8\nheight = 8\ncfa = "RGBX"', "Unknown CFA"),
        ('[stream]\nformat = "avi"\nwidth = 8\nheight = 8', "format 'avi' is unknown"),
        ('[stream]\nformat = "plain"\nwidth = "8"\nheight = 8', "'width' must be an integer"),
        ('[stream]\nformat = "plain"\nwidth = 8\nheight = 8\ncolour = 1', "unknown setting"),
    ],
)
def test_bad_sidecar_names_the_sidecar(tmp_path, text, match):
    data = write_plain(tmp_path / "x.dat", _spikes(0, 2, 8, 8), sidecar=False)
    sidecar_path(data).write_text(text)
    with pytest.raises(InputFileError, match=f"x.dat.toml.*{match}"):
        open_source(data)


def test_sidecar_settings_are_used_and_tables_reach_extra(tmp_path):
    spikes = _spikes(1, 6, 16, 24)
    path = write_plain(tmp_path / "s.dat", spikes, flip_vertical=False, cfa="GBRG", tick_rate=10000.0,
                       extra_tables={"simulation": {"scene": "disc"}})
    src = open_source(path)
    assert isinstance(src, PlainDatSource)
    assert (src.width, src.height, src.cfa, src.tick_rate, src.info.flip_vertical) == (24, 16, "GBRG", 10000.0, False)
    assert src.info.extra["simulation"] == {"scene": "disc"}
    assert src.info.warnings == []
    np.testing.assert_array_equal(src.read(0, 6), spikes)


def test_explicit_arguments_override_the_sidecar(tmp_path):
    spikes = _spikes(2, 4, 16, 24)
    path = write_plain(tmp_path / "o.dat", spikes, flip_vertical=True, cfa="RGGB")
    src = open_source(path, cfa=None, flip_vertical=False, tick_rate=1000)
    assert src.cfa is None and src.tick_rate == 1000.0 and src.info.flip_vertical is False
    np.testing.assert_array_equal(src.read(0, 4), spikes[:, ::-1])  # the stored orientation
    assert open_source(path, cfa="none").cfa is None
    assert open_source(path).cfa == "RGGB"  # unset keeps the sidecar's
    other = open_source(path, width=48, height=8)  # a different geometry is taken as given
    assert other.shape == (4, 8, 48)
    with pytest.raises(ParameterError, match="Unknown CFA"):
        open_source(path, cfa="RGB")


# --------------------------------------------------------------------------------- detection
def test_detect_known_plain_sizes(tmp_path):
    p400 = tmp_path / "a.dat"
    p400.write_bytes(pack_frames(_spikes(3, 3, 250, 400)).tobytes())  # 37,500 bytes
    src = open_source(p400)
    assert isinstance(src, PlainDatSource) and src.shape == (3, 250, 400) and src.info.flip_vertical
    assert src.info.warnings[0].startswith("no sidecar, read as a plain 400x250 file")  # the file is named by whoever shows it
    p1k = tmp_path / "b.dat"
    p1k.write_bytes(pack_frames(_spikes(4, 2, 1000, 1000)).tobytes())
    # 125,000 bytes are also ten 400x250 frames: every 1000x1000 file needs its geometry given
    with pytest.raises(GeometryError, match="b.dat.*several known formats.*--width 1000 --height 1000") as e:
        open_source(p1k)
    assert e.value.candidates == [(1000, 1000), (400, 250)]
    assert open_source(p1k, width=1000, height=1000).shape == (2, 1000, 1000)


def test_detect_raw_formats(tmp_path):
    frames = _spikes(5, 2, 250, 400)
    r400 = tmp_path / "c.bin"
    r400.write_bytes(encode_raw400(frames))  # 26,000 bytes: whole raw frames, not whole plain frames
    src = open_source(r400)
    assert isinstance(src, Raw400Source)
    np.testing.assert_array_equal(src.read(0, 2), frames)
    big = _spikes(6, 2, 1000, 1000)
    r1m = tmp_path / "d.bin"
    r1m.write_bytes(b"\x55" * 1234 + encode_raw1m(big))
    src = open_source(r1m)
    assert isinstance(src, Raw1MSource) and src.n_frames == 2
    assert any("block tags" in w for w in src.info.warnings)
    np.testing.assert_array_equal(src.read(1, 2), big[1:])
    with pytest.raises(ParameterError, match="always 1000x1000"):
        open_source(r1m, format="raw1m", width=400)


def test_given_dims_without_format_mean_plain(tmp_path):
    spikes = _spikes(7, 3, 8, 16)
    path = tmp_path / "g.dat"
    path.write_bytes(pack_frames(spikes).tobytes())
    src = open_source(path, width=16, height=8)
    assert src.info.format == "plain" and src.info.warnings == []
    np.testing.assert_array_equal(src.read(0, 3), spikes)


def test_ambiguous_size_lists_candidates(tmp_path):
    path = tmp_path / "amb.dat"
    path.write_bytes(bytes(325_000))  # 26 plain 400x250 frames = 25 raw 400x250 frames
    with pytest.raises(GeometryError, match="amb.dat.*fits several known formats.*--format raw400") as e:
        open_source(path)
    assert e.value.candidates == [(400, 250)]
    assert open_source(path, format="raw400").n_frames == 25


def test_unknown_size_lists_fitting_geometries(tmp_path):
    path = tmp_path / "u.dat"
    path.write_bytes(pack_frames(_spikes(8, 3, 64, 64)).tobytes())  # 1,536 bytes
    with pytest.raises(GeometryError, match="u.dat.*pass --width and --height") as e:
        open_source(path)
    assert (64, 64) in e.value.candidates
    for w, h in e.value.candidates:
        assert 1536 % (w * h // 8) == 0  # every candidate really fits
    with pytest.raises(GeometryError) as e:
        open_source(path, width=64)  # one of the two is not enough
    assert e.value.candidates[0] == (64, 64) and all(w == 64 for w, _ in e.value.candidates)


def test_geometry_candidates_order():
    cands = plain_geometry_candidates(125_000 * 4)
    assert cands[0] == (1000, 1000)
    assert all((125_000 * 4) % (w * h // 8) == 0 for w, h in cands)
    assert plain_geometry_candidates(12_345) == []


# ------------------------------------------------------------------------------------ errors
def test_errors_are_one_sentence_naming_the_file(tmp_path):
    with pytest.raises(InputFileError, match="missing.dat: file not found"):
        open_source(tmp_path / "missing.dat")
    with pytest.raises(InputFileError, match="is a folder"):
        open_source(tmp_path)
    empty = tmp_path / "e.dat"
    empty.write_bytes(b"")
    with pytest.raises(InputFileError, match="e.dat: the file is empty"):
        open_source(empty)
    noise = tmp_path / "noise.bin"
    noise.write_bytes(np.random.default_rng(0).integers(0, 256, 12_347, dtype=np.uint8).tobytes())
    with pytest.raises(InputFileError, match="noise.bin: not a spike file") as e:  # random bytes: no geometry offered
        open_source(noise)
    assert str(e.value).count(". ") == 0  # one sentence
    # given a geometry, a text file or an image is still said to be one (not read as spikes); random bytes with a
    # geometry are the user's call (a noisy capture may look so)
    notes = tmp_path / "notes.txt"
    notes.write_text("ticks 0-99 were dark; then the lamp came on\n" * 400)
    png = tmp_path / "frame.dat"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(16_376))
    for path, what in ((notes, "it holds text"), (png, "a PNG image")):
        with pytest.raises(InputFileError, match=f"{path.name}: not a spike file \\({what}\\)"):
            open_source(path, width=64, height=64)
    with open_source(noise, width=8, height=8, flip_vertical=False) as src:
        assert src.n_frames == 12_347 // 8
    good = write_plain(tmp_path / "ok.dat", _spikes(9, 2, 8, 8))
    with pytest.raises(InputFileError, match="is a sidecar.*open ok.dat"):
        open_source(sidecar_path(good))
    with pytest.raises(ParameterError, match="format 'mp4' is unknown"):
        open_source(good, format="mp4")
    with pytest.raises(ParameterError, match="layout applies only"):
        open_source(good, layout="thw")
    for bad in (-5, 0, 1e-300, 1e300, float("nan")):  # absurd rates overflow every duration downstream
        with pytest.raises(ParameterError, match="tick_rate"):
            open_source(good, tick_rate=bad)


def test_arrays_through_open_source(tmp_path):
    spikes = _spikes(10, 5, 250, 400)
    path = write_array(tmp_path / "a.npy", spikes.transpose(1, 2, 0), cfa="RGGB")  # stored (H, W, T)
    side = read_sidecar(path)  # write_array took the array as (T, H, W): the sidecar says 5x400 frames
    assert (side.stream.width, side.stream.height) == (5, 400)
    src = open_source(path, width=400, height=250)  # explicit sizes override it and pick the (H, W, T) layout
    assert src.cfa == "RGGB" and src.shape == (5, 250, 400)
    np.testing.assert_array_equal(src.read(0, 5), spikes)
    bare = tmp_path / "b.npy"
    np.save(bare, spikes.transpose(1, 2, 0))
    src = open_source(bare)  # 250x400 leading axes: a known sensor, so (H, W, T)
    assert src.shape == (5, 250, 400) and "(H, W, T)" in src.info.warnings[0]
    assert open_source(bare, format="npz", layout="thw").shape == (250, 400, 5)


def test_plain_format_without_size_detects_geometry(tmp_path):
    path = tmp_path / "p.bin"
    path.write_bytes(pack_frames(_spikes(11, 2, 250, 400)).tobytes())  # 25,000 bytes: 400x250 only
    src = open_source(path, format="plain")
    assert src.shape == (2, 250, 400) and "plain 400x250" in src.info.warnings[0]
    with pytest.raises(GeometryError) as e:
        open_source(path, format="plain", width=1000)
    assert e.value.candidates == []
