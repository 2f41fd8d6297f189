"""The desktop app, offscreen (pytest-qt): open, scrub, sliders, guided runs, export, errors.

Every test here fails on a Qt warning (``qt_log_level_fail``). The one message ignored is the
offscreen platform plugin's "does not support propagateSizeHints()", which the plugin prints for any
dock widget and which does not exist on a real display (X11, Wayland, Windows, macOS).
"""

from __future__ import annotations

import functools
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")
from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.session import core
from spikeview.gui.app import configure_pyqtgraph
from spikeview.gui.main_window import MainWindow
from spikeview.session.model import SPECS
from spikeview.gui.widgets import ParamSlider

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]

WAIT_MS = 60_000  # generous: the test machine is shared; nothing here measures speed


@functools.cache
def _demo():
    from spikeview.sim.demo import demo_capture

    return demo_capture(size=64, n_ticks=240, seed=1)


def demo_stream() -> core.OpenedStream:
    """A tiny simulated capture (64×64, 240 ticks, RGGB, ground truth known)."""
    cap = _demo()
    return core.memory_stream(cap, "test capture", cap.gt_at)


def frames_at(window, tick: int):
    f = window.controller.last_frames
    return f is not None and f.tick == tick and window.stream_panel.tfp.image() is not None


@pytest.fixture
def opened(window, qtbot):
    """The window with the tiny capture open and its first previews shown."""
    window.set_stream(demo_stream())
    qtbot.waitUntil(lambda: frames_at(window, window.session.tick), timeout=WAIT_MS)
    qtbot.waitUntil(lambda: window.rates_panel.last is not None, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: window.degradation_panel.last is not None, timeout=WAIT_MS)
    return window


def write_plain_dat(path: Path, spikes: np.ndarray) -> None:
    """The ecosystem's plain format: rows flipped, LSB-first packed, no header."""
    t = spikes.shape[0]
    flipped = spikes[:, ::-1].reshape(t, -1)
    np.packbits(flipped, axis=1, bitorder="little").tofile(path)


# ------------------------------------------------------------------------------------ opening
def test_no_argument_opens_the_demo_capture(window, qtbot):
    window.open_demo(size=32, n_ticks=120)
    qtbot.waitUntil(lambda: window.session.stream is not None, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: frames_at(window, window.session.tick), timeout=WAIT_MS)
    st = window.session.stream
    assert st.label == "demo capture" and st.is_simulated and st.source.cfa == "RGGB"
    assert window.windowTitle() == "demo capture — spikeview"
    tfp = window.stream_panel.tfp.image()
    assert tfp.shape == (32, 32, 3) and tfp.dtype == np.uint8 and tfp.std() > 0  # a real picture
    assert window.controller.errors == []


def test_open_a_plain_file_asks_geometry_with_a_live_preview(window, qtbot, tmp_path):
    spikes = _demo().read(0, 120)
    path = tmp_path / "capture.dat"
    write_plain_dat(path, spikes)
    window.open_path(path)
    qtbot.waitUntil(lambda: window.settings_dialog is not None, timeout=WAIT_MS)
    dlg = window.settings_dialog
    dlg.width_spin.setValue(64)
    dlg.height_spin.setValue(64)
    dlg.cfa.setCurrentIndex(dlg.cfa.findData("RGGB"))
    dlg.flip.setChecked(True)
    dlg.update_preview()
    assert dlg.error.text() == "" and dlg.preview.image().shape == (64, 64, 3)
    right = dlg.preview.image().astype(float)
    dlg.flip.setChecked(False)  # a wrong flip on an even height is a wrong CFA phase: colours change
    dlg.update_preview()
    assert np.abs(dlg.preview.image().astype(float) - right).mean() > 10
    dlg.flip.setChecked(True)
    dlg.update_preview()
    assert dlg.remember.isVisible()
    dlg.remember.setChecked(True)
    dlg.accept()
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.path == path, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: frames_at(window, window.session.tick), timeout=WAIT_MS)
    src = window.session.source
    assert (src.width, src.height, src.n_frames, src.cfa) == (64, 64, 120, "RGGB")
    np.testing.assert_array_equal(src.read(10, 12), spikes[10:12])  # decoded the right way up
    assert window.recent_files()[0]["path"] == str(path)
    # the sidecar was written: the next open asks nothing
    assert (tmp_path / "capture.dat.toml").exists()
    window.session.set_tick(3)
    window.open_path(path)
    qtbot.waitUntil(lambda: window.session.tick == 60, timeout=WAIT_MS)  # re-opened: centre tick
    assert window.settings_dialog is None and window.session.source.cfa == "RGGB"


def test_open_npy_and_drop_a_file(window, qtbot, tmp_path):
    spikes = _demo().read(0, 100)
    path = tmp_path / "spikes.npy"
    np.save(path, spikes)
    mime = QtCore.QMimeData()
    mime.setUrls([QtCore.QUrl.fromLocalFile(str(path))])
    ev = QtGui.QDropEvent(QtCore.QPointF(10, 10), QtCore.Qt.DropAction.CopyAction, mime,
                          QtCore.Qt.MouseButton.LeftButton, QtCore.Qt.KeyboardModifier.NoModifier)
    window.dropEvent(ev)
    qtbot.waitUntil(lambda: window.settings_dialog is not None, timeout=WAIT_MS)  # no sidecar: CFA unknown
    dlg = window.settings_dialog
    assert "Detected npz, 64×64" in dlg.message.text() and dlg.cfa.currentData() == "RGGB"
    dlg.accept()
    qtbot.waitUntil(lambda: window.session.stream is not None, timeout=WAIT_MS)
    assert window.session.source.shape == (100, 64, 64) and window.session.source.cfa == "RGGB"


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_a_sheared_width_is_said_with_a_button_that_reopens_it_right(window, qtbot, tmp_path, cfa):
    """The CLI refuses to write a capture whose rows the spikes show sheared (tests/test_geometry_guess.py); the app
    opens it as asked, says so, and its notice's button reopens it at the size the spikes point to."""
    from tests.test_geometry_guess import write_capture

    path = write_capture(tmp_path / "c.dat", 128, 96, 200, cfa=cfa != "none")
    window.open_path(path, width=192, height=64, cfa=cfa)
    qtbot.waitUntil(lambda: window.session.stream is not None and window.notice.is_shown(), timeout=WAIT_MS)
    assert window.notice.kind == "warning" and "do not line up" in window.notice.text()
    buttons = [b for b in window.notice.findChildren(QtWidgets.QPushButton) if b.text() == "Reopen as 128×96"]
    assert len(buttons) == 1, [b.text() for b in window.notice.findChildren(QtWidgets.QPushButton)]
    buttons[0].click()
    qtbot.waitUntil(lambda: window.session.source.shape[1:] == (96, 128), timeout=WAIT_MS)
    assert (window.session.source.cfa or "none") == cfa
    assert window.session.source.info.likely_size is None and not window.notice.is_shown()


