"""Ctrl-C in the terminal that started ``spikeview`` closes the app, as it stops every sub-command.

Before: Python's default handler raised KeyboardInterrupt inside whatever Qt slot ran next; the app's
exception hook printed a traceback, showed "Unexpected KeyboardInterrupt … (a bug …)" in the window and
the app went on running.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

import pytest

pytest.importorskip("PySide6")
from PySide6 import QtCore, QtWidgets  # noqa: E402

from spikeview.session import core  # noqa: E402
from spikeview.gui.main_window import MainWindow  # noqa: E402

OFFSCREEN_NOISE = r"This plugin does not support propagateSizeHints"
pytestmark = [pytest.mark.gui, pytest.mark.qt_log_level_fail("WARNING"), pytest.mark.qt_log_ignore(OFFSCREEN_NOISE)]


def _tiny_demo() -> core.OpenedStream:
    from spikeview.sim.demo import demo_capture

    cap = demo_capture(size=32, n_ticks=60, seed=1)
    return core.memory_stream(cap, "test capture", cap.gt_at)


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT cannot be sent to one's own process on Windows")
def test_ctrl_c_closes_the_app_with_one_line(qtbot, monkeypatch, capfd, request):
    from spikeview.cli.main import main

    monkeypatch.setattr(core, "demo_stream", lambda size, n_ticks: _tiny_demo())
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)
    # a terminal's Python: SIGINT raises KeyboardInterrupt. A test run started in the background of a non-interactive
    # shell (`pytest … &`) inherits SIGINT ignored, where the app rightly installs nothing (spikeview.gui.app): the test
    # sets the terminal's handler for itself and puts the inherited one back
    inherited = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    request.addfinalizer(lambda: signal.signal(signal.SIGINT, inherited))
    before = signal.getsignal(signal.SIGINT)
    app = QtWidgets.QApplication.instance()
    seen: dict[str, object] = {}

    def poll() -> None:
        wins = [x for x in app.topLevelWidgets() if isinstance(x, MainWindow) and x.isVisible()]
        if wins and wins[0].controller.last_frames is not None:
            seen["window"] = True
            # the signal arrives from outside while the event loop idles, as a terminal's Ctrl-C does
            threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
        else:
            QtCore.QTimer.singleShot(50, poll)

    def give_up() -> None:  # the app did not react: end the loop so that the test fails instead of hanging
        seen["gave_up"] = True
        app.quit()

    QtCore.QTimer.singleShot(50, poll)
    guard = QtCore.QTimer()
    guard.setSingleShot(True)
    guard.timeout.connect(give_up)
    guard.start(60_000)  # generous: under a parallel run the first frame alone can take seconds
    try:
        status = main([])
    finally:
        guard.stop()
    err = capfd.readouterr().err
    assert seen == {"window": True}, err[-2000:]
    assert status == 130
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert "spikeview: interrupted (Ctrl-C)" in err
    assert signal.getsignal(signal.SIGINT) is before  # the test process's own handler is back
    app.processEvents()
    assert not [x for x in app.topLevelWidgets() if isinstance(x, MainWindow)]  # the window is gone
