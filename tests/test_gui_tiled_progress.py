"""The app at full resolution (issue 15, items 2–3), offscreen with pytest-qt: a tiled guided run shows
the whole frame after every step (tiles step together), and the guided panel's "Tiles" toggle draws
the plan's tile map over x̂₀ (one box per tile, coloured by skipped / short / full), disabled with the
plan's reason when tiles are off — for a Bayer and a monochrome capture. Cancel inside a prior pass:
tests/test_cancel_latency.py."""

from __future__ import annotations

import functools

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from spikeview.session import core  # noqa: E402

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]
WAIT_MS = 60_000  # generous: the machine is shared; nothing here measures speed
SIZE = 128


@functools.cache
def _capture():
    from spikeview.sim.demo import demo_capture

    return demo_capture(size=SIZE, n_ticks=120, seed=2)


def _run(window, qtbot, cfa, tile):
    window.set_stream(core.memory_stream(_capture(), "test capture", None, cfa=cfa, _use_cfa=True))
    qtbot.waitUntil(lambda: window.controller.last_frames is not None, timeout=WAIT_MS)
    s = window.session
    s.set("tile", tile)
    s.set("steps", 2)
    s.set("precision", "float32")
    steps = []
    window.controller.guided_update.connect(lambda u: steps.append(u) if u.kind == "step" else None)
    window.controller.run_guided()
    qtbot.waitUntil(lambda: window.controller.guided_result is not None, timeout=WAIT_MS * 3)
    return steps


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tiled_run_shows_the_whole_frame_and_the_tile_map(window, qtbot, cfa):
    from spikeview.gui.panels.guided import TILE_COLOURS

    steps = _run(window, qtbot, cfa, 64)
    r = window.controller.guided_result
    assert f"{SIZE}×{SIZE} in 4 tiles of 64 px" in r.plan  # the plan's tile map line
    shape = (SIZE, SIZE, 3) if cfa else (SIZE, SIZE)
    assert r.image.shape == shape
    assert [u.step for u in steps] == [1, 2] and all(u.preview.shape[:2] == (SIZE, SIZE) for u in steps)
    assert steps[0].preview[-16:, -16:].max() > 0  # the whole frame from the first step (tiles step together)
    assert steps[-1].step == steps[-1].total == window.guided_panel.progress.maximum()
    panel = window.guided_panel
    qtbot.waitUntil(lambda: panel.tiles_btn.isEnabled(), timeout=WAIT_MS)
    assert "in 4 tiles" in panel.tiles_btn.toolTip()
    assert panel._tile_items == []  # off until asked
    panel.tiles_btn.setChecked(True)
    tm = panel._tile_map
    assert len(panel._tile_items) == len(tm["tiles"]) == 4
    for item, (y0, y1, x0, x1, kind, _steps) in zip(panel._tile_items, tm["tiles"], strict=True):
        assert item.scene() is panel.preview.vb.scene()
        box = item.rect()
        assert (box.x(), box.y(), box.width(), box.height()) == (x0, y0, x1 - x0, y1 - y0)
        assert item.pen().color().getRgb()[:3] == TILE_COLOURS[kind]
    covered = sum((y1 - y0) * (x1 - x0) for y0, y1, x0, x1, *_ in tm["tiles"])
    assert covered == SIZE * SIZE  # the tiles partition the frame
    panel.tiles_btn.setChecked(False)
    assert panel._tile_items == []
    assert window.controller.errors == []


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tile_map_toggle_says_why_when_tiles_are_off(window, qtbot, cfa):
    _run(window, qtbot, cfa, 0)
    panel = window.guided_panel
    qtbot.waitUntil(lambda: "guided.tile = 0" in panel.tiles_btn.toolTip(), timeout=WAIT_MS)
    assert not panel.tiles_btn.isEnabled() and panel._tile_items == []
    assert window.controller.errors == []
