"""App on a monochrome capture (found opening a Spike-Zoo clip): the controls that act only through a colour
filter (demosaicking, the colour cast and its η) are disabled with the reason, and the degradation preview's
M and C panes say they are identities, as the plan does ("mosaic off", "cast off"); on a Bayer capture, and
after going back to one, all of them act again."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from spikeview.gui.widgets import MONO_TIP  # noqa: E402
from test_gui_first_hour import OFFSCREEN_NOISE, WAIT_MS, _open, _simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]


def _controls(window):
    sp, dp = window.stream_panel, window.degradation_panel
    return {"demosaic": sp.demosaic, "colour cast": sp.cast, "η": dp.eta}


@pytest.mark.parametrize("order", [("none", "RGGB"), ("RGGB", "none")])
def test_colour_only_controls_follow_the_capture(window, qtbot, tmp_path, order):
    panel = window.degradation_panel
    for cfa in order:
        path = _simulate(tmp_path, cfa)
        before = panel.updates
        _open(window, qtbot, path)
        qtbot.waitUntil(lambda: window.session.stream.path == path, timeout=WAIT_MS)  # the second one, too
        colour = cfa != "none"
        for name, control in _controls(window).items():
            assert control.isEnabled() == colour, (cfa, name)
            assert (control.toolTip() == MONO_TIP) != colour, (cfa, name, control.toolTip())
        panes = window.degradation_panel.panes
        assert ("monochrome" in panes["mx"].title.text()) != colour, panes["mx"].title.text()
        assert ("monochrome" in panes["cmx"].title.text()) != colour, panes["cmx"].title.text()
        # the preview's info line names η only where it acts (a colour filter)
        # (a view of the capture before may still arrive: wait for one of this capture)
        qtbot.waitUntil(lambda: panel.updates > before and panel.last.colour == colour
                        and panel.info.text().startswith("tick "), timeout=WAIT_MS)
        assert ("η =" in panel.info.text()) == colour, (cfa, panel.info.text())
