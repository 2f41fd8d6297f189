"""Start the desktop app: ``spikeview`` (demo capture) or ``spikeview FILE``."""

from __future__ import annotations

import os
import signal
import sys
import threading
import traceback
from pathlib import Path
from types import TracebackType
from typing import Any


def configure_pyqtgraph() -> None:
    """Global pyqtgraph options the app relies on: row-major images, no antialiasing of images."""
    import pyqtgraph as pg

    pg.setConfigOptions(imageAxisOrder="row-major", antialias=False, background=(24, 24, 24), foreground=(220, 220, 220))


def apply_style(app: Any) -> None:
    """The app's look: Fusion with a dark palette, whose **disabled** group is visibly dimmer (grey text, a
    grey slider fill): a knob the plan switches off must not look like a live one."""
    from PySide6 import QtGui

    app.setStyle("Fusion")
    pal = QtGui.QPalette()
    dark, mid, text = QtGui.QColor(37, 37, 40), QtGui.QColor(53, 53, 58), QtGui.QColor(225, 225, 225)
    role = QtGui.QPalette.ColorRole
    for r, colour in ((role.Window, dark), (role.Base, QtGui.QColor(28, 28, 30)), (role.AlternateBase, mid),
                      (role.Button, mid), (role.Text, text), (role.WindowText, text), (role.ButtonText, text),
                      (role.ToolTipBase, mid), (role.ToolTipText, text), (role.Highlight, QtGui.QColor(255, 150, 30)),
                      (role.HighlightedText, QtGui.QColor(20, 20, 20))):
        pal.setColor(r, colour)
    grey, off = QtGui.QColor(115, 115, 120), QtGui.QPalette.ColorGroup.Disabled
    for r, colour in ((role.Text, grey), (role.WindowText, grey), (role.ButtonText, grey),
                      (role.Highlight, QtGui.QColor(80, 80, 86)), (role.HighlightedText, grey),
                      (role.Button, QtGui.QColor(44, 44, 48)), (role.Base, QtGui.QColor(33, 33, 36))):
        pal.setColor(off, r, colour)
    app.setPalette(pal)


def make_application(argv: list[str] | None = None) -> Any:
    """The QApplication (created once), styled, with pyqtgraph configured."""
    from PySide6 import QtWidgets

    from spikeview.gui.workers import configure_runtime

    app = QtWidgets.QApplication.instance()
    if app is None:
        from PySide6 import QtCore

        QtCore.qInstallMessageHandler(_qt_message)
        app = QtWidgets.QApplication(argv if argv is not None else [sys.argv[0]])
        app.setOrganizationName("spikeview")
        app.setApplicationName("spikeview")
        apply_style(app)
    configure_pyqtgraph()
    configure_runtime()
    return app


#: Qt's messages that say nothing to a user: the off-screen platform (``--screenshot``, headless tests) cannot pass a
#: window's size hints on, and says so twice a window
QT_NOISE = ("does not support propagateSizeHints",)


def _qt_message(mode: Any, context: Any, message: str) -> None:
    """Qt's own messages to the terminal, as Qt prints them, less :data:`QT_NOISE`."""
    if not any(n in message for n in QT_NOISE):
        print(message, file=sys.stderr)


def _excepthook(window: Any) -> Any:
    """Exceptions that reach the event loop become a message; parameters are saved first."""

    def hook(exc_type: type[BaseException], exc: BaseException, tb: TracebackType | None) -> None:
        traceback.print_exception(exc_type, exc, tb, file=sys.stderr)
        try:
            window.save_settings()
            window.show_error(f"Unexpected {exc_type.__name__}: {exc} (a bug; your parameters are saved — please report the "
                              "terminal output).")
        except Exception as e:  # noqa: BLE001 - the window itself is broken: all that is left is the terminal
            print(f"spikeview: could not report the error in the window ({e}).", file=sys.stderr)

    return hook


def _quit_on_ctrl_c(app: Any, interrupted: list[bool]) -> Any:
    """Ctrl-C in the terminal closes the app (as it stops every sub-command) instead of a KeyboardInterrupt
    traceback reported as a bug while the window stays open.

    Python runs its signal handlers only between bytecodes, never inside Qt's event loop, so a timer wakes the
    interpreter a few times a second. Returns the function that undoes this (the previous handler back, the
    timer gone); nothing is installed off the main thread or when SIGINT is ignored (a background job: it
    stays ignored).
    """
    from PySide6 import QtCore

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.SIG_IGN or previous is None:
        return lambda: None

    def on_sigint(signum: int, frame: Any) -> None:
        interrupted.append(True)
        QtCore.QTimer.singleShot(0, app.quit)  # also when the loop has not started yet (a demo still loading)

    signal.signal(signal.SIGINT, on_sigint)
    wake = QtCore.QTimer(app)
    wake.setObjectName("sigint_wake")
    wake.timeout.connect(lambda: None)
    wake.start(200)

    def undo() -> None:
        signal.signal(signal.SIGINT, previous)
        wake.stop()
        wake.deleteLater()

    return undo


def run_app(path: str | os.PathLike[str] | None = None) -> int:
    """Open the main window on ``path`` (or the built-in demo) and run the event loop; returns the exit status."""
    app = make_application()
    from PySide6 import QtCore

    from spikeview.gui.main_window import MainWindow

    window = MainWindow()
    try:  # live capture (USB and simulated cameras) when its pieces are installed
        from spikeview.gui.live_panel import install_live

        install_live(window)
    except ImportError as e:  # pragma: no cover - pyusb missing: the rest of the app works
        window.statusBar().showMessage(f"Live capture is unavailable ({e}).", 10000)
    sys.excepthook = _excepthook(window)
    interrupted: list[bool] = []
    undo_ctrl_c = _quit_on_ctrl_c(app, interrupted)
    window.show()
    if path is None:
        window.open_demo()
    else:
        window.open_path(Path(path))
    try:
        status = int(app.exec())
    finally:
        undo_ctrl_c()
    window.close()  # after app.quit() the window may still be open: stop its workers, save the settings
    sys.excepthook = sys.__excepthook__
    if interrupted:
        print("spikeview: interrupted (Ctrl-C); the window was closed, its settings saved.", file=sys.stderr)
        status = 130
    # Closing the last window posts a Quit event that exec() has returned before seeing; left queued, the
    # next event processing would deliver it and make every later event loop of this QApplication return
    # at once (a second window in the same process, or the next test, would freeze).
    QtCore.QCoreApplication.removePostedEvents(app, QtCore.QEvent.Type.Quit)
    window.deleteLater()
    QtCore.QCoreApplication.sendPostedEvents(None, QtCore.QEvent.Type.DeferredDelete)
    return status


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(run_app(sys.argv[1] if len(sys.argv) > 1 else None))