@pytest.mark.parametrize("content", [None, b"", b"not numpy at all"])
def test_a_bad_file_is_an_error_message_not_a_crash(window, qtbot, tmp_path, content):
    path = tmp_path / ("missing.npy" if content is None else "bad.npy")
    if content is not None:
        path.write_bytes(content)
    window.open_path(path)
    qtbot.waitUntil(lambda: window.notice.is_shown(), timeout=WAIT_MS)
    assert window.notice.kind == "error" and path.name in window.notice.text()
    assert window.session.stream is None and window.isVisible()


# ------------------------------------------------------------------------------------ stream
def test_scrub_step_and_keyboard(opened, qtbot):
    w, s = opened, opened.session
    w.stream_panel.scrub.setValue(37)
    assert s.tick == 37
    qtbot.waitUntil(lambda: frames_at(w, 37), timeout=WAIT_MS)
    assert "tick 37" in w.stream_panel.time_label.text() and "1\u2009850 µs" in w.stream_panel.time_label.text()
    qtbot.mouseClick(w.stream_panel.fwd_btn, QtCore.Qt.MouseButton.LeftButton)
    assert s.tick == 38
    w.activateWindow()
    w.setFocus()
    for key, expect in ((QtCore.Qt.Key.Key_Left, 37), (QtCore.Qt.Key.Key_End, 239), (QtCore.Qt.Key.Key_Home, 0)):
        w.findChild(QtGui.QAction, {"Left": "act_back", "End": "act_end", "Home": "act_home"}[key.name[4:]]).trigger()
        assert s.tick == expect
    qtbot.waitUntil(lambda: frames_at(w, 0), timeout=WAIT_MS)
    f = w.controller.last_frames
    assert (f.a, f.b) == core.window_range(0, s.get("window"), 240)
    assert "tick 0" in w.time_status.text()


def test_play_every_window_with_loop_and_marks(opened, qtbot):
    w, s = opened, opened.session
    s.set("speed", "window")
    s.set_tick(100)
    s.set_mark_in()
    s.set_tick(140)
    s.set_mark_out()
    assert "range 100–140" in w.stream_panel.marks_label.text()
    s.set_tick(100)
    seen: set[int] = set()
    w.controller.frames_ready.connect(lambda f: seen.add(f.tick))
    w.act_play.trigger()  # Space
    assert s.playing
    qtbot.waitUntil(lambda: {100, 110, 120, 130, 140} <= seen, timeout=WAIT_MS)
    assert seen <= {100, 110, 120, 130, 140}  # every window, looping inside the marks
    qtbot.waitUntil(lambda: w.controller.display_fps() > 0, timeout=WAIT_MS)
    w.act_play.trigger()
    assert not s.playing
    qtbot.waitUntil(lambda: "paused" in w.fps_status.text(), timeout=WAIT_MS)


def test_roi_restricts_the_rates(opened, qtbot):
    w, s = opened, opened.session
    qtbot.mouseClick(w.stream_panel.roi_btn, QtCore.Qt.MouseButton.LeftButton)
    assert s.roi == (16, 16, 32, 32) and w.stream_panel.roi_item is not None
    w.stream_panel.roi_item.setPos((8, 8))  # drag: the model follows the handle
    assert s.roi == (8, 8, 32, 32)
    qtbot.waitUntil(lambda: "ROI" in w.rates_panel.summary.text(), timeout=WAIT_MS)
    qtbot.waitUntil(lambda: w.degradation_panel.last.shape == (32, 32), timeout=WAIT_MS)


# ------------------------------------------------------------------------------------ sliders
def test_every_slider_changes_its_parameter_and_undoes(opened, qtbot):
    w, s = opened, opened.session
    sliders = w.findChildren(ParamSlider)
    names = {sl.name for sl in sliders}
    assert {"k", "eta", "levels", "s", "t_start", "black", "white"} <= names
    for sl in sliders:
        spec = SPECS[sl.name]
        before = s.get(sl.name)
        target = spec.minimum if before != spec.minimum else spec.maximum
        if sl.name == "white":
            target = sl._from_pos(sl._to_pos(0.8))  # above black, on the slider's grid
        sl.slider.setSliderDown(True)  # a drag: press, move through values, release
        for frac in (0.3, 0.6, 1.0):
            sl.slider.setValue(round(sl._to_pos(before) + frac * (sl._to_pos(target) - sl._to_pos(before))))
        sl.slider.setSliderDown(False)
        assert s.get(sl.name) == pytest.approx(target), sl.name
        assert sl.spin.value() == pytest.approx(target)
        s.undo()  # the whole drag is one step
        assert s.get(sl.name) == pytest.approx(before), sl.name
        assert sl.slider.value() == sl._to_pos(before)
    assert w.controller.errors == []


def test_k_and_window_update_the_degradation_preview(opened, qtbot):
    w, s = opened, opened.session
    panel = w.degradation_panel
    n = panel.updates
    s.set("k", 5.0)
    qtbot.waitUntil(lambda: panel.updates > n and "k = 5" in panel.info.text(), timeout=WAIT_MS)
    before = panel.panes["qcmx"].image().copy()
    s.set("window", 20)
    qtbot.waitUntil(lambda: "Δτ = 20" in panel.info.text(), timeout=WAIT_MS)
    assert not np.array_equal(before, panel.panes["qcmx"].image())
    s.set("levels", 2)
    s.set("show_pyramid", True)
    qtbot.waitUntil(lambda: panel.band_box.isVisible() and panel.bands[2].image() is not None, timeout=WAIT_MS)
    assert [panel.bands[i].image().shape for i in range(3)] == [(64, 64), (32, 32), (16, 16)]  # L = 2 + residual
    assert not panel.bands[3].isVisible()


