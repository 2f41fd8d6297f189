"""The degradation panel's Fit in every layout (issue 27: Fit broke in the two-pane views without X, whose hidden X pane
still drove the shared zoom): the shown panes zoom together and Fit shows the whole image in each. Mono and colour."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

pytestmark = [pytest.mark.gui]


@pytest.mark.parametrize("colour", [True, False])
def test_fit_shows_the_whole_image_in_every_layout(qtbot, colour):
    from spikeview.gui.app import configure_pyqtgraph
    from spikeview.gui.panels.degradation import LAYOUTS, DegradationPanel
    from spikeview.session.model import Session

    configure_pyqtgraph()
    panel = DegradationPanel(Session())
    qtbot.addWidget(panel)
    panel.resize(900, 600)
    panel.show()
    shape = (200, 300, 3) if colour else (200, 300)
    img = (np.random.default_rng(0).random(shape) * 255).astype(np.uint8)
    for pane in panel.panes.values():
        pane.set_image(img)
    for key in LAYOUTS:
        panel.set_layout(key)
        shown = [panel.panes[k] for k in LAYOUTS[key][1]]
        qtbot.waitUntil(lambda: all(p.isVisible() and p.covers_image() for p in shown), timeout=5000)
        shown[-1].vb.scaleBy((0.3, 0.3))  # the user zooms into the last pane: every shown pane follows
        shown[-1].vb.sigRangeChangedManually.emit(None)
        qtbot.waitUntil(lambda: not any(p.covers_image() for p in shown), timeout=5000)
        panel.fit_btn.click()
        qtbot.waitUntil(lambda: all(p.covers_image() for p in shown), timeout=5000)
        ranges = np.array([np.ravel(p.vb.viewRange()) for p in shown])
        assert np.abs(ranges - ranges[0]).max() <= 1.0, (key, ranges)  # the same view in each (within a pixel)
