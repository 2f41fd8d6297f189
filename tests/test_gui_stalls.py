"""The window's thread stays free while the app works (issue 15, item 3: no stall over 50 ms at 1000×1000).

Measured in benchmarks/bench_ui_stalls.py; here, without any clock, the tests pin *where* the heavy work
runs, so that it cannot drift back onto the GUI thread: the colour mapping of every image the window shows
(stream frames, degradation stages, the guided run's x̂₀ per step, the pooling map) happens in a worker, and
the recipe (a check of every field, ~15 ms) is built once per change of the values, not on every event.
Monochrome and RGGB.
"""

from __future__ import annotations

import gc
import threading

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from spikeview.session import core  # noqa: E402
from spikeview.io.source import ArraySource  # noqa: E402

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]
WAIT_MS = 60_000  # the machine is shared; nothing here measures speed
SIZE, TICKS = 48, 90


def capture(cfa: str | None) -> ArraySource:
    rng = np.random.default_rng(3)
    rates = np.clip(rng.random((SIZE, SIZE)).astype(np.float32), 0.1, 0.8)
    return ArraySource((rng.random((TICKS, SIZE, SIZE)) < rates).astype(np.uint8), cfa=cfa)


def open_capture(window, qtbot, cfa):
    label = f"stall test {cfa}"
    window.set_stream(core.memory_stream(capture(cfa), label))
    c = window.controller
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.label == label, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: c.last_frames is not None and window.degradation_panel.last is not None
                    and window.guided_panel.pooling_map.pooling is not None, timeout=WAIT_MS)


class Threads:
    """Wraps a function and records the thread of every call."""

    def __init__(self, fn):
        self.fn, self.threads = fn, []

    def __call__(self, *args, **kwargs):
        self.threads.append(threading.current_thread())
        return self.fn(*args, **kwargs)

    def on_gui_thread(self) -> int:
        return sum(t is threading.main_thread() for t in self.threads)


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_display_conversions_run_in_workers(window, qtbot, monkeypatch, cfa):
    """Every float → uint8 display conversion (stream, degradation, x̂₀ of each guided step, the result) and
    the pooling map's colours are made off the GUI thread."""
    import spikeview.gui.panels.pooling as pooling

    to_display = Threads(core.to_display)
    colours = Threads(core.POOLING_PALETTE or pooling.palette)  # the app's palette, as the session's jobs call it
    monkeypatch.setattr(core, "to_display", to_display)
    monkeypatch.setattr(core, "POOLING_PALETTE", colours)
    open_capture(window, qtbot, cfa)
    s, c = window.session, window.controller
    s.set("steps", 2)
    steps = []
    c.guided_update.connect(lambda u: steps.append(u) if u.kind == "step" else None)
    run = c.run_guided()
    qtbot.waitUntil(lambda: c.guided_result is not None and c.guided_result.run == run, timeout=WAIT_MS * 3)
    qtbot.waitUntil(lambda: not c.preview.is_active() and not c.guided.is_active(), timeout=WAIT_MS)
    assert len(steps) == 2 and all(u.preview is not None and u.preview.dtype == np.uint8 for u in steps)
    assert window.guided_panel.pooling_map.pane.image() is not None  # the map is shown …
    assert colours.threads and colours.on_gui_thread() == 0  # … and was coloured in a worker
    assert len(to_display.threads) >= 4 and to_display.on_gui_thread() == 0


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_the_recipe_is_built_once_per_change(window, qtbot, monkeypatch, cfa):
    """Opening a capture asks for the session's recipe many times (previews, export panel, α); it is built
    once for a set of values and again only when a value changes."""
    from spikeview.recipe import Recipe

    builds = Threads(Recipe.with_values)
    monkeypatch.setattr(Recipe, "with_values", lambda self, *a, **k: builds(self, *a, **k))
    open_capture(window, qtbot, cfa)
    s = window.session
    # the session's recipe and the export panel's (with the stream and the range) once each; the α job's
    # result sets the white point (a change): once more each
    assert builds.on_gui_thread() <= 4, builds.on_gui_thread()
    first = s.recipe()
    assert s.recipe() is first  # same values: not rebuilt
    s.set("k", float(s.get("k")) + 1.0)
    second = s.recipe()
    assert second is not first and second.guided.k == pytest.approx(float(s.get("k")))
    assert s.recipe() is second


def test_the_heap_is_frozen_before_the_window_shows(window):
    """The objects loaded at start-up (torch, numba, pyqtgraph, the widgets) are out of the collector's reach
    before the first file opens: the first open's collection walked all of them on the GUI thread."""
    assert gc.get_freeze_count() > 100_000


def test_a_notice_does_not_re_lay_out_the_window(window, qtbot):
    """Showing or dismissing a message (an export's "finished", an error) leaves every dock where it was: a
    strip that appeared and vanished resized every dock and repainted every view (~30 ms of the GUI thread
    at 1000×1000, the stall at the end of an export)."""
    from PySide6 import QtWidgets

    def geometries():
        return {d.objectName(): d.geometry().getRect() for d in window.findChildren(QtWidgets.QDockWidget) if d.isVisible()}

    qtbot.wait(50)
    before = geometries()
    assert before
    window.notice.show_message("Export finished: 12 frames written to /tmp/a_rather_long_folder/clip.mp4. " * 4, "success",
                               [("Open", lambda: None), ("Open folder", lambda: None)])
    qtbot.wait(50)
    assert window.notice.is_shown() and "clip.mp4" in window.notice.text()
    assert geometries() == before
    window.notice.dismiss()
    qtbot.wait(50)
    assert geometries() == before and window.notice.text() == ""