# ------------------------------------------------------------------------------------ guided
def test_guided_run_to_the_end_plots_quality(opened, qtbot):
    w, s = opened, opened.session
    s.set("steps", 3)
    w.findChild(QtGui.QAction, "act_run").trigger()
    qtbot.waitUntil(lambda: w.controller.guided_result is not None, timeout=WAIT_MS * 3)
    g = w.guided_panel
    r = w.controller.guided_result
    assert r.image.shape == (64, 64, 3) and np.isfinite(r.image).all()
    assert "mosaic" in g.plan.toPlainText() and "levels" in g.plan.toPlainText()
    assert g.progress.value() == g.progress.maximum() == 3
    _pc, _sc, ts, ps, ss = g.curves[r.run]
    assert len(ts) == 3 and ts == sorted(ts) and all(np.isfinite(ps)) and 0 < ss[-1] <= 1
    assert "finished" in g.status.text()
    # the degradation preview now starts from the guided result
    qtbot.waitUntil(lambda: "guided run" in w.degradation_panel.panes["x"].title.text(), timeout=WAIT_MS)
    # the Export panel says that its classical method does not write the guided result shown, until Guided is chosen
    count = w.export_panel.count
    s.set("export_method", "tfp")
    assert "TFP, not the guided result: Method Guided exports it" in count.text(), count.text()
    s.set("export_method", "guided")
    assert "not the guided result" not in count.text(), count.text()
    s.set("export_method", "tfp")
    # a second run keeps the first run's curve
    w.controller.run_guided()
    qtbot.waitUntil(lambda: w.controller.guided_result.run == r.run + 1, timeout=WAIT_MS * 3)
    assert set(g.curves) == {r.run, r.run + 1}


def test_cancel_a_guided_run_midway(opened, qtbot):
    w, s = opened, opened.session
    s.set("steps", 400)
    qtbot.mouseClick(w.guided_panel.run_btn, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.guided_panel.progress.value() >= 1, timeout=WAIT_MS * 3)
    assert w.guided_panel.cancel_btn.isEnabled()
    qtbot.mouseClick(w.guided_panel.cancel_btn, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not w.controller.guided.is_active(), timeout=WAIT_MS)
    assert w.controller.guided_result is None
    assert "cancelled" in w.guided_panel.status.text() and not w.guided_panel.cancel_btn.isEnabled()
    assert w.guided_panel.progress.value() < 400
    assert w.controller.errors == []


def test_slider_change_restarts_a_running_job_and_drops_stale_results(opened, qtbot):
    w, s = opened, opened.session
    s.set("steps", 400)
    first = w.controller.run_guided()
    qtbot.waitUntil(lambda: w.guided_panel.progress.value() >= 1, timeout=WAIT_MS * 3)
    w.guided_panel.s.set_value(0.5)  # debounced restart
    qtbot.waitUntil(lambda: w.controller.guided_run == first + 1, timeout=WAIT_MS)
    runs: list[int] = []
    w.controller.guided_update.connect(lambda u: runs.append(u.run))
    qtbot.waitUntil(lambda: len(runs) >= 2, timeout=WAIT_MS * 3)
    assert set(runs) == {first + 1}  # nothing from the cancelled run reaches the view
    w.controller.cancel_guided()
    qtbot.waitUntil(lambda: not w.controller.guided.is_active(), timeout=WAIT_MS)


def _largest_tick_gap(qtbot, during, until, timeout_ms: int) -> tuple[float, int]:
    """Largest gap (s) between ticks of a 10 ms QTimer while ``during()`` starts work and ``until()`` is false."""
    stamps: list[float] = []
    timer = QtCore.QTimer()
    timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    timer.setInterval(10)
    timer.timeout.connect(lambda: stamps.append(time.perf_counter()))
    timer.start()
    during()
    qtbot.waitUntil(until, timeout=timeout_ms)
    # one more tick: the interval that spans the end of the work is measured too (without it a freeze
    # that ends the work could be missed when the loop checks ``until`` before the overdue tick)
    n = len(stamps)
    qtbot.waitUntil(lambda: len(stamps) > n, timeout=timeout_ms)
    timer.stop()
    gaps = np.diff(stamps)
    return (float(gaps.max()) if len(gaps) else float("inf")), len(gaps)


def _span(qtbot, during, until, timeout_ms: int) -> tuple[float, int, float]:
    """:func:`_largest_tick_gap` and the seconds the work took (first to last tick)."""
    t0 = time.perf_counter()
    gap, n = _largest_tick_gap(qtbot, during, until, timeout_ms)
    return gap, n, time.perf_counter() - t0


#: the largest gap the stall test accepts outright. The target is 50 ms, measured by benchmarks
#: (``benchmarks/bench_ui_stalls.py`` at 1000×1000, ``bench_gui.py --stall``; BENCHMARKS.md), not here: this test runs
#: on shared 2-core machines beside another test process (``-n 2``), where the operating system or a garbage
#: collection alone holds the GUI thread off for 100-160 ms now and then (CI measured 162 ms once). So a gap passes
#: below this bound **or** below a quarter of the measured run; a real freeze (the sampler on the GUI thread) stalls
#: for the whole blocked work, which fails both (the control below blocks for at least 200 ms).
STALL_LIMIT_S = 0.100


