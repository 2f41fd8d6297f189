"""The app at full resolution (issue 15, item 3), offscreen with pytest-qt: a tiled guided run shows
the whole frame filling in tile by tile (every step's preview is the frame, not a tile), for a Bayer
and a monochrome capture. Cancel inside a prior pass: tests/test_cancel_latency.py."""

from __future__ import annotations

import functools

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from spikeview.gui import core  # noqa: E402

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]
WAIT_MS = 60_000  # generous: the machine is shared; nothing here measures speed
SIZE = 128


@functools.cache
def _capture():
    from spikeview.sim.demo import demo_capture

    return demo_capture(size=SIZE, n_ticks=120, seed=2)


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tiled_guided_run_fills_in_the_whole_frame(window, qtbot, cfa):
    cap = _capture()
    window.set_stream(core.memory_stream(cap, "test capture", None, cfa=cfa, _use_cfa=True))
    qtbot.waitUntil(lambda: window.controller.last_frames is not None, timeout=WAIT_MS)
    s = window.session
    s.set("tile", 64)
    s.set("steps", 2)
    s.set("precision", "float32")
    steps = []
    window.controller.guided_update.connect(lambda u: steps.append(u) if u.kind == "step" else None)
    window.controller.run_guided()
    qtbot.waitUntil(lambda: window.controller.guided_result is not None, timeout=WAIT_MS * 3)
    r = window.controller.guided_result
    assert f"{SIZE}×{SIZE} in" in r.plan  # the plan's tile map line
    shape = (SIZE, SIZE, 3) if cfa else (SIZE, SIZE)
    assert r.image.shape == shape
    assert len(steps) >= 3 and all(u.preview.shape[:2] == (SIZE, SIZE) for u in steps)
    # the first preview has only the first tile (top left): the bottom-right corner is still empty;
    # the last one is the whole frame
    first, last = steps[0].preview, steps[-1].preview
    assert first[-16:, -16:].max() == 0 and first[:16, :16].max() > 0
    assert last[-16:, -16:].max() > 0
    assert steps[-1].step == steps[-1].total == window.guided_panel.progress.maximum()
    assert window.controller.errors == []
