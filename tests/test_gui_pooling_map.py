"""The guided panel's pooling map (issue 16): Δτ_eff per photosite of the current window, from the library.

Small simulated captures (a static texture and a panned one, monochrome and RGGB) are opened in the
app; the map the panel shows must be the library's ``Pooling.dtau`` of the window's observation
(:meth:`spikeview.guided.observation.Observation.from_source`, the sampler's), its colours must count
the pooled neighbours, its caption must be the plan's temporal reason, and the "Map" button must be
disabled with the reason where nothing can be pooled (``temporal_radius = 0``, a capture too short).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from spikeview.session import core
from spikeview.gui.panels.pooling import palette
from spikeview.guided.observation import Observation
from spikeview.io.source import ArraySource

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]

WAIT_MS = 60_000  # the machine is shared; nothing here measures speed
SIZE = 48
TICKS = 90


def _texture(seed: int = 0) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    t = gaussian_filter(rng.random((SIZE + 64, SIZE + 64)), 2.0)
    t = (t - t.min()) / (t.max() - t.min())
    return (0.1 + 0.8 * t).astype(np.float32)


def capture(motion: str, cfa: str | None, ticks: int = TICKS) -> ArraySource:
    """Bernoulli spikes of a texture, still (``"static"``) or panned 0.3 px per tick (``"moving"``: 3 px per window)."""
    tex = _texture()
    speed = 0.0 if motion == "static" else 0.3
    rates = np.stack([tex[8:8 + SIZE, 8 + int(round(speed * t)):8 + int(round(speed * t)) + SIZE]
                      for t in range(ticks)]) * 0.6
    rng = np.random.default_rng(1)
    return ArraySource((rng.random(rates.shape) < rates).astype(np.uint8), cfa=cfa)


def open_capture(window, qtbot, src: ArraySource, label: str):
    window.set_stream(core.memory_stream(src, label))
    panel = window.guided_panel
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.label == label, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: panel.pooling_map.pooling is not None, timeout=WAIT_MS)
    return panel


def library_pooling(window, src: ArraySource):
    rec = window.session.recipe()
    obs = Observation.from_source(src, window.session.tick, rec.guided.window, radius=rec.guided.temporal_radius, eta=2.0)
    return obs.pooling


@pytest.mark.parametrize("cfa", [None, "RGGB"])
@pytest.mark.parametrize("motion", ["static", "moving"])
def test_the_pooling_map_is_the_library_dtau(window, qtbot, motion, cfa):
    src = capture(motion, cfa)
    panel = open_capture(window, qtbot, src, f"{motion} {cfa}")
    assert window.session.get("temporal_radius") == 3  # the default pools ±3 windows
    pool = library_pooling(window, src)
    assert pool.dtau is not None and len(pool.offsets) == 6
    shown = panel.pooling_map
    qtbot.waitUntil(lambda: shown.dtau is not None, timeout=WAIT_MS)
    np.testing.assert_array_equal(shown.dtau, pool.dtau)
    # colours count the pooled neighbours, 0 (own window only) … 6 (±3 windows)
    n = np.rint(pool.dtau / pool.window - 1).astype(int)
    np.testing.assert_array_equal(shown.pane.image(), palette(6)[n])
    assert shown.caption.text() == pool.reason == panel.pooling_map.pooling.reason
    assert pool.reason in window.degradation_panel.last.plan  # the plan's temporal row
    assert "±3 windows" in shown.legend.text()
    if motion == "static":
        assert pool.kind == "static" and (n == 6).mean() > 0.8
    else:  # 3 px per window: the neighbours are aligned (or rejected), never pooled in place
        assert pool.kind != "static"
        assert any(np.abs(pool.shifts[k][pool.accepted[k]]).max(initial=0) > 0 for k in pool.offsets) or (n == 0).mean() > 0.5
    # the button shows the map in place of x̂₀
    assert panel.pool_btn.isEnabled()
    panel.pool_btn.click()
    qtbot.waitUntil(lambda: shown.isVisible() and not panel.preview.isVisible(), timeout=WAIT_MS)
    assert window.controller.enabled["pooling"]

    # radius 0: no map, the button is disabled with the reason
    window.session.set("temporal_radius", 0)
    qtbot.waitUntil(lambda: not panel.pool_btn.isEnabled(), timeout=WAIT_MS)
    assert shown.dtau is None and shown.pane.image() is None
    assert "temporal_radius is 0" in panel.pool_btn.toolTip()
    assert not panel.pool_btn.isChecked() and panel.preview.isVisible()
    assert library_pooling(window, src).dtau is None  # the library agrees: nothing pooled
    # back to ±2: the map returns, again the library's
    window.session.set("temporal_radius", 2)
    qtbot.waitUntil(lambda: panel.pool_btn.isEnabled() and shown.dtau is not None, timeout=WAIT_MS)
    np.testing.assert_array_equal(shown.dtau, library_pooling(window, src).dtau)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_a_capture_too_short_has_no_pooling_map(window, qtbot, cfa):
    src = capture("static", cfa, ticks=10)
    panel = open_capture(window, qtbot, src, f"short {cfa}")
    qtbot.waitUntil(lambda: panel.pooling_map.why_not is not None and "10 ticks" in panel.pooling_map.why_not,
                    timeout=WAIT_MS)
    assert not panel.pool_btn.isEnabled()
    assert "10 ticks" in panel.pool_btn.toolTip() and panel.pooling_map.dtau is None
    # the same sentence as the Neighbours ± control's (knob_status)
    assert panel.pooling_map.why_not in panel.temporal.toolTip()