def test_window_keeps_ticking_while_a_guided_run_works(opened, qtbot):
    """The UI-stall test: the largest gap between ticks of a 10 ms QTimer while the sampler runs (see STALL_LIMIT_S).

    Measured once, over a whole 100-step run at 64×64 (at least 20 timer intervals however fast the
    machine), after a warm-up run (torch and the prior load once per session).
    """
    w, s = opened, opened.session
    s.set("steps", 2)
    w.controller.run_guided()
    qtbot.waitUntil(lambda: w.controller.guided_result is not None, timeout=WAIT_MS * 3)
    s.set("steps", 100)
    state: dict[str, int] = {}

    def start() -> None:
        state["run"] = w.controller.run_guided()

    def done() -> bool:
        r = w.controller.guided_result
        return r is not None and r.run == state["run"]

    gap, n, span = _span(qtbot, start, done, WAIT_MS * 3)
    w.controller.cancel_guided()
    qtbot.waitUntil(lambda: not w.controller.guided.is_active(), timeout=WAIT_MS)
    assert n > 20  # the loop ticked all along
    assert gap < max(STALL_LIMIT_S, span / 4), f"largest gap {1000 * gap:.0f} ms of a {1000 * span:.0f} ms run"


def test_the_stall_measurement_sees_a_freeze(opened, qtbot):
    """Control for the test above: a sampler run on the GUI thread stalls the timer for all its length."""
    from spikeview.session import jobs

    w, s = opened, opened.session
    s.set("steps", 120)  # ~0.5 s on the test capture: well beyond 2 × the stall limit on a fast machine too
    req = jobs.GuidedRequest(s.source, s.tick, dict(s.params), w.controller.alpha, None, recipe=s.recipe())

    class Ctx:
        def __init__(self) -> None:
            self.cancelled = __import__("threading").Event()
            self.state: dict = {}

        def report(self, payload) -> None:
            pass

        def check(self) -> None:
            pass

    flag: dict[str, float] = {}

    def block() -> None:
        t0 = time.perf_counter()
        jobs.guided_job(req, Ctx())  # wrongly on the GUI thread
        flag["blocked"] = time.perf_counter() - t0

    gap, _n = _largest_tick_gap(qtbot, lambda: QtCore.QTimer.singleShot(30, block), lambda: "blocked" in flag, WAIT_MS)
    assert flag["blocked"] > 2 * STALL_LIMIT_S  # 120 prior calls: a freeze well beyond the allowed gap
    assert gap >= flag["blocked"] - 0.002  # … and the measurement sees all of it: more than a quarter of any run


# ------------------------------------------------------------------------------------ export
def test_export_the_current_frame_and_open_it_from_the_notification(opened, qtbot, tmp_path):
    w, s = opened, opened.session
    s.set("export_format", "png")
    out = tmp_path / "frame.png"
    w.export_panel.path.setText(str(out))
    w.findChild(QtGui.QAction, "act_export").trigger()  # Ctrl+E
    qtbot.waitUntil(lambda: w.notice.kind == "success", timeout=WAIT_MS)
    assert out.exists()
    from spikeview.export import read_export_metadata

    rec = read_export_metadata(out)
    assert rec["centre_tick"] == s.tick and rec["method"] == "tfp" and rec["params"]["classical"]["window"] == 10
    class Catcher(QtCore.QObject):
        def __init__(self) -> None:
            super().__init__()
            self.urls: list[str] = []

        @QtCore.Slot(QtCore.QUrl)
        def open(self, url: QtCore.QUrl) -> None:
            self.urls.append(url.toLocalFile())

    catcher = Catcher()
    QtGui.QDesktopServices.setUrlHandler("file", catcher, "open")
    try:
        buttons = [b for b in w.notice.findChildren(QtWidgets.QPushButton) if b.text() == "Open"]
        qtbot.waitUntil(buttons[0].isVisible, timeout=WAIT_MS)
        assert w.notice.geometry().width() > 600  # laid out across its bar
        qtbot.mouseClick(buttons[0], QtCore.Qt.MouseButton.LeftButton)
    finally:
        QtGui.QDesktopServices.unsetUrlHandler("file")
    assert catcher.urls == [str(out)]


def test_export_the_marked_range_as_mp4_shows_slow_motion(opened, qtbot, tmp_path):
    w, s = opened, opened.session
    s.set_tick(20)
    s.set_mark_in()
    s.set_tick(79)
    s.set_mark_out()
    s.set("export_range", "marked")
    s.set("export_format", "mp4")
    s.set("export_fps", 25.0)
    assert "80× slow motion" in w.export_panel.slowmo.text()  # 20 kHz / (10 ticks · 25 fps)
    assert "6 frame(s)" in w.export_panel.count.text()
    out = tmp_path / "clip.mp4"
    w.export_panel.path.setText(str(out))
    w.export_panel.export_btn.click()
    qtbot.waitUntil(lambda: w.notice.kind == "success", timeout=WAIT_MS)
    assert out.exists() and w.export_panel.progress.value() == 6


def test_cancel_an_export_and_a_failed_export(opened, qtbot, tmp_path):
    w, s = opened, opened.session
    s.set("export_range", "marked")
    s.set("export_method", "guided")
    s.set("steps", 400)
    s.set("export_format", "png")
    out = tmp_path / "g_%04d.png"
    w.export_panel.path.setText(str(out))
    w.export_panel.export_btn.click()
    assert w.export_panel.cancel_btn.isEnabled()
    qtbot.wait(200)
    w.export_panel.cancel_btn.click()
    qtbot.waitUntil(lambda: "cancelled" in w.export_panel.status.text(), timeout=WAIT_MS * 3)
    assert w.export_panel.export_btn.isEnabled()
    s.set("export_method", "tfp")
    w.export_panel.path.setText(str(tmp_path / "missing" / "f_%04d.png"))
    w.export_panel.export_btn.click()
    qtbot.waitUntil(lambda: w.notice.kind == "error", timeout=WAIT_MS)
    assert "Export not started" in w.notice.text() and "missing does not exist" in w.notice.text()  # before any work


# ------------------------------------------------------------------------------------ comfort
def test_presets_save_and_load_and_a_bad_one_keeps_parameters(opened, tmp_path):
    w, s = opened, opened.session
    s.set("k", 77.0)
    assert w.save_preset(tmp_path / "p.toml")
    s.set("k", 12.0)
    assert w.load_preset(tmp_path / "p.toml") and s.get("k") == 77.0
    (tmp_path / "bad.toml").write_text("[guided]\nk = -3\n")
    assert not w.load_preset(tmp_path / "bad.toml")
    assert s.get("k") == 77.0 and "bad.toml" in w.notice.text()


