"""The export entry point: settings, paths, frame checks, atomic writes, callbacks."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from spikeview.errors import OutputFileError, ParameterError, SpikeviewError
from spikeview.export import ExportConfig, ExportMetadata, export_frames, open_exporter, read_export_metadata
from spikeview.export.atomic import PARTIAL_MARKER, AtomicFile, atomic_path

H, W = 32, 48


def frame(value=0.5, shape=(H, W, 3)):
    return np.full(shape, value, np.float32)


# -- settings ------------------------------------------------------------------------------------


def test_export_config_saves_and_loads_unchanged(tmp_path):
    cfg = ExportConfig(
        fps=29.97,
        crf=23,
        preset="slow",
        compression="piz",
        png_bits=16,
        black=0.1,
        white=0.9,
        transfer="gamma",
        gamma=2.4,
        first_frame=1,
        even_size="crop",
    )
    assert ExportConfig.load(cfg.save(tmp_path / "export.toml")) == cfg


@pytest.mark.parametrize(
    ("change", "name"),
    [
        ({"fps": 0.0}, "fps"),
        ({"crf": 52}, "crf"),
        ({"preset": "quick"}, "preset"),
        ({"compression": "b44"}, "compression"),
        ({"png_bits": 12}, "png_bits"),
        ({"black": 1.0, "white": 0.5}, "black/white"),
        ({"transfer": "pq"}, "transfer"),
        ({"gamma": -1.0}, "gamma"),
        ({"first_frame": -1}, "first_frame"),
        ({"even_size": "stretch"}, "even_size"),
    ],
)
def test_export_config_rejects_bad_values_by_name(change, name):
    with pytest.raises(ParameterError, match=f"'{name}'"):
        ExportConfig(**change)
    with pytest.raises(ParameterError, match=f"'{name}'"):
        ExportConfig.from_dict(change)


def test_metadata_params_accept_numpy_scalars_and_reject_arrays():
    meta = ExportMetadata(params={"gain": np.float32(0.5), "n": np.int64(3), "t": (1, 2), "skip": None})
    assert meta.params == {"gain": 0.5, "n": 3, "t": [1, 2]}
    assert type(meta.params["n"]) is int
    with pytest.raises(ParameterError, match="'params.weights' has type ndarray"):
        ExportMetadata(params={"weights": np.zeros(3)})
    with pytest.raises(ParameterError, match="not valid TOML"):
        ExportMetadata(params="a = ")


def test_metadata_ticks_are_checked_and_shifted():
    with pytest.raises(ParameterError, match="'window'"):
        ExportMetadata(window=(10, 10))
    with pytest.raises(ParameterError, match="'centre_tick'"):
        ExportMetadata(window=(0, 10), centre_tick=10)
    meta = ExportMetadata(window=(0, 10), centre_tick=5, step_ticks=4)
    assert meta.frame_ticks(3) == ((12, 22), 17)
    assert ExportMetadata(window=(0, 10)).frame_ticks(1) == (None, None)


def test_dict_settings_and_metadata_are_validated(tmp_path):
    with pytest.raises(ParameterError, match="unknown setting"):
        open_exporter(tmp_path / "a.npy", 1, (H, W), {"fsp": 30})
    with open_exporter(tmp_path / "a.npy", 1, (H, W), {"fps": 24}, {"source": "s.dat", "window": [0, 4]}) as ex:
        ex.write(frame(shape=(H, W)))
    record = read_export_metadata(tmp_path / "a.npy")
    assert record["export"]["fps"] == 24.0 and record["window"] == [0, 4]


# -- paths ---------------------------------------------------------------------------------------


def test_unknown_suffix(tmp_path):
    with pytest.raises(ParameterError, match=r"unknown export format '\.tif'.*\.exr, \.png, \.mp4 or \.npy"):
        open_exporter(tmp_path / "a.tif", 1, (H, W, 3))


def test_missing_and_non_folder_destinations(tmp_path):
    with pytest.raises(OutputFileError, match="does not exist"):
        open_exporter(tmp_path / "nope" / "a.npy", 1, (H, W, 3))
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputFileError, match="is not a folder"):
        open_exporter(tmp_path / "file" / "a.npy", 1, (H, W, 3))


def test_unwritable_folder(tmp_path, monkeypatch):
    # os.access is consulted rather than chmod: tests may run as root, who can write anywhere
    import spikeview.export.base as base

    monkeypatch.setattr(base.os, "access", lambda path, mode: False)
    with pytest.raises(OutputFileError, match="no permission to write"):
        open_exporter(tmp_path / "a.exr", 1, (H, W, 3))


@pytest.mark.parametrize("name", ["f_%s.exr", "f_%04d_%04d.exr", "100%.png"])
def test_bad_patterns(tmp_path, name):
    with pytest.raises(ParameterError, match="exactly one frame-number field"):
        open_exporter(tmp_path / name, 2, (H, W, 3))


def test_literal_percent_in_a_pattern(tmp_path):
    written = export_frames([frame(), frame()], tmp_path / "50%%_%02d.png")
    assert [p.name for p in written] == ["50%_00.png", "50%_01.png"]


def test_multi_frame_exr_without_pattern_says_how_to_write_one(tmp_path):
    with pytest.raises(ParameterError, match=r"3-frame EXR.*e\.g\. .*clip_%04d\.exr"):
        open_exporter(tmp_path / "clip.exr", 3, (H, W, 3))


# -- frames --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (frame(shape=(H, W + 1, 3)), r"frame 0 has shape \(32, 49, 3\) but this export was opened for \(32, 48, 3\)"),
        (frame(shape=(H, W)), r"has shape \(32, 48\)"),
        (np.full((H, W, 3), 0.5), "dtype float64.*astype"),
        (np.full((H, W, 3), np.inf, np.float32), f"{H * W * 3} NaN or infinite"),
        ([[0.5]], "is a list"),
    ],
)
@pytest.mark.parametrize("suffix", [".exr", ".png", ".mp4", ".npy"])
def test_bad_frames_are_refused_and_nothing_is_left(tmp_path, bad, message, suffix):
    with pytest.raises(ParameterError, match=message):
        with open_exporter(tmp_path / f"a{suffix}", 1, (H, W, 3)) as ex:
            ex.write(bad)
    assert list(tmp_path.iterdir()) == []


def test_bad_frame_shape_at_open(tmp_path):
    with pytest.raises(ParameterError, match="frame_shape"):
        open_exporter(tmp_path / "a.npy", 1, (H, W, 4))
    with pytest.raises(ParameterError, match="n_frames"):
        open_exporter(tmp_path / "a.npy", 0, (H, W, 3))


def test_too_many_frames_and_write_after_close(tmp_path):
    ex = open_exporter(tmp_path / "a.npy", 1, (H, W, 3))
    ex.write(frame())
    with pytest.raises(ParameterError, match="opened for 1 frame"):
        ex.write(frame())
    ex.close()
    with pytest.raises(ParameterError, match="already closed"):
        ex.write(frame())
    assert ex.close() == [tmp_path / "a.npy", tmp_path / "a.npy.toml"]  # closing twice is harmless


def test_generator_needs_n_frames(tmp_path):
    with pytest.raises(ParameterError, match="n_frames"):
        export_frames((frame() for _ in range(2)), tmp_path / "a.npy")
    written = export_frames((frame(v) for v in (0.25, 0.75)), tmp_path / "a.npy", n_frames=2)
    assert np.load(written[0])[:, 0, 0, 0].tolist() == [0.25, 0.75]


def test_generator_shorter_than_n_frames_is_an_error(tmp_path):
    with pytest.raises(ParameterError, match="only 1 of 3 frames"):
        export_frames(iter([frame()]), tmp_path / "v.mp4", n_frames=3)
    assert list(tmp_path.iterdir()) == []


def test_progress_callback(tmp_path):
    seen = []
    export_frames([frame()] * 3, tmp_path / "p_%d.exr", progress=lambda done, total: seen.append((done, total)))
    assert seen == [(1, 3), (2, 3), (3, 3)]


def test_every_error_is_for_people(tmp_path):
    """Errors are SpikeviewError subclasses whose message names the path."""
    with pytest.raises(SpikeviewError, match="a.tif"):
        open_exporter(tmp_path / "a.tif", 1, (H, W, 3))
    with pytest.raises(SpikeviewError, match="nothing.exr"):
        read_export_metadata(tmp_path / "nothing.exr")
    (tmp_path / "x.npy").write_bytes(b"")
    with pytest.raises(SpikeviewError, match="no metadata sidecar"):
        read_export_metadata(tmp_path / "x.npy")


# -- atomic writes -------------------------------------------------------------------------------


def test_atomic_path_renames_on_success_and_cleans_up_on_failure(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            assert tmp.parent == tmp_path and tmp.suffix == ".txt" and PARTIAL_MARKER in tmp.name
            tmp.write_text("half")
            raise RuntimeError
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]
    with atomic_path(target) as tmp:
        tmp.write_text("new")
        assert target.read_text() == "old"  # not visible until the block ends
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_file_discard_is_idempotent(tmp_path):
    f = AtomicFile(tmp_path / "a.bin")
    f.tmp.write_bytes(b"x")
    f.discard()
    f.discard()
    assert list(tmp_path.iterdir()) == []


# -- structure -----------------------------------------------------------------------------------


def test_importing_export_does_not_load_openimageio_or_pyav():
    import os
    from pathlib import Path

    import spikeview

    root = str(Path(spikeview.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    code = "import sys, spikeview.export; print(sorted(m for m in ('OpenImageIO', 'av') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == "[]"
