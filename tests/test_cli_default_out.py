"""``spikeview reconstruct`` without ``--out`` (the command of issue 15): a named default in the
current folder, never replacing a file unless ``--overwrite`` is given. Monochrome and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_reconstruct_without_out_writes_a_fresh_default_name_each_run(tmp_path, monkeypatch, capsys, cfa):
    src = tmp_path / "in" / "cap.npy"
    src.parent.mkdir()
    np.save(src, (np.random.default_rng(1).random((60, 16, 16)) < 0.3).astype(np.uint8))
    monkeypatch.chdir(tmp_path)
    argv = ["reconstruct", str(src), "--cfa", cfa, "--at", "30"]
    assert main(argv) == 0
    first = (tmp_path / "cap_tfp_t30.exr").read_bytes()
    assert (tmp_path / "cap_tfp_t30.exr.preset.toml").exists()
    assert main(argv) == 0  # the same command again: a new name, the first file kept byte for byte
    err = capsys.readouterr().err
    assert "writing cap_tfp_t30_2.exr" in err, err
    assert (tmp_path / "cap_tfp_t30.exr").read_bytes() == first
    assert (tmp_path / "cap_tfp_t30_2.exr").exists() and (tmp_path / "cap_tfp_t30_2.exr.preset.toml").exists()
    assert main(argv + ["--overwrite"]) == 0  # --overwrite: the plain name is replaced, no _3
    assert not (tmp_path / "cap_tfp_t30_3.exr").exists()
    assert main(["reconstruct", str(src), "--cfa", cfa, "--range", "10:50:10"]) == 0
    assert (tmp_path / "cap_tfp_10-50.mp4").stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "in").iterdir()) == ["cap.npy"]  # nothing beside the input


def test_preset_only_in_the_way_also_moves_to_the_next_name(tmp_path, monkeypatch):
    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(2).random((40, 8, 8)) < 0.3).astype(np.uint8))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cap_tfp_t20.exr.preset.toml").write_text("# mine\n")
    assert main(["reconstruct", str(src), "--cfa", "none", "--at", "20"]) == 0
    assert (tmp_path / "cap_tfp_t20.exr.preset.toml").read_text() == "# mine\n"
    assert (tmp_path / "cap_tfp_t20_2.exr").exists()


def test_a_file_that_is_not_a_capture_is_named_before_any_default_output(tmp_path, monkeypatch, capsys):
    (tmp_path / "pic.png").write_text("x")
    monkeypatch.chdir(tmp_path)
    assert main(["reconstruct", "pic.png", "--at", "10"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error: pic.png: not a spike file") and "writing" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pic.png"]


@pytest.mark.parametrize("out", ["", "nofolder/", "./"])
def test_an_out_that_names_no_file_gets_one_sentence(tmp_path, monkeypatch, capsys, out):
    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(3).random((40, 8, 8)) < 0.3).astype(np.uint8))
    monkeypatch.chdir(tmp_path)
    assert main(["reconstruct", str(src), "--cfa", "none", "--at", "20", "--out", out]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"spikeview: error: --out {out!r} names no file") and "\n" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap.npy"]


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_several_png_frames_without_a_field_are_refused_before_the_white_point(tmp_path, capsys, cfa):
    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(4).random((60, 8, 8)) < 0.3).astype(np.uint8))
    assert main(["reconstruct", str(src), "--cfa", cfa, "--range", "10:50:10", "--out", str(tmp_path / "seq.png")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error:") and "frame-number field" in err and "white point" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap.npy"]


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_the_printed_plan_says_auto_when_the_precision_was_not_given(tmp_path, capsys, cfa):
    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(5).random((40, 16, 16)) < 0.3).astype(np.uint8))
    out = tmp_path / "g.exr"
    assert main(["reconstruct", str(src), "--cfa", cfa, "--method", "guided", "--steps", "2", "--at", "20", "--out", str(out)]) == 0
    row = next(ln for ln in capsys.readouterr().err.splitlines() if ln.strip().startswith("precision"))
    assert "auto on this CPU" in row and "set by precision=" not in row, row
    assert 'precision = "' in (tmp_path / "g.exr.preset.toml").read_text()  # the preset holds what auto resolved to
    assert 'precision = "auto"' not in (tmp_path / "g.exr.preset.toml").read_text()


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_a_stopped_png_sequence_keeps_its_frames_and_their_preset(tmp_path, monkeypatch, capsys, cfa):
    import spikeview.pipeline as pipeline

    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(6).random((80, 8, 8)) < 0.3).astype(np.uint8))
    original = pipeline.reconstruct_windows

    def stops_after_two(*args, **kwargs):
        for i, frame in enumerate(original(*args, **kwargs)):
            if i == 2:
                raise KeyboardInterrupt
            yield frame

    monkeypatch.setattr(pipeline, "reconstruct_windows", stops_after_two)
    out = tmp_path / "f_%04d.png"
    assert main(["reconstruct", str(src), "--cfa", cfa, "--range", "10:70:10", "--out", str(out)]) == 130
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["cap.npy", "f.png.preset.toml", "f_0000.png", "f_0001.png"], names
    # and without any finished frame there is no preset
    monkeypatch.setattr(pipeline, "reconstruct_windows", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
    assert main(["reconstruct", str(src), "--cfa", cfa, "--range", "10:70:10", "--out", str(tmp_path / "h_%04d.png")]) == 130
    assert not any(p.name.startswith("h") for p in tmp_path.iterdir())


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_an_8bit_output_takes_the_captures_display_curve_and_says_so(tmp_path, capsys, cfa):
    """A capture without a sidecar (a Spike-Zoo or SpikeCV clip: spikes simulated from display values) is shown
    linearly by default, as its ecosystem shows it (the walk-through measured its PNGs 30-50 % too bright with the
    sRGB curve); spikeview's own captures (sidecar) keep sRGB; --transfer overrides; the line says which and why."""
    from spikeview.sim import SimConfig, simulate_to_file
    from spikeview.sim.scenes import StaticScene

    scene = StaticScene(np.full((24, 32, 3), 0.4, dtype=np.float32))
    files = simulate_to_file(scene, SimConfig(n_ticks=60, width=32, height=24, cfa=cfa, seed=1), tmp_path / "sim.dat")
    flags = ["--method", "tfp", "--cfa", cfa]

    def err_of(*extra):
        capsys.readouterr()
        at = [] if "--range" in extra else ["--at", "30"]
        assert main(["reconstruct", str(files.dat), *flags, *at, *extra]) == 0
        return capsys.readouterr().err

    def png_mean(name):
        import OpenImageIO as oiio

        return float(np.asarray(oiio.ImageBuf(str(tmp_path / name)).get_pixels(oiio.UINT8)).mean())

    own = err_of("--out", str(tmp_path / "a.png"))
    assert "display curve srgb (" in own  # spikeview's own sidecar: linear light, the sRGB curve
    files.sidecar.unlink()
    plain = ["--width", "32", "--height", "24"]
    eco = err_of(*plain, "--out", str(tmp_path / "b.png"))
    assert eco.count("display curve linear (a capture without a sidecar") == 1
    assert "display curve linear" in err_of(*plain, "--range", "10:50:10", "--out", str(tmp_path / "b.mp4"))
    assert "display curve" not in err_of(*plain, "--out", str(tmp_path / "b.exr"))  # linear values: no display curve
    assert "display curve" not in err_of(*plain, "--transfer", "srgb", "--out", str(tmp_path / "c.png"))  # the user's
    assert png_mean("b.png") < png_mean("c.png") - 20  # linear is darker than sRGB on a mid-grey scene
    assert png_mean("a.png") == pytest.approx(png_mean("c.png"), abs=1)  # the sidecar's sRGB = the flag's
    from spikeview.recipe import Recipe

    assert Recipe.load(tmp_path / "b.png.preset.toml").export.transfer == "linear"  # recorded as resolved