def test_preferences_and_layout_survive_a_restart_but_no_result_setting_does(qtbot, settings):
    """Issue 27: every recipe parameter (what a result depends on) and the export range start at the CLI's
    defaults in a new launch (the next launch's Ctrl+E once started a 200-frame guided export of an unmarked
    capture); the user's preferences (playback, layout) stay."""
    configure_pyqtgraph()
    a = MainWindow(settings=settings)
    qtbot.addWidget(a)
    a.show()
    a.session.set("k", 33.0)
    a.session.set("eta", 3.0)
    a.session.set("export_range", "marked")
    a.session.set("speed", "realtime")
    a.docks["rates"].hide()
    a.close()
    b = MainWindow(settings=settings)
    qtbot.addWidget(b)
    b.show()
    assert b.session.get("speed") == "realtime" and not b.docks["rates"].isVisible()
    assert b.session.get("k") == 20.0 and b.session.get("eta") == 2.0 and b.session.get("export_range") == "frame"
    assert b.guided_panel.k.spin.value() == 20.0
    b.close()


def test_undo_shortcut_and_help(opened, qtbot):
    w, s = opened, opened.session
    s.set("eta", 3.0)
    assert w.act_undo.isEnabled() and "Colour range" in w.act_undo.text()
    w.act_undo.trigger()
    assert s.get("eta") == 2.0
    dlg = w.show_help()
    qtbot.waitUntil(dlg.isVisible)
    table = dlg.findChild(QtWidgets.QTableWidget, "shortcuts_table")
    keys = {table.item(i, 0).text() for i in range(table.rowCount())}
    assert {"Space", "Ctrl+O", "Ctrl+E", "F1", "Home / End"} <= keys
    params = dlg.findChild(QtWidgets.QTableWidget, "parameters_help")  # every knob: control, flag, one sentence
    rows = {params.item(i, 1).text(): params.item(i, 2).text() for i in range(params.rowCount())}
    assert "ticks" in rows["--window"] and "Q is on" in rows["--k"] and "full scale" in rows["--t-start"]
    dlg.close()


def test_stream_settings_reinterpret_the_cfa(opened, qtbot):
    w, s = opened, opened.session
    dlg = w.stream_settings()
    right = dlg.preview.image().astype(float)
    assert "probably wrong" not in dlg.hint.text()
    dlg.cfa.setCurrentIndex(dlg.cfa.findData("GRBG"))  # one column off: greens read as red/blue
    dlg.update_preview()
    assert "probably wrong" in dlg.hint.text()
    assert np.abs(dlg.preview.image().astype(float) - right).mean() > 10
    dlg.accept()
    assert s.source.cfa == "GRBG" and s.tick == 120
    qtbot.waitUntil(lambda: "probably wrong" in w.rates_panel.hint.text(), timeout=WAIT_MS)


# ------------------------------------------------------------------------------------ meta
def test_a_qt_warning_fails_a_test(tmp_path):
    """The strictness above is real: a test that makes Qt warn fails under these markers."""
    test = tmp_path / "test_warns.py"
    test.write_text(
        "import pytest\nfrom PySide6 import QtCore\n"
        "pytestmark = [pytest.mark.qt_log_level_fail('WARNING')]\n"
        "def test_warns(qtbot):\n    QtCore.qWarning('boom')\n"
    )
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test)], check=False,
                         capture_output=True, text=True, timeout=300, cwd=tmp_path,
                         env={**__import__("os").environ, "QT_QPA_PLATFORM": "offscreen"})
    assert out.returncode == 1, out.stdout[-2000:]
    assert "boom" in out.stdout


def test_export_name_follows_the_format_and_range(opened, tmp_path):
    w, s = opened, opened.session
    w.export_panel.path.setText(str(tmp_path / "mine.png"))
    w.export_panel.path.textEdited.emit("mine.png")  # typed by the user: no more automatic names
    s.set("export_format", "mp4")
    assert w.export_panel.path.text() == str(tmp_path / "mine.mp4")
    s.set("export_range", "marked")
    s.set("export_format", "exr")
    assert w.export_panel.path.text() == str(tmp_path / "mine_%04d.exr")


def test_a_missing_model_is_a_message_with_the_fix(opened, qtbot, tmp_path):
    w, s = opened, opened.session
    s.set("prior", "sd")  # the latent prior needs DPS: the message says so
    w.controller.run_guided()
    qtbot.waitUntil(lambda: w.notice.kind == "error", timeout=WAIT_MS)
    assert 'set guidance = "dps"' in w.notice.text()
    w.notice.dismiss()
    s.set("guidance", "dps")
    s.set("model_path", str(tmp_path / "no-such-weights"))
    w.controller.run_guided()
    qtbot.waitUntil(lambda: "failed" in w.guided_panel.status.styleSheet() or w.notice.kind == "error", timeout=WAIT_MS)
    assert w.notice.kind == "error" and "no-such-weights" in w.notice.text()
    assert s.get("k") == SPECS["k"].default and w.isVisible()  # nothing lost, nothing crashed


def test_the_spikeview_command_opens_the_window_on_the_demo(qtbot, monkeypatch, tmp_path):
    """``spikeview`` with no argument: the CLI's ``app`` command → run_app(None) → the demo capture."""
    from spikeview.cli.main import main

    # (QSettings are isolated per test by tests/conftest.py)
    monkeypatch.setattr(core, "demo_stream", lambda size, n_ticks: demo_stream())  # the tiny capture, not 256×256
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)
    app = QtWidgets.QApplication.instance()
    seen: dict[str, object] = {}

    def poll() -> None:
        wins = [x for x in app.topLevelWidgets() if isinstance(x, MainWindow) and x.isVisible()]
        if wins and wins[0].controller.last_frames is not None:
            seen["label"] = wins[0].session.stream.label
            seen["live"] = hasattr(wins[0], "live_panel")
            app.quit()
        else:
            QtCore.QTimer.singleShot(50, poll)

    QtCore.QTimer.singleShot(50, poll)
    before = {id(x) for x in app.topLevelWidgets() if isinstance(x, MainWindow)}
    assert main([]) == 0
    assert seen == {"label": "test capture", "live": True}
    # Nothing of the app is left to disturb what runs next in this process: closing its window posted a
    # Quit event after exec() returned; delivered later, it made every event loop return at once (-1), so
    # the next window froze (issue 10, item 10: three live tests timed out after this one).
    app.processEvents()
    assert not [x for x in app.topLevelWidgets() if isinstance(x, MainWindow) and id(x) not in before]  # deleted
    loop = QtCore.QEventLoop()
    QtCore.QTimer.singleShot(20, lambda: loop.exit(7))
    assert loop.exec() == 7


