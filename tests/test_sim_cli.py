"""``spikeview simulate`` from the command line: inputs, what it reads from folders, what it says first."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


def write_png(path, value: float, size: int = 16) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(size, size, 3, "uint8"))
    out.write_image(np.full((size, size, 3), int(value * 255), np.uint8))
    out.close()


def test_an_image_folder_reads_its_frames_and_names_what_it_skipped(tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(6):
        write_png(frames / f"f{i}.png", 0.2 + 0.1 * i)
    (frames / "notes.txt").write_text("hello\n")
    (frames / "f_0000.exr").write_bytes(b"an export someone wrote here")  # another image type: not a frame
    assert main(["simulate", str(frames), "--fps", "1000", "--ticks", "100", "--out", str(tmp_path / "s.dat")]) == 0
    err = capsys.readouterr().err
    assert "read 6 .png images and skipped 2 other files: f_0000.exr, notes.txt" in err
    from spikeview.config import load_toml

    assert load_toml(tmp_path / "s.dat.toml")["scene"]["n_frames"] == 6


def test_config_from_a_sidecar_and_a_capture_as_input(tmp_path, capsys):
    first = tmp_path / "a.dat"
    assert main(["simulate", "--demo", "--size", "16", "--ticks", "60", "--seed", "4", "--out", str(first)]) == 0
    again = tmp_path / "b.dat"
    assert main(["simulate", "--demo", "--config", str(first) + ".toml", "--out", str(again)]) == 0
    assert again.read_bytes() == first.read_bytes()  # the sidecar's [simulation] table reproduces the capture
    capsys.readouterr()
    assert main(["simulate", str(first), "--out", str(tmp_path / "c.dat")]) == 1
    assert "a.dat: is a spike capture, not a scene" in capsys.readouterr().err


def test_large_writes_announce_their_sizes_first(tmp_path, capsys, monkeypatch):
    import spikeview._files as files

    monkeypatch.setattr(files, "LARGE_WRITE_BYTES", 1000)
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "200", "--out", str(tmp_path / "s.dat")]) == 0
    err = capsys.readouterr().err
    # 32·32/8 = 128 bytes per tick · 200 ticks = 25.6 KB; 4 ground-truth frames · 32·32·3 · 2 bytes + 4096 = 28.7 KB
    assert "writing s.dat (25.6 KB) and s.gt.npz (up to 28.7 KB, one frame every 50 ticks; --gt-every changes it)" in err


@pytest.mark.parametrize("argv, needle", [
    (["--demo", "--size", "8"], "--size 16"),
    (["--demo", "--rate", "0"], "--rate 0.0 is not valid"),
])
def test_setting_errors_use_flag_names(tmp_path, capsys, argv, needle):
    assert main(["simulate", *argv, "--out", str(tmp_path / "x.dat")]) == 1
    err = capsys.readouterr().err
    assert needle in err and "\n" not in err.strip(), err
    assert not list(tmp_path.iterdir())
