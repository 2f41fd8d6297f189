"""The app on files it did not make (issue 14): a monochrome capture with ground truth beside it, opened
from disk, offscreen. Exposure, legend, Reset parameters, PSNR curves and the scene plan."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
from PySide6 import QtGui

from spikeview.cli.main import main

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]
WAIT_MS = 60_000


def _simulate(tmp_path, cfa: str):
    path = tmp_path / f"cap_{cfa}.dat"
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "120", "--cfa", cfa, "--gt-every", "10",
                 "--out", str(path)]) == 0
    return path


def _open(window, qtbot, path):
    window.open_path(path)
    qtbot.waitUntil(lambda: window.session.stream is not None and window.controller.capture_white is not None,
                    timeout=WAIT_MS)
    qtbot.waitUntil(lambda: window.rates_panel.last is not None, timeout=WAIT_MS)


def test_a_monochrome_capture_opens_exposed_like_the_command_line(window, qtbot, tmp_path):
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence
    from spikeview.recipe import Recipe

    path = _simulate(tmp_path, "none")
    _open(window, qtbot, path)
    s = window.session
    with open_source(path) as src:
        cli_white = prepare_sequence(src, Recipe()).white
    assert s.get("white") == pytest.approx(cli_white, rel=1e-6)  # the same number the CLI prints
    # no colour channels: no α R/G/B legend or curves
    rp = window.rates_panel
    assert not rp.alpha_plot.plotItem.legend.isVisible()
    assert not any(c.isVisible() for c in rp.alpha_curves)
    # Edit ▸ Reset parameters: the exposure goes back to the capture's white point, not to 1
    s.set("white", 1.0)
    window.reset_params()
    assert s.get("white") == pytest.approx(cli_white, rel=1e-6)


def test_a_colour_capture_keeps_its_alpha_legend_and_reset_white(window, qtbot, tmp_path):
    path = _simulate(tmp_path, "RGGB")
    _open(window, qtbot, path)
    rp = window.rates_panel
    assert rp.alpha_plot.plotItem.legend.isVisible() and all(c.isVisible() for c in rp.alpha_curves)
    white = window.controller.capture_white
    window.session.set("white", white / 2)
    window.reset_params()
    assert window.session.get("white") == pytest.approx(white)


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_psnr_curves_for_a_capture_with_ground_truth_beside_it(window, qtbot, tmp_path, cfa):
    path = _simulate(tmp_path, cfa)
    _open(window, qtbot, path)
    s, g = window.session, window.guided_panel
    assert s.stream.is_simulated and g.metrics_box.isVisibleTo(window)
    s.set_tick(60)  # a stored ground-truth frame (every 10 ticks)
    s.set("steps", 2)
    window.findChild(QtGui.QAction, "act_run").trigger()
    qtbot.waitUntil(lambda: window.controller.guided_result is not None, timeout=WAIT_MS * 3)
    r = window.controller.guided_result
    assert r.psnr is not None and np.isfinite(r.psnr) and 0 < r.ssim <= 1
    assert "no demosaic" in g.plan.toPlainText() if cfa == "none" else "demosaic" in g.plan.toPlainText()


def test_export_keeps_a_typed_path_and_defaults_to_a_writable_folder(window, qtbot, tmp_path, monkeypatch):
    import os
    from pathlib import Path

    path = _simulate(tmp_path, "RGGB")
    real_access = os.access
    # the capture's folder is read-only (a mounted card, a shared data set): exports go home, not there
    monkeypatch.setattr(os, "access", lambda p, mode, *a, **k: False if Path(p) == tmp_path else real_access(p, mode, *a, **k))
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: tmp_path / "home"))
    _open(window, qtbot, path)
    panel, s = window.export_panel, window.session
    assert Path(panel.path.text()).parent == tmp_path / "home"
    # a path the user gives (typed or pasted): a format change keeps it and changes only the suffix
    panel.path.setText(str(tmp_path / "out" / "my clip.png"))
    s.set("export_format", "exr")
    assert panel.path.text() == str(tmp_path / "out" / "my clip.exr")
    s.set("export_format", "mp4")
    assert panel.path.text() == str(tmp_path / "out" / "my clip.mp4")
    panel.path.setText(str(tmp_path / "out" / "noext"))
    s.set("export_format", "png")
    assert panel.path.text() == str(tmp_path / "out" / "noext.png")
    # the last export folder is the default for the next capture
    panel.remember_folder(tmp_path / "exports")
    window.set_stream(window.session.stream)
    window.export_panel._on_source()
    assert Path(panel.path.text()).parent == tmp_path / "exports"


def test_a_disabled_knob_looks_disabled(qapp):
    """The app's palette greys text and the slider fill of a disabled control (before: the disabled
    group had the active colours, so a greyed-out k looked like the live s slider)."""
    from PySide6 import QtGui

    from spikeview.gui.app import apply_style

    before, style = qapp.palette(), qapp.style().name()
    try:
        apply_style(qapp)
        pal = qapp.palette()
        group, role = QtGui.QPalette.ColorGroup, QtGui.QPalette.ColorRole
        for r in (role.WindowText, role.Text, role.ButtonText, role.Highlight):
            on, off = pal.color(group.Active, r), pal.color(group.Disabled, r)
            assert abs(on.lightness() - off.lightness()) > 40 or abs(on.saturation() - off.saturation()) > 100, r
    finally:
        qapp.setPalette(before)
        qapp.setStyle(style)


def test_pane_titles_that_do_not_fit_are_elided_with_the_full_text_in_a_tooltip(qtbot):
    from spikeview.gui.widgets import ElidedLabel

    label = ElidedLabel("guided run 3: x̂₀ at step 12 of 20, tick 1500, ROI 120x80 at (40, 20)")
    qtbot.addWidget(label)
    label.resize(120, 20)
    label.show()
    shown = label.shown_text()
    assert shown.endswith("…") and len(shown) < len(label.text()) and label.toolTip() == label.text()
    label.resize(2000, 20)
    assert label.shown_text() == label.text() and label.toolTip() == ""


def test_the_open_dialog_warns_about_a_colour_filter_read_as_monochrome(tmp_path, qapp):
    from test_geometry_guess import write_capture

    from spikeview.session import core
    from spikeview.gui.dialogs import settings_preview

    bayer = write_capture(tmp_path / "b.dat", 128, 96, 200, cfa=True)
    hint = settings_preview(core.open_file(bayer, width=128, height=96, cfa="none"))[3]
    assert "read as monochrome (CFA none)" in hint and "choose CFA RGGB" in hint and "--cfa" not in hint
    mono = write_capture(tmp_path / "m.dat", 128, 96, 200, cfa=False)
    assert settings_preview(core.open_file(mono, width=128, height=96, cfa="none"))[3] == ""


def test_an_ecosystem_file_opens_at_the_ecosystem_conversion_rate(window, qtbot, tmp_path):
    """A monochrome .dat without a sidecar firing 0.6 spikes per tick at white (a Spike-Zoo clip's convention): the app
    starts at the white point the command line prints (0.6), not its own estimate."""
    from spikeview.io.plain import write_plain
    from spikeview.session import core

    ramp = np.minimum(np.linspace(0.05, 1.0, 64) / 0.97, 1.0)
    rate = 0.6 * np.broadcast_to(ramp[None, :], (48, 64))
    v = np.random.default_rng(1).random(rate.shape)
    spikes = np.zeros((200,) + rate.shape, np.uint8)
    for t in range(200):
        v += rate
        spikes[t] = v >= 1.0
        v[spikes[t] > 0] -= 1.0
    path = tmp_path / "zoo_like.dat"
    write_plain(path, spikes, sidecar=False)
    window.set_stream(core.open_file(path, width=64, height=48, cfa=None))
    qtbot.waitUntil(lambda: window.controller.capture_white is not None, timeout=WAIT_MS)
    assert window.controller.capture_white == pytest.approx(0.6)
