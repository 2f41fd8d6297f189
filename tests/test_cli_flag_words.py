"""Bad flag values found by trying the CLI as a newcomer: one sentence naming the flag the user typed."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


def test_simulate_size_zero_names_size(tmp_path, capsys):
    assert main(["simulate", "--demo", "--size", "0", "--out", str(tmp_path / "x.dat")]) == 1
    err = capsys.readouterr().err
    assert "--size 0 is not valid" in err and "--width" not in err and "\n" not in err.strip(), err
    assert not list(tmp_path.iterdir())


def test_simulate_width_zero_still_names_width(tmp_path, capsys):
    assert main(["simulate", "--demo", "--width", "0", "--height", "8", "--out", str(tmp_path / "x.dat")]) == 1
    assert "--width 0 is not valid" in capsys.readouterr().err


@pytest.mark.parametrize("n", ["0", "-4"])
def test_info_sample_windows_below_one_is_refused(tmp_path, capsys, n):
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(0).random((40, 8, 8)) < 0.3).astype(np.uint8))
    assert main(["info", str(path), "--cfa", "none", "--sample-windows", n]) == 1
    captured = capsys.readouterr()
    assert f"--sample-windows {n} is not valid" in captured.err and captured.out == "", captured
    assert main(["info", str(path), "--cfa", "none", "--sample-windows", "1"]) == 0


@pytest.mark.parametrize("out", ["nofolder/x.png", "nofolder/f_%04d.png", "nofolder/x.mp4", "nofolder/x.npy"])
def test_missing_output_folder_is_named_before_any_other_line(tmp_path, capsys, out):
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(0).random((40, 8, 8)) < 0.3).astype(np.uint8))
    argv = ["reconstruct", str(path), "--cfa", "none", "--out", str(tmp_path / out)]
    argv += ["--range", "5:30:10"] if "%" in out or out.endswith(".mp4") else ["--at", "20"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error:") and "does not exist" in err and "white point" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.npy"]


def test_ground_truth_npz_points_to_its_capture(tmp_path, capsys):
    gt = tmp_path / "cap.gt.npz"
    np.savez(gt, frames=np.zeros((2, 4, 4, 3), np.float16), ticks=np.array([0, 50]), tick_rate=20000.0)
    assert main(["info", str(gt)]) == 1
    err = capsys.readouterr().err
    assert "ground-truth frames" in err and "cap.dat" in err and "key=" not in err, err


def test_npz_without_a_spike_name_gets_a_fix_the_cli_user_can_apply(tmp_path, capsys):
    path = tmp_path / "x.npz"
    np.savez(path, a=np.zeros((4, 4, 4), np.uint8), b=np.zeros(3))
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err
    assert "numpy.savez(file, spikes=a)" in err and "\n" not in err.strip(), err


def test_window_longer_than_the_stream_is_said_before_the_white_point(tmp_path, capsys):
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(0).random((8, 8, 8)) < 0.3).astype(np.uint8))
    assert main(["reconstruct", str(path), "--cfa", "none", "--at", "1", "--out", str(tmp_path / "r.png")]) == 1
    err = "\n".join(ln for ln in capsys.readouterr().err.splitlines() if "--layout" not in ln)  # (8, 8, 8): order hint
    assert err.startswith("spikeview: error: window of 10 ticks is longer than the stream's 8 ticks"), err
    assert "white point" not in err
    assert main(["reconstruct", str(path), "--cfa", "none", "--at", "1", "--window", "8", "--out", str(tmp_path / "r.png")]) == 0


def test_export_names_an_existing_output_before_the_slow_motion_line(tmp_path, capsys):
    pytest.importorskip("zarr")
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(0).random((60, 8, 8)) < 0.3).astype(np.uint8))
    store = tmp_path / "s.zarr"
    assert main(["reconstruct", str(path), "--cfa", "none", "--range", "5:55:10", "--out", str(store)]) == 0
    (tmp_path / "c.mp4").write_bytes(b"keep me")
    capsys.readouterr()
    assert main(["export", str(store), "--out", str(tmp_path / "c.mp4")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error:") and "already exists" in err and "slow motion" not in err, err
    assert (tmp_path / "c.mp4").read_bytes() == b"keep me"
    assert main(["export", str(store), "--out", str(tmp_path / "nofolder" / "c.mp4")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error:") and "does not exist" in err, err
    assert main(["export", str(store), "--out", str(tmp_path / "c2.mp4")]) == 0


def test_a_tables_own_rule_names_the_flag(tmp_path, capsys):
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(0).random((40, 8, 8)) < 0.3).astype(np.uint8))
    assert main(["reconstruct", str(path), "--cfa", "none", "--method", "guided", "--tile", "7", "--at", "20",
                 "--out", str(tmp_path / "g.exr")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error: --tile = 7 is out of range") and "guided.tile" not in err, err