# ------------------------------------------------------------------------------------ screen size
#: a 1366×768 laptop screen less a title bar and a desktop panel (what a window can get)
SMALL_SCREEN = (1366, 768 - 80)


def in_sight(window, w) -> bool:
    """``w`` is shown, inside the window and, in a scrolling panel, inside the part of it on screen (no scrolling needed)."""
    from PySide6 import QtWidgets

    if not w.isVisible():
        return False
    box = QtCore.QRect(w.mapTo(window, QtCore.QPoint(0, 0)), w.size())
    if not window.rect().contains(box):
        return False
    area = w.parentWidget()
    while area is not None and not isinstance(area, QtWidgets.QScrollArea):
        area = area.parentWidget()
    return area is None or area.viewport().rect().contains(QtCore.QRect(w.mapTo(area.viewport(), QtCore.QPoint(0, 0)), w.size()))


def test_the_window_fits_a_1366x768_screen(window, qtbot):
    """The start-up layout at 1366×688: minimum width ≤ 1280 px; every panel is in sight or one tab away; the
    controls a user needs (transport, display, ROI, Run, Export, the degradation's Fit, the status bar, the notice)
    are in sight without scrolling, each panel's when its tab is in front."""
    from spikeview.gui.live_panel import install_live
    from spikeview.live.mockusb import MockBackend

    install_live(window, backend=MockBackend())
    window.show_error("A long notice to show that the notification strip does not widen the window. " * 4)
    hint = window.minimumSizeHint()
    assert hint.width() <= 1280 and hint.height() <= SMALL_SCREEN[1], hint
    window.resize(1366, 768)  # the whole screen (a maximised window without decorations)
    qtbot.waitUntil(lambda: (window.width(), window.height()) == (1366, 768), timeout=WAIT_MS)
    window.resize(*SMALL_SCREEN)
    qtbot.waitUntil(lambda: (window.width(), window.height()) == SMALL_SCREEN, timeout=WAIT_MS)
    window.default_layout()
    qtbot.wait(50)  # the dock layout settles
    for key, dock in window.docks.items():
        assert dock.isVisible() or window.tabifiedDockWidgets(dock), key
    for w in (window.statusBar(), window.notice, window.canvas, window.stream_panel.cast, window.stream_panel.roi_btn,
              window.stream_panel.scrub, window.stream_panel.white):
        assert in_sight(window, w), w.objectName() or type(w).__name__
    for key, w in (("guided", window.guided_panel.run_btn), ("export", window.export_panel.export_btn),
                   ("degradation", window.degradation_panel.fit_btn), ("rates", window.rates_panel),
                   ("compare", window.compare_panel.load_btn)):
        window.docks[key].raise_()
        qtbot.waitUntil(lambda w=w: in_sight(window, w), timeout=WAIT_MS)
    assert (window.width(), window.height()) == SMALL_SCREEN


# ------------------------------------------------------------------------------------ degradation view
def _deg_panes(w):
    d = w.degradation_panel
    return [p for p in list(d.panes.values()) + d.bands if p.isVisible() and p.image() is not None]


def test_degradation_panes_keep_their_fit_and_zoom_resets(opened, qtbot):
    """Issue 10, item 7: panes shrank to specks after "per level", Edit ▸ Reset parameters or a notice."""
    w, s = opened, opened.session
    d = w.degradation_panel

    def recomputed(action) -> None:
        n = d.updates
        action()
        qtbot.waitUntil(lambda: d.updates > n, timeout=WAIT_MS)

    def after(action) -> None:
        recomputed(action)
        qtbot.waitUntil(lambda: all(p.covers_image() for p in _deg_panes(w)), timeout=WAIT_MS)

    assert len(_deg_panes(w)) == 6 and all(p.covers_image() for p in _deg_panes(w))
    after(lambda: s.set("show_pyramid", True))
    after(lambda: s.set("k", 3.0))
    after(w.reset_params)
    w.show_error("A notice that takes room at the bottom of the window. " * 3)
    qtbot.waitUntil(lambda: all(p.covers_image() for p in _deg_panes(w)), timeout=WAIT_MS)
    # the user zooms in: the fit ends (and stays ended through a recomputation) until Fit resets it
    x = d.panes["x"]
    x.vb.scaleBy((0.25, 0.25))
    x.vb.sigRangeChangedManually.emit(x.vb.state["mouseEnabled"])
    assert not x.fit and not x.covers_image() and not d.panes["y"].covers_image()  # linked: all zoomed together
    recomputed(lambda: s.set("k", 4.0))
    qtbot.wait(50)
    assert not x.covers_image()
    w.findChild(QtGui.QAction, "act_fit").trigger()  # View ▸ Fit images (Ctrl+0)
    qtbot.waitUntil(lambda: all(p.covers_image() for p in _deg_panes(w)), timeout=WAIT_MS)
    assert x.fit
    # two large panes side by side
    d.layout_combo.setCurrentIndex(d.layout_combo.findData("compare"))
    assert [k for k, p in d.panes.items() if p.isVisible()] == ["qcmx", "y"]
    qtbot.waitUntil(lambda: all(p.covers_image() for p in _deg_panes(w)), timeout=WAIT_MS)
    assert d.panes["y"].view.width() > 1.4 * d.panes["x"].view.minimumWidth()


