"""The first hour's rough edges in the terminal (issue 14, item 5): each one checked here."""

from __future__ import annotations

from spikeview.cli.main import main


def test_a_missing_file_is_named_before_the_missing_display(tmp_path, monkeypatch, capsys):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    assert main([str(tmp_path / "nosuch.dat")]) == 1
    err = capsys.readouterr().err
    assert "nosuch.dat: file not found" in err and "display" not in err


def _capture(tmp_path):
    from test_geometry_guess import write_capture

    return write_capture(tmp_path / "c.dat", 32, 32, 200, cfa=True, sidecar=True)


def test_arguments_are_checked_before_any_informational_line(tmp_path, capsys):
    cap = _capture(tmp_path)
    assert main(["reconstruct", str(cap), "--at", "100", "--out", str(tmp_path / "z.xyz")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("spikeview: error: ") and "unknown export format '.xyz'" in err and "white point" not in err


def test_a_leftover_settings_file_gets_a_clear_sentence_first(tmp_path, capsys):
    cap = _capture(tmp_path)
    out = tmp_path / "lo.npy"
    assert main(["reconstruct", str(cap), "--at", "100", "--out", str(out)]) == 0
    out.unlink()  # the user deleted the output; its settings files stayed
    capsys.readouterr()
    assert main(["reconstruct", str(cap), "--at", "100", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "settings file of an earlier run whose output lo.npy is gone" in err and "white point" not in err
    assert main(["reconstruct", str(cap), "--at", "100", "--out", str(out), "--overwrite"]) == 0


def test_an_mp4_without_at_or_range_says_it_holds_one_frame(tmp_path, capsys):
    cap = _capture(tmp_path)
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "v.mp4")]) == 0
    assert "the video holds one frame" in capsys.readouterr().err


def test_the_npy_layout_hint_uses_the_command_line_syntax(tmp_path):
    import numpy as np

    from spikeview.io import open_source

    path = tmp_path / "a.npy"
    np.save(path, (np.random.default_rng(0).random((20, 30, 40)) < 0.3).astype(np.uint8))
    with open_source(path) as src:
        assert any("--layout hwt" in w for w in src.info.warnings)


def test_simulate_names_the_users_file_not_its_temporary(tmp_path, capsys, monkeypatch):
    from test_full_disk import fail_writes_under

    out = tmp_path / "out"
    out.mkdir()
    fail_writes_under(monkeypatch, out, "write", 20_000, ".dat.tmp")
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "3000", "--gt-every", "10", "--no-noise",
                 "--out", str(out / "s.dat")]) == 1
    err = capsys.readouterr().err
    assert "s.dat" in err and ".tmp" not in err


def test_the_scene_plan_prints_the_same_numbers_in_the_cli_and_the_app(tmp_path, capsys):
    """One unit: the plan of the settings the sampler runs (η at the sequence's exposure) in both (the app's jobs
    plan their window with pipeline.plan_window, as the CLI)."""
    from spikeview.io import open_source
    from spikeview.pipeline import plan_window, prepare_sequence
    from spikeview.recipe import Recipe

    cap = _capture(tmp_path)
    assert main(["reconstruct", str(cap), "--at", "100", "--method", "guided", "--steps", "1",
                 "--out", str(tmp_path / "g.npy")]) == 0
    cli = next(ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("plan ("))
    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 1})
    with open_source(cap) as src:
        state = prepare_sequence(src, recipe)
        app = str(plan_window(src, recipe, 100, state=state).plan).splitlines()[0]
    assert cli == app and "/255 of the image the sampler sees" in cli
