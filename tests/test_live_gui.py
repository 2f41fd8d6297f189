"""Live capture in the app (pytest-qt, offscreen): Open camera, live indicator, Record/Stop, closing the app.

Every test fails on a Qt warning, like the other app tests; the offscreen plugin's
"propagateSizeHints" message is the one ignored (it does not exist on a real display).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
from spikeview.gui.live_panel import format_bytes, format_elapsed, indicator_state, install_live  # noqa: E402
from spikeview.io import ArraySource, encode_raw1m, open_source, read_sidecar  # noqa: E402
from spikeview.live import LiveStatus, SimCamera  # noqa: E402
from spikeview.live.mockusb import Fault, MockBackend  # noqa: E402

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]
WAIT_MS = 30_000


@pytest.fixture(scope="module")
def spikes() -> np.ndarray:
    rng = np.random.default_rng(42)
    return rng.integers(0, 2, (50, 32, 32), dtype=np.uint8)


def test_install_adds_the_menu_action_and_the_dock(window):
    panel = install_live(window, backend=MockBackend())
    assert window.live_panel is panel
    file_menu = next(a.menu() for a in window.menuBar().actions() if a.text() == "&File")
    assert "act_open_camera" in [a.objectName() for a in file_menu.actions()]
    assert panel.dock.objectName() == "dock_live"
    assert panel.indicator.text() == "● OFFLINE"
    assert not panel.record_btn.isEnabled()


def test_dialog_lists_usb_devices_and_the_simulated_camera(window, qtbot):
    panel = install_live(window, backend=MockBackend())
    dlg = panel.open_dialog()
    entries = dlg.entries()
    assert any("Simulated camera: demo scene" in e for e in entries)
    assert any("Mock spike camera f055:5b1c" in e for e in entries)
    assert dlg.list.currentItem().text().startswith("USB: ")  # the camera found is preselected
    assert (dlg.vid.text(), dlg.pid.text()) == ("f055", "5b1c")
    dlg.roi.setText("1, 2, 3")
    dlg.accept()  # bad settings: the dialog stays open and says why
    assert dlg.isVisible() and "roi must be [top, left, height, width]" in dlg.error.text()
    dlg.reject()


def test_usb_camera_failure_is_a_status_not_a_crash(window, qtbot):
    panel = install_live(window, backend=MockBackend(open_error="access"))
    dlg = panel.open_dialog()
    assert dlg.select("USB: ")
    dlg.accept()
    qtbot.waitUntil(lambda: panel.source is not None and panel.source.status is LiveStatus.PERMISSION_DENIED,
                    timeout=WAIT_MS)
    qtbot.waitUntil(lambda: "udev" in window.notice.text(), timeout=WAIT_MS)
    panel.refresh_labels()
    assert panel.indicator.text() == "● ERROR"
    assert "/etc/udev/rules.d/" in panel.status.text()
    assert not panel.record_btn.isEnabled()


def test_usb_camera_through_the_dialog_is_shown_live(window, qtbot):
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 2, (4, 1000, 1000), dtype=np.uint8)
    raw = encode_raw1m(frames)
    panel = install_live(window, backend=MockBackend([raw, raw[:1000], Fault("disconnect")]))
    dlg = panel.open_dialog()
    dlg.select("USB: ")
    dlg.accept()
    qtbot.waitUntil(lambda: window.session.source is panel.source, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: panel.source.status is LiveStatus.DISCONNECTED, timeout=WAIT_MS)
    assert window.session.n_frames == 4
    qtbot.waitUntil(lambda: window.controller.last_frames is not None, timeout=WAIT_MS)
    panel.refresh_labels()
    assert "Dropped: device 0" in panel.dropped.text()
    assert "was disconnected" in window.notice.text()


def test_record_stop_and_close_the_app_during_a_second_recording(window, qtbot, tmp_path, spikes):
    panel = install_live(window)
    cam = SimCamera(ArraySource(spikes, cfa="RGGB"), slowdown=20, label="test camera")  # 1 kHz: data keeps coming
    panel.attach(cam)
    qtbot.waitUntil(lambda: window.session.source is cam, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: panel.indicator.text() == "● LIVE", timeout=WAIT_MS)
    assert window.windowTitle().startswith("test camera")

    # Record / Stop with the button (the save dialog is replaced)
    first = tmp_path / "first.dat"
    panel.ask_record_path = lambda: str(first)
    panel.record_btn.click()
    assert cam.recording and panel.record_btn.text() == "■ Stop"
    qtbot.waitUntil(lambda: cam.recorder is not None and cam.recorder.frames_written >= 30, timeout=WAIT_MS)
    panel.refresh_labels()
    assert panel.elapsed.text().startswith("REC ") and "frames" in panel.size.text()
    panel.record_btn.click()
    assert not cam.recording and panel.record_btn.text() == "● Record"
    assert "Recorded" in window.notice.text()
    check_recording(first, spikes)

    # the follow mode keeps the viewer near the newest tick
    qtbot.waitUntil(lambda: window.session.tick >= cam.n_frames - 200, timeout=WAIT_MS)

    # a second recording, interrupted by closing the window
    second = tmp_path / "second.dat"
    assert panel.start_recording(second)
    qtbot.waitUntil(lambda: cam.recorder is not None and cam.recorder.frames_written >= 20, timeout=WAIT_MS)
    window.close()
    assert not cam.running and cam.status is LiveStatus.STOPPED
    n = check_recording(second, spikes)
    assert n == cam.n_frames - read_sidecar(second).tables["recording"]["first_tick"]  # everything acquired


def check_recording(path, spikes) -> int:
    """The file is complete and readable, and holds consecutive ticks of the looped source."""
    table = read_sidecar(path).tables["recording"]
    assert table["state"] == "complete"
    with open_source(path) as src:
        assert src.n_frames == table["frames"] > 0 and src.cfa == "RGGB" and src.info.warnings == []
        ticks = (table["first_tick"] + np.arange(src.n_frames)) % len(spikes)
        np.testing.assert_array_equal(src.read(0, src.n_frames), spikes[ticks])
        return src.n_frames


def test_label_helpers():
    assert format_bytes(999) == "999 B" and format_bytes(1_234_567) == "1.2 MB"
    assert format_elapsed(75.25) == "01:15.2" and format_elapsed(3725) == "1:02:05"
    assert indicator_state(LiveStatus.RUNNING) == ("● LIVE", "live")
    assert indicator_state(LiveStatus.DISCONNECTED) == ("● ERROR", "error")
    assert indicator_state(LiveStatus.STOPPED) == ("● OFFLINE", "off")


def test_replaying_the_open_file_keeps_running_after_the_viewer_switches(window, qtbot, tmp_path, spikes):
    from spikeview.io import write_plain

    path = write_plain(tmp_path / "clip.dat", spikes, cfa="RGGB")
    window.open_path(path)
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.path == path, timeout=WAIT_MS)
    panel = install_live(window, backend=MockBackend())
    dlg = panel.open_dialog()
    assert dlg.select("replay clip.dat")
    dlg.accept()
    cam = panel.source
    qtbot.waitUntil(lambda: window.session.source is cam, timeout=WAIT_MS)  # the viewer closed its copy of the file
    start = cam.n_frames
    qtbot.waitUntil(lambda: cam.n_frames > start + 100, timeout=WAIT_MS)  # and the camera's own copy still plays
    assert cam.status is LiveStatus.RUNNING and cam.cfa == "RGGB"
    a, got = cam.latest_window(10)
    np.testing.assert_array_equal(got, spikes[np.arange(a, a + 10) % len(spikes)])
    panel.close_camera()
    assert cam.status is LiveStatus.STOPPED and panel.indicator.text() == "● OFFLINE"