# ------------------------------------------------------------------------------------ stale state
def test_idle_progress_bars_read_the_settings(opened, qtbot):
    """Issue 10, item 8: idle bars read "0 / 100 steps" with 6 steps set."""
    w, s = opened, opened.session
    s.set("steps", 6)
    assert w.guided_panel.progress.text() == "0 / 6 steps"
    s.set("export_format", "png")
    s.set("export_range", "frame")
    assert w.export_panel.progress.text() == "0 / 1 frames"
    s.set("export_format", "mp4")
    s.set_tick(100)
    s.set_mark_in()
    s.set_tick(140)
    s.set_mark_out()
    s.set("export_range", "marked")
    n = len(w.export_panel.ticks())
    assert n > 1 and w.export_panel.progress.text() == f"0 / {n} frames"


def test_opening_another_capture_clears_the_previous_run_and_errors(opened, qtbot, tmp_path):
    """Issue 10, item 8: the guided panel kept the previous file's run and PSNR, the old export error stayed."""
    w, s = opened, opened.session
    g = w.guided_panel
    s.set("steps", 2)
    w.controller.run_guided()
    qtbot.waitUntil(lambda: w.controller.guided_result is not None, timeout=WAIT_MS * 3)
    assert g.curves and "finished" in g.status.text() and g.preview.image() is not None
    s.set("export_format", "png")
    s.set("export_range", "frame")
    w.export_to(str(tmp_path / "missing" / "frame.png"))
    qtbot.waitUntil(lambda: w.notice.kind == "error", timeout=WAIT_MS)
    qtbot.waitUntil(lambda: "missing" in w.export_panel.status.text(), timeout=WAIT_MS)

    other = core.memory_stream(_demo(), "another capture", _demo().gt_at)
    w.set_stream(other)
    qtbot.waitUntil(lambda: frames_at(w, s.tick), timeout=WAIT_MS)
    assert w.session.stream is other and w.windowTitle() == "another capture — spikeview"
    assert g.curves == {} and g.preview.image() is None and g.plan.toPlainText() == ""
    assert s.get("steps") == 6  # the previous capture's knobs do not carry over (issue 27)
    assert g.status.text() == "Idle." and g.progress.text() == "0 / 6 steps"
    assert w.controller.guided_result is None
    assert w.export_panel.status.text() == "" and w.notice.text() == ""


def test_panes_agree_on_the_tick_when_playback_pauses(opened, qtbot):
    """Issue 10, item 8: after playback, stream, TFI, rates and degradation showed 700, 490, 420 and 100."""
    w, s = opened, opened.session
    c = w.controller
    s.set("speed", "window")
    s.set_tick(20)
    w.act_play.trigger()
    qtbot.waitUntil(lambda: c.last_frames is not None and c.last_frames.tick >= 80, timeout=WAIT_MS)
    # while playing, a pane that trails says which tick it shows
    assert "follows the stream when playback pauses" in w.degradation_panel.info.text()
    assert f"tick {w.degradation_panel.last.tick}" in w.degradation_panel.info.text()
    w.act_play.trigger()
    assert not s.playing

    def agreed() -> bool:
        busy = c.preview.is_active() or c.tfi.is_active()
        ticks = (c.last_frames.tick, w.stream_panel.tfi_tick, w.rates_panel.last.tick, w.degradation_panel.last.tick)
        return not busy and set(ticks) == {s.tick}

    qtbot.waitUntil(agreed, timeout=WAIT_MS)
    assert f"tick {s.tick}" in w.stream_panel.tfi.title.text() and "while playing" not in w.stream_panel.tfi.title.text()
    assert f"tick {s.tick}" in w.rates_panel.summary.text()
    assert f"tick {s.tick}" in w.degradation_panel.info.text()


# ------------------------------------------------------------------------------------ the app's words
def test_messages_name_menus_that_exist(window):
    """Issue 10, item 9: hints pointed to a "Stream ▸ Settings…" menu that does not exist."""
    import re

    from spikeview.gui.live_panel import install_live
    from spikeview.live.mockusb import MockBackend

    install_live(window, backend=MockBackend())
    menus = {a.text().replace("&", ""): [x.text().replace("&", "") for x in a.menu().actions()]
             for a in window.menuBar().actions() if a.menu() is not None}
    import spikeview.gui

    roots = (Path(spikeview.gui.__file__).parent, Path(core.__file__).parent)  # the app's views and its session
    found = 0
    for path in (p for root in roots for p in root.rglob("*.py")):
        for menu, rest in re.findall(r"(\w+) ▸ ([^\n]+)", path.read_text("utf-8")):
            found += 1
            assert menu in menus, f"{path.name}: no menu {menu!r} (for {rest!r})"
            assert any(rest.startswith(x.rstrip("…")) for x in menus[menu]), \
                f"{path.name}: {menu} ▸ {rest!r} names no item of the {menu} menu ({menus[menu]})"
    assert found >= 5


def test_a_file_notice_names_the_file_once_in_the_apps_words(window, qtbot, tmp_path):
    from spikeview.io import write_plain

    path = write_plain(tmp_path / "cut.dat", _demo().read(0, 20), cfa="RGGB")
    with open(path, "ab") as f:
        f.write(bytes(100))  # a partial last frame
    window.open_path(path)
    qtbot.waitUntil(lambda: window.notice.kind == "warning", timeout=WAIT_MS)
    text = window.notice.text()
    assert text.count("cut.dat") == 1 and "--" not in text and "width and height" in text


