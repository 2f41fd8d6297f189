"""EXR sequences, read back through OpenImageIO."""

from __future__ import annotations

import tomllib

import numpy as np
import OpenImageIO as oiio  # a required dependency: a broken install fails here, it is not skipped
import pytest

from spikeview.config import Config
from spikeview.errors import Cancelled, OutputFileError
from spikeview.export import ExportConfig, ExportMetadata, export_frames, open_exporter, read_export_metadata
from spikeview.export.atomic import PARTIAL_MARKER

H, W = 32, 48


def frames(n: int, mono: bool = False, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    shape = (n, H, W) if mono else (n, H, W, 3)
    return rng.random(shape, dtype=np.float32)


def metadata() -> ExportMetadata:
    return ExportMetadata(
        source="/data/capture.dat",
        method="tfp",
        tick_rate=20_000.0,
        window=(100, 110),
        centre_tick=105,
        step_ticks=10,
        params={"window_ticks": 10, "cfa": "RGGB", "demosaic": {"method": "malvar2004"}},
    )


def read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        spec = inp.spec()
        attrs = {a.name: a.value for a in spec.extra_attribs}
        pixels = inp.read_image("float")
    finally:
        inp.close()
    return spec, attrs, pixels


def stray_temporaries(folder):
    return [p.name for p in folder.iterdir() if PARTIAL_MARKER in p.name]


@pytest.mark.parametrize("compression", ["zip", "piz", "none"])
def test_exr_sequence_reads_back_half_with_metadata(tmp_path, compression):
    x = frames(3)
    written = export_frames(x, tmp_path / "frame_%04d.exr", ExportConfig(compression=compression), metadata())
    assert [p.name for p in written] == ["frame_0000.exr", "frame_0001.exr", "frame_0002.exr"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [p.name for p in written]
    for i, path in enumerate(written):
        spec, attrs, pixels = read(path)
        assert (spec.width, spec.height, spec.nchannels) == (W, H, 3)
        assert spec.channelnames == ("R", "G", "B")
        assert spec.format == oiio.TypeDesc("half")
        assert attrs["compression"] == compression
        # stored as half: exactly numpy's round-to-nearest float16 of the input
        np.testing.assert_array_equal(pixels, x[i].astype(np.float16).astype(np.float32))
        assert np.abs(pixels - x[i]).max() <= 2.0**-11
        assert attrs["spikeview:source"] == "/data/capture.dat"
        assert attrs["spikeview:method"] == "tfp"
        assert attrs["spikeview:tickRate"] == 20_000.0
        # frame i's window is the first window shifted by i·step_ticks
        assert attrs["spikeview:tickStart"] == 100 + 10 * i
        assert attrs["spikeview:tickStop"] == 110 + 10 * i
        assert attrs["spikeview:centreTick"] == 105 + 10 * i
        assert attrs["spikeview:frameIndex"] == i
        assert f"ticks [{100 + 10 * i}, {110 + 10 * i})" in attrs["ImageDescription"]
        assert attrs["Software"].startswith("spikeview ")
        record = tomllib.loads(attrs["spikeview:config"])
        assert record["params"] == {"window_ticks": 10, "cfa": "RGGB", "demosaic": {"method": "malvar2004"}}
        assert record["window"] == [100 + 10 * i, 110 + 10 * i]
        assert record["export"]["compression"] == compression
        assert read_export_metadata(path) == record


def test_exr_record_rebuilds_the_export_config(tmp_path):
    cfg = ExportConfig(compression="piz", first_frame=7, fps=24.0)
    (path,) = export_frames(frames(1), tmp_path / "one.exr", cfg, metadata())
    assert path.name == "one.exr"
    assert ExportConfig.from_dict(read_export_metadata(path)["export"]) == cfg


def test_exr_mono_is_one_y_channel(tmp_path):
    x = frames(2, mono=True)
    written = export_frames(x, tmp_path / "m_%03d.exr")
    assert [p.name for p in written] == ["m_000.exr", "m_001.exr"]
    spec, _, pixels = read(written[1])
    assert spec.nchannels == 1 and spec.channelnames == ("Y",)
    np.testing.assert_array_equal(pixels[:, :, 0], x[1].astype(np.float16).astype(np.float32))


def test_exr_linear_values_are_not_clipped_or_encoded(tmp_path):
    x = np.full((H, W, 3), 0.25, np.float32)
    x[0, 0] = [1.5, 0.0, 1e-3]  # above white, black, dark: stored as given
    (path,) = export_frames([x], tmp_path / "lin.exr")
    _, attrs, pixels = read(path)
    assert "lin" in attrs["oiio:ColorSpace"]
    np.testing.assert_allclose(pixels[0, 0], [1.5, 0.0, 1e-3], rtol=2.0**-11)
    assert pixels[5, 5, 1] == 0.25


def test_exr_first_frame_sets_the_numbering(tmp_path):
    written = export_frames(frames(2), tmp_path / "f%d.exr", ExportConfig(first_frame=1))
    assert [p.name for p in written] == ["f1.exr", "f2.exr"]
    assert read_export_metadata(written[1])["frame_number"] == 2
    assert read_export_metadata(written[1])["frame_index"] == 1


def test_exr_per_frame_ticks_passed_to_write(tmp_path):
    meta = ExportMetadata(source="s.dat", method="tfi")  # no step: later frames need explicit ticks
    with open_exporter(tmp_path / "t_%02d.exr", 2, (H, W, 3), None, meta) as ex:
        ex.write(frames(1)[0], window=(0, 41), centre_tick=20)
        ex.write(frames(1)[0])
    first, second = read_export_metadata(tmp_path / "t_00.exr"), read_export_metadata(tmp_path / "t_01.exr")
    assert first["window"] == [0, 41] and first["centre_tick"] == 20
    assert "window" not in second and "centre_tick" not in second


def test_exr_error_mid_export_keeps_finished_frames_only(tmp_path):
    x = frames(4)
    with pytest.raises(RuntimeError, match="boom"):
        with open_exporter(tmp_path / "frame_%04d.exr", 4, (H, W, 3)) as ex:
            for i in range(4):
                if i == 2:
                    raise RuntimeError("boom")
                ex.write(x[i])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0000.exr", "frame_0001.exr"]
    _, _, pixels = read(tmp_path / "frame_0001.exr")
    np.testing.assert_array_equal(pixels, x[1].astype(np.float16).astype(np.float32))


def test_exr_failure_while_writing_a_frame_leaves_no_temporary(tmp_path, monkeypatch):
    from spikeview.export import _oiio

    (tmp_path / "frame_0000.exr").write_bytes(b"older file")
    real = _oiio.write_image

    def half_written(tmp, final, *args, **kwargs):
        real(tmp, final, *args, **kwargs)  # the temporary exists and is complete …
        raise OSError("disk full")  # … but the write is reported as failed

    monkeypatch.setattr(_oiio, "write_image", half_written)
    with pytest.raises(OutputFileError, match="already exists.*--overwrite"):
        export_frames(frames(2), tmp_path / "frame_%04d.exr")  # never replaced without overwrite
    with pytest.raises(OutputFileError, match="frame 0 failed: disk full"):
        export_frames(frames(2), tmp_path / "frame_%04d.exr", overwrite=True)
    assert stray_temporaries(tmp_path) == []
    # the file of the same name is untouched: a failed frame never replaces it
    assert (tmp_path / "frame_0000.exr").read_bytes() == b"older file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame_0000.exr"]


def test_exr_cancel_keeps_finished_frames(tmp_path):
    calls = []

    def cancel() -> bool:
        return len(calls) >= 2

    with pytest.raises(Cancelled):
        export_frames(
            frames(5), tmp_path / "c_%04d.exr", progress=lambda done, total: calls.append((done, total)), cancel=cancel
        )
    assert calls == [(1, 5), (2, 5)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c_0000.exr", "c_0001.exr"]


def test_exr_params_from_a_config_and_from_toml_text(tmp_path):
    import dataclasses

    @dataclasses.dataclass
    class Recon(Config):
        window_ticks: int = 10
        method: str = "tfp"

    for i, params in enumerate([Recon(), Recon().to_toml()]):
        (path,) = export_frames(frames(1), tmp_path / f"p{i}.exr", metadata=ExportMetadata(params=params))
        assert Recon.from_dict(read_export_metadata(path)["params"]) == Recon()
