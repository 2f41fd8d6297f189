"""The ``spikeview`` command line, driven in-process (and once as a real subprocess)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.io.plain import write_plain


@pytest.fixture
def capture(tmp_path):
    """A 64×96 Bayer capture of 400 ticks with a left-to-right brightness ramp, no sidecar."""
    rng = np.random.default_rng(7)
    ramp = np.linspace(0.05, 0.9, 96, dtype=np.float32)[None, None, :]
    spikes = (rng.random((400, 64, 96)) < ramp).astype(np.uint8)
    path = tmp_path / "cap.dat"
    write_plain(path, spikes)
    return path, spikes


GEOM = ["--width", "96", "--height", "64", "--cfa", "RGGB"]


def test_info_reports_geometry_and_rates(capture, capsys):
    path, spikes = capture
    assert main(["info", str(path), *GEOM]) == 0
    out = capsys.readouterr().out
    assert "96 x 64" in out and "RGGB" in out and "400 ticks" in out and "20.000 ms" in out
    # overall rate printed with 4 decimals; sampled windows cover the whole stream here
    overall = float(out.split("all ")[1].split()[0])
    assert overall == pytest.approx(spikes.mean(), abs=2e-3)


def test_info_without_geometry_lists_candidates(capture, capsys):
    path, _ = capture
    path.with_name(path.name + ".toml").unlink(missing_ok=True)
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error:") and "--width" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("bad, needle", [
    (["info", "does-not-exist.dat"], "not found"),
    (["info", "{cap}", "--width", "96", "--height", "64", "--cfa", "RGBG"], "CFA"),
    (["reconstruct", "{cap}", *GEOM, "--at", "5000", "--out", "{tmp}/x.npy"], "outside"),
    (["reconstruct", "{cap}", *GEOM, "--range", "10:5", "--out", "{tmp}/x.npy"], "--range"),
    (["reconstruct", "{cap}", *GEOM, "--range", "0:100", "--out", "{tmp}/x.gif"], ".gif"),
    (["reconstruct", "{cap}", *GEOM, "--range", "0:100", "--out", "{tmp}/x.exr"], "%04d"),
    (["reconstruct", "{cap}", *GEOM, "--range", "0:100", "--out", "/proc/x.mp4"], "cannot create files in /proc"),
    (["reconstruct", "{cap}", *GEOM, "--range", "0:100", "--out", "{tmp}/old.npy"], "already exists"),
    (["reconstruct", "{cap}", *GEOM, "--range", "0:100", "--preset", "{tmp}/empty.toml", "--out", "{tmp}/x.npy"],
     "empty.toml"),
    (["info", "{tmp}/nokeys.dat"], "nokeys.dat.toml"),
    (["simulate", "nothere.png", "--out", "{tmp}/x.dat"], "nothere.png: not found"),
    (["simulate", "nothere.png", "--pan", "10", "0", "--out", "{tmp}/x.dat"], "nothere.png: not found"),
    (["simulate", "--demo", "--ticks", "0", "--out", "{tmp}/x.dat"], "--ticks 0"),
    (["simulate", "--demo", "--gt-every", "0", "--out", "{tmp}/x.dat"], "--gt-every 0"),
    (["simulate", "--demo", "--config", "{tmp}/empty.toml", "--out", "{tmp}/x.dat"], "empty.toml"),
    (["simulate", "--demo", "--size", "16", "--ticks", "10", "--out", "{tmp}/old.dat"], "--overwrite"),
    (["simulate", "--demo", "--size", "16", "--ticks", "10", "--config", "{tmp}/old.dat.toml", "--overwrite",
      "--out", "{tmp}/old.dat"], "input of the run"),
    # the synthetic motion flags: finite numbers, a zoom above 0, none with --demo (which has its own motion)
    (["simulate", "{tmp}/img.png", "--rotation", "inf", "--ticks", "10", "--out", "{tmp}/x.dat"], "--rotation inf"),
    (["simulate", "{tmp}/img.png", "--pan", "nan", "0", "--ticks", "10", "--out", "{tmp}/x.dat"], "--pan nan"),
    (["simulate", "{tmp}/img.png", "--zoom", "0", "--ticks", "10", "--out", "{tmp}/x.dat"], "--zoom 0"),
    (["simulate", "{tmp}/img.png", "--fan", "nan", "--ticks", "10", "--out", "{tmp}/x.dat"], "--fan nan"),
    (["simulate", "--demo", "--zoom", "2", "--ticks", "10", "--out", "{tmp}/x.dat"], "leave them out with --demo"),
    (["bench", "--quick", "--frames", "0"], "--frames 0"),
    (["bench", "--quick", "--size", "3"], "--size 3"),
    (["info", "{tmp}/bogus.dat"], "transfer = 'bogus'"),
])
def test_bad_input_gets_one_clear_sentence(capture, tmp_path, capsys, bad, needle):
    path, _ = capture
    (tmp_path / "old.npy").write_bytes(b"keep me")  # existing outputs: never replaced without --overwrite
    (tmp_path / "old.dat").write_bytes(b"keep me too")
    (tmp_path / "old.dat.toml").write_text("n_ticks = 10\n")
    (tmp_path / "empty.toml").write_text("# nothing here\n")
    (tmp_path / "nokeys.dat").write_bytes(bytes(64))
    (tmp_path / "nokeys.dat.toml").write_text('[stream]\nformat = "plain"\n')
    (tmp_path / "bogus.dat").write_bytes(bytes(64))
    (tmp_path / "bogus.dat.toml").write_text('[stream]\nformat = "plain"\nwidth = 8\nheight = 8\n\n'
                                             '[display]\ntransfer = "bogus"\n')
    from PIL import Image

    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(tmp_path / "img.png")
    argv = [a.format(cap=path, tmp=tmp_path) for a in bad]
    assert main(argv) == 1
    out = capsys.readouterr().err.strip()
    *before, err = out.splitlines()  # information printed before the failure (e.g. the slow-motion factor)
    assert not any("error" in line or "Traceback" in line for line in before), out
    assert err.startswith("spikeview: error:") and needle in err, out
    assert "Traceback" not in err
    assert "this is a bug" not in err and "unexpected" not in err, err  # the last-resort fallback is a bug
    assert "__init__" not in err and "'n_ticks'" not in err, err  # the user's words, not the code's
    assert (tmp_path / "old.npy").read_bytes() == b"keep me" and (tmp_path / "old.dat").read_bytes() == b"keep me too"
    assert (tmp_path / "old.dat.toml").read_text() == "n_ticks = 10\n"
    assert not list(tmp_path.glob("x*")), "no output may be left behind by a failed run"


@pytest.mark.parametrize("word, needle", [("infoo", "did you mean 'info'"), ("reconstrct", "did you mean 'reconstruct'"),
                                          ("frobnicate", "the commands are")])
def test_a_mistyped_command_is_named_not_opened_as_a_file(tmp_path, capsys, word, needle):
    """``spikeview infoo x.dat`` was read as the app opening ``infoo`` and failed on "unrecognized arguments: x.dat"."""
    assert main([word, str(tmp_path / "x.dat")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"spikeview: error: '{word}' is not a command nor a file") and needle in err, err
    assert len(err.splitlines()) == 1


def test_sigterm_ends_a_simulation_as_ctrl_c_does_and_leaves_no_file(tmp_path):
    """``kill``/``timeout`` send SIGTERM: the run stops, says so, and removes its unfinished output (the default action
    left the hidden temporary capture and ground truth behind)."""
    import signal
    import subprocess
    import sys
    import time

    p = subprocess.Popen([sys.executable, "-m", "spikeview", "simulate", "--demo", "--size", "128", "--ticks", "20000",
                          "--out", str(tmp_path / "s.dat")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(tmp_path.iterdir()):  # it has begun writing
        time.sleep(0.05)
    time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 143, err
    assert "spikeview: error: terminated" in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


def test_reconstruct_npy_matches_library_and_preset_reproduces(capture, tmp_path, capsys):
    from spikeview.classical.reconstruct import ClassicalConfig, reconstruct_frames
    from spikeview.io import open_source

    path, _ = capture
    out = tmp_path / "frames.npy"
    assert main(["reconstruct", str(path), *GEOM, "--range", "0:400:50", "--window", "10",
                 "--demosaic", "bilinear", "--out", str(out)]) == 0
    frames = np.load(out)
    assert frames.shape == (8, 64, 96, 3) and frames.dtype == np.float32
    assert 0.0 <= frames.min() and frames.max() <= 1.0
    # the npy holds the linear frames divided by the sequence's white point (printed, recorded in the
    # preset), clipped to [0, 1]
    from spikeview.config import load_toml

    preset = tmp_path / "frames.npy.preset.toml"
    assert preset.exists()
    white = load_toml(preset)["export"]["white"]
    assert f"white point {white:.4g}" in capsys.readouterr().err
    from spikeview.classical.calibration import attach

    with open_source(path, width=96, height=64, cfa="RGGB") as src:
        attach(src, None)  # the capture's own corrections (hot pixels, a dark rate), as the CLI opens it
        ref = np.stack(list(reconstruct_frames(src, range(0, 400, 50), ClassicalConfig(window=10, demosaic="bilinear"))))
    np.testing.assert_array_equal(frames, np.clip(ref * np.float32(1.0 / white), 0.0, 1.0))
    # clipped beyond half a quantisation step: at most 0.2 % (the white point is the 99.9th percentile of the
    # TFP values spread over their steps, so it may split the top level, whose values then clip by a few %)
    assert (ref * np.float32(1.0 / white) > 1.05).mean() <= 0.002
    # the preset beside the output re-runs the same reconstruction exactly
    again = tmp_path / "again.npy"
    assert main(["reconstruct", str(path), "--preset", str(preset), "--out", str(again)]) == 0
    np.testing.assert_array_equal(np.load(again), frames)


def test_reconstruct_tfi_png_sequence_and_mp4(capture, tmp_path, capsys):
    import av

    path, _ = capture
    assert main(["reconstruct", str(path), *GEOM, "--method", "tfi", "--range", "32:368:48",
                 "--out", str(tmp_path / "png" / "f_%03d.png")]) == 1  # folder does not exist: clear error
    (tmp_path / "png").mkdir()
    assert main(["reconstruct", str(path), *GEOM, "--method", "tfi", "--range", "32:368:48",
                 "--out", str(tmp_path / "png" / "f_%03d.png")]) == 0
    assert sorted(p.name for p in (tmp_path / "png").glob("*.png")) == [f"f_{i:03d}.png" for i in range(7)]
    mp4 = tmp_path / "clip.mp4"
    assert main(["reconstruct", str(path), *GEOM, "--range", "0:400:10", "--fps", "25", "--out", str(mp4)]) == 0
    err = capsys.readouterr().err
    assert "80× slow motion" in err  # 20000 / (10 * 25)
    with av.open(str(mp4)) as c:
        s = c.streams.video[0]
        assert (s.codec_context.width, s.codec_context.height) == (96, 64)
        assert s.average_rate == 25
        assert sum(1 for _ in c.decode(s)) == 40


def test_cli_subprocess_no_traceback(tmp_path):
    out = subprocess.run([sys.executable, "-m", "spikeview", "info", str(tmp_path / "nope.dat")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 1
    assert "Traceback" not in out.stderr and "nope.dat" in out.stderr


def test_simulate_then_guided_reconstruct_prints_plan_and_preset_reproduces(tmp_path, capsys):
    dat = tmp_path / "demo.dat"
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "60", "--seed", "3", "--out", str(dat)]) == 0
    assert dat.exists() and (tmp_path / "demo.dat.toml").exists() and (tmp_path / "demo.gt.npz").exists()
    out = tmp_path / "g.npy"
    assert main(["reconstruct", str(dat), "--method", "guided", "--steps", "2", "--range", "10:50:20",
                 "--seed", "1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "plan" in err and "mosaic" in err and "Bayer RGGB" in err
    frames = np.load(out)
    assert frames.shape == (2, 32, 32, 3) and np.isfinite(frames).all()
    assert 0.0 <= frames.min() and frames.max() <= 1.0
    again = tmp_path / "again.npy"
    assert main(["reconstruct", str(dat), "--preset", str(tmp_path / "g.npy.preset.toml"), "--out", str(again)]) == 0
    np.testing.assert_array_equal(np.load(again), frames)
    # a different seed gives a different sample: the seed is really used
    other = tmp_path / "other.npy"
    assert main(["reconstruct", str(dat), "--preset", str(tmp_path / "g.npy.preset.toml"), "--seed", "2",
                 "--out", str(other)]) == 0
    assert not np.array_equal(np.load(other), frames)


def test_a_shorter_sequence_over_a_longer_one_says_the_earlier_frames_remain(capture, tmp_path, capsys):
    path, _ = capture
    out = str(tmp_path / "f_%03d.png")
    assert main(["reconstruct", str(path), *GEOM, "--range", "0:200:20", "--out", out]) == 0
    assert "earlier run" not in capsys.readouterr().err
    assert main(["reconstruct", str(path), *GEOM, "--range", "0:100:20", "--out", out, "--overwrite"]) == 0
    err = capsys.readouterr().err
    assert "warning: 5 files named like f_005.png" in err and "this one wrote 5" in err, err
    assert len(list(tmp_path.glob("f_*.png"))) == 10  # said, not deleted: no one named them


def test_a_mistyped_option_names_the_nearest_and_a_choice_takes_any_case(capture, tmp_path, capsys):
    """argparse printed ~40 lines of usage before its error, and ``--methd`` was said by the top-level parser without
    the command's options; ``--method TFP`` was refused while ``--cfa rggb`` was taken."""
    path, _ = capture
    assert main(["reconstruct", str(path), *GEOM, "--methd", "tfp"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("spikeview reconstruct: error: unrecognized arguments: --methd tfp (did you mean --method?); "
                   "spikeview reconstruct --help lists the options"), err
    with pytest.raises(SystemExit) as e:
        main(["reconstruct", str(path), *GEOM, "--method", "fast"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "invalid choice: 'fast'" in err and "usage:" not in err, err
    assert main(["reconstruct", str(path), *GEOM, "--method", "TFP", "--at", "100", "--out", str(tmp_path / "a.npy")]) == 0
