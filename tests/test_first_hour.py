"""The first hour's rough edges in the terminal (issue 14, item 5): each one checked here."""

from __future__ import annotations

from spikeview.cli.main import main


def test_a_missing_file_is_named_before_the_missing_display(tmp_path, monkeypatch, capsys):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    assert main([str(tmp_path / "nosuch.dat")]) == 1
    err = capsys.readouterr().err
    assert "nosuch.dat: file not found" in err and "display" not in err