def test_export_asks_before_replacing_a_file(opened, qtbot, tmp_path):
    w, s = opened, opened.session
    s.set("export_format", "png")
    s.set("export_range", "frame")
    out = tmp_path / "frame.png"
    out.write_bytes(b"mine")
    asked: list[list[Path]] = []
    answers = [False, True]
    w.ask_overwrite = lambda path, existing: (asked.append(existing), answers.pop(0))[1]
    w.export_to(str(out))
    assert asked == [[out]] and out.read_bytes() == b"mine" and not w.controller.exporter.is_active()
    w.export_to(str(out))
    qtbot.waitUntil(lambda: w.notice.kind == "success", timeout=WAIT_MS)
    assert len(asked) == 2 and out.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_the_display_curve_auto_follows_the_capture_as_an_export_does(window, qtbot, tmp_path, cfa):
    """Issue 26: a capture without a sidecar (the ecosystem's) is shown linearly, spikeview's own captures with the
    sRGB curve; the view's curve is the one an export of the same capture writes (pipeline.recipe_for_state)."""
    from spikeview.io import open_source
    from spikeview.pipeline import SequenceState, recipe_for_state
    from spikeview.recipe import Recipe

    assert window.session.params["transfer"] == "auto"
    window.set_stream(demo_stream())  # in memory, simulated: linear light
    assert window.controller.display_params()["transfer"] == "srgb"
    path = tmp_path / "eco.npy"
    np.save(path, _demo().read(0, 120))
    src = open_source(str(path), cfa=cfa)
    window.set_stream(core.OpenedStream(src, "eco.npy", path))
    assert window.controller.display_params()["transfer"] == "linear"
    exported = recipe_for_state(Recipe(), SequenceState(), src).export.transfer
    assert exported == window.controller.display_params()["transfer"]
    window.session.set("transfer", "srgb")
    assert window.controller.display_params()["transfer"] == "srgb"  # the user's choice wins


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_an_export_after_knob_changes_a_restart_a_file_switch_and_reset_equals_the_cli(qtbot, settings, tmp_path, cfa):
    """Issue 27, "state that never lies": η changed in the demo, the app quit, a capture opened, η changed again,
    Edit ▸ Reset parameters, the current frame exported as PNG: the same bytes' pixels as `spikeview reconstruct
    --at T --out x.png` (the reset white point is the CLI's for the default η, not the old η's)."""
    import OpenImageIO as oiio

    from spikeview.cli.main import main

    cap = tmp_path / "cap.dat"
    assert main(["simulate", "--demo", "--size", "48", "--ticks", "120", "--cfa", cfa, "--out", str(cap)]) == 0
    configure_pyqtgraph()
    a = MainWindow(settings=settings)
    qtbot.addWidget(a)
    a.show()
    a.set_stream(demo_stream())
    a.session.set("eta", 3.0)
    a.session.set("white", 0.15)
    a.close()
    b = MainWindow(settings=settings)
    qtbot.addWidget(b)
    b.show()
    b.open_path(cap)
    qtbot.waitUntil(lambda: b.session.stream is not None and b.session.stream.path == cap, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: b.controller.capture_white is not None, timeout=WAIT_MS)
    first_white = b.controller.capture_white
    assert b.session.get("eta") == 2.0 and b.session.get("white") == first_white  # nothing carried over
    b.session.set("eta", 3.5)
    if cfa != "none":  # Y·α/η: re-estimated for η 3.5 (a monochrome capture's white point is its plain rate)
        qtbot.waitUntil(lambda: b.controller.capture_white != first_white, timeout=WAIT_MS)
    b.reset_params()
    qtbot.waitUntil(lambda: b.controller.capture_white == first_white and b.session.get("white") == first_white,
                    timeout=WAIT_MS)
    tick = b.session.tick
    b.session.set("export_format", "png")
    b.session.set("export_range", "frame")
    app_out = tmp_path / "app.png"
    b.export_to(str(app_out))
    qtbot.waitUntil(lambda: b.notice.kind == "success", timeout=WAIT_MS)
    b.close()
    assert main(["reconstruct", str(cap), "--at", str(tick), "--out", str(tmp_path / "cli.png")]) == 0

    def pixels(p):
        return np.asarray(oiio.ImageBuf(str(p)).get_pixels(oiio.UINT8))

    assert np.array_equal(pixels(app_out), pixels(tmp_path / "cli.png"))


def test_an_export_into_a_missing_folder_is_refused_before_it_starts(opened, tmp_path):
    """Issue 27: the export once started (and ran its reconstruction) before failing at its first write."""
    w, s = opened, opened.session
    s.set("export_format", "png")
    s.set("export_range", "frame")
    assert w.controller.start_export(str(tmp_path / "missing" / "frame.png")) is False
    assert not w.controller.exporter.is_active() and w.notice.kind == "error"
    assert "missing does not exist" in w.export_panel.status.text() and not (tmp_path / "missing").exists()


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_a_dark_captures_tfi_pane_searches_as_far_as_the_cli(window, qtbot, tmp_path, cfa):
    """The TFI pane of a dark capture uses the CLI's search (spikeview.pipeline.tfi_half_window) and says it in its
    title; the pane's pixels are TFI at that reach."""
    from spikeview.classical.tfi import tfi
    from spikeview.io.plain import write_plain

    ramp = 0.03 * np.linspace(0.1, 1.0, 32)
    v = np.random.default_rng(3).random((32, 32))
    s = np.zeros((400, 32, 32), np.uint8)
    for t in range(400):
        v += ramp[None, :]
        s[t] = v >= 1
        v -= s[t]
    path = write_plain(tmp_path / "dark.dat", s, cfa=cfa)
    window.set_stream(core.open_file(path))
    qtbot.waitUntil(lambda: window.session.tfi_reach is not None, timeout=WAIT_MS)
    reach = window.session.tfi_reach
    assert 40 <= reach <= 512 and window.session.tfi_search() == reach and window.session.get("tfi_half_window") == 32
    assert window.controller.display_params()["tfi_half_window"] == reach
    window.session.set_tick(200)
    qtbot.waitUntil(lambda: f"TFI at tick 200  (±{reach} ticks, a dark capture's)" in window.stream_panel.tfi.title.text(),
                    timeout=WAIT_MS)
    req = window.controller._request(tick=200, factor=1)  # what the pane's job computes from
    assert req.params["tfi_half_window"] == reach
    # photosites firing at least once in `reach` ticks are never capped at the reach; with ±32 many of them were
    seen = np.s_[:, ramp >= 1.0 / reach]
    assert (tfi(req.source, 200, reach)[seen] == np.float32(1 / (2 * reach))).mean() == 0
    assert (tfi(req.source, 200, 32)[seen] == np.float32(1 / 64)).mean() > 0.2
