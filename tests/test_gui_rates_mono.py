"""Rates panel and open dialog on a monochrome capture (found trying a Spike-Zoo clip at 1366×768): no α plot and no
"window α = (3.46)" for a capture without colour channels; a Bayer capture keeps both."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from test_gui_first_hour import OFFSCREEN_NOISE, WAIT_MS, _open, _simulate  # noqa: F401  (WAIT_MS used by _open)

pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_alpha_shown_only_for_colour_captures(window, qtbot, tmp_path, cfa):
    _open(window, qtbot, _simulate(tmp_path, cfa))
    rp = window.rates_panel
    colour = cfa != "none"
    assert rp.alpha_plot.isVisibleTo(window) == colour
    assert ("window α" in rp.summary.text()) == colour, rp.summary.text()
    # α in its unit, the one the plan's "gains η/α" divides the sampler's η by
    assert ("window α = 1/mean SFR = (" in rp.summary.text() and "ticks/spike" in rp.summary.text()) == colour
    assert "Mean SFR" in rp.summary.text()


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_open_dialog_hint_fits_the_cfa(qtbot, tmp_path, cfa):
    from spikeview.session import core
    from spikeview.gui.dialogs import StreamSettingsDialog

    path = _simulate(tmp_path, cfa)
    dlg = StreamSettingsDialog("Open", lambda **kw: core.open_file(path, **kw), {"cfa": cfa, "flip_vertical": True})
    qtbot.addWidget(dlg)
    dlg.update_preview()
    hint = dlg.hint.text()
    assert hint and ("greens" in hint) == (cfa != "none"), hint
