"""A colour filter read as monochrome is warned about, Bayer files with few ticks get their true size,
and files that are not spike data are refused (issue 14)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.errors import InputFileError
from spikeview.io import open_source
from spikeview.io.geometry import guess_cfa, rank_plain_geometries
from test_geometry_guess import write_capture

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def test_a_bayer_file_read_as_monochrome_is_warned_with_the_cfa_to_pass(tmp_path, capsys):
    bayer = write_capture(tmp_path / "b.dat", 128, 96, 200, cfa=True)
    with open_source(bayer, width=128, height=96, cfa=None) as src:
        assert any("--cfa RGGB" in w and "read as monochrome" in w for w in src.info.warnings)
    assert main(["info", str(bayer), "--width", "128", "--height", "96"]) == 0  # --cfa none is the default
    assert "pass --cfa RGGB" in capsys.readouterr().out
    mono = write_capture(tmp_path / "m.dat", 128, 96, 200, cfa=False)
    with open_source(mono, width=128, height=96, cfa=None) as src:
        assert not any("monochrome" in w for w in src.info.warnings)


def test_guess_cfa_names_each_phase_and_none_for_monochrome():
    rng = np.random.default_rng(1)
    base = rng.uniform(0.2, 0.4, (64, 64))
    for cfa, gains in {"RGGB": (0.6, 1.0, 1.0, 0.4), "BGGR": (0.4, 1.0, 1.0, 0.6), "GRBG": (1.0, 0.6, 0.4, 1.0),
                       "GBRG": (1.0, 0.4, 0.6, 1.0)}.items():
        img = base.copy()
        for (py, px), g in zip(((0, 0), (0, 1), (1, 0), (1, 1)), gains):
            img[py::2, px::2] *= g
        assert guess_cfa(img) == cfa
    assert guess_cfa(base) is None


def test_the_app_open_dialog_starts_from_the_guess(tmp_path):
    from spikeview.session import core

    assert core.probe_file(write_capture(tmp_path / "b.dat", 128, 96, 200, cfa=True))[0]["cfa"] == "RGGB"
    assert core.probe_file(write_capture(tmp_path / "m.dat", 128, 96, 200, cfa=False))[0]["cfa"] == "none"


@pytest.mark.parametrize("w, h, kind", [(128, 128, "gradient"), (256, 256, "flat")])
def test_bayer_files_of_200_ticks_with_little_texture_rank_their_true_size_first(tmp_path, w, h, kind):
    """A smooth colour gradient: the filter's row pattern lines rows up at twice the width too (before:
    256x128-like guesses); a flat scene: the filter's row pattern repeats within a frame (before: 8x8)."""
    from bench_geometry import wide_scene

    from spikeview.sim import SimConfig, simulate_to_file

    files = simulate_to_file(wide_scene(kind, w, h, tmp_path), SimConfig(n_ticks=200, width=w, height=h, cfa="RGGB", seed=1),
                             tmp_path / "x.dat")
    files.dat.with_name(files.dat.name + ".toml").unlink()
    assert rank_plain_geometries(files.dat)[0].size == (w, h)


def _png(path):
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(oiio.ImageSpec(32, 32, 3, oiio.UINT8))
    assert buf.write(str(path.with_suffix(".png")))
    return path.with_suffix(".png").rename(path)


@pytest.mark.parametrize("kind", ["text", "png", "random"])
def test_a_file_that_is_not_spike_data_is_refused(tmp_path, kind, capsys):
    if kind == "text":
        path = tmp_path / "notes.txt"
        path.write_text("shopping: milk, eggs\nbread\n" * 2)
    elif kind == "png":
        path = _png(tmp_path / "img.dat")
    else:
        path = tmp_path / "noise.dat"
        path.write_bytes(np.random.default_rng(0).integers(0, 256, 100_000, dtype=np.uint8).tobytes())
    with pytest.raises(InputFileError, match="not a spike file"):
        open_source(path)
    assert main(["info", str(path)]) != 0
    err = capsys.readouterr().err
    assert "not a spike file" in err and ".npy/.npz" in err and "most likely" not in err
    # given a geometry, the user has said what it is: read as asked
    if kind == "random":
        with open_source(path, width=400, height=250) as src:
            assert src.n_frames == 8


def test_a_real_capture_is_not_refused(tmp_path):
    path = write_capture(tmp_path / "c.dat", 128, 96, 200, cfa=False)
    from spikeview.io.geometry import not_spike_data

    assert not_spike_data(np.fromfile(path, dtype=np.uint8)) is None
