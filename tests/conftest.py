import os
import sys

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")
# torch ops in these tiny tests run fastest single-threaded; with pytest-xdist workers and other
# jobs sharing the cores, torch's default thread pool oversubscribes them (10x slower measured).
os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture(autouse=True)
def _isolated_qt_settings(request, tmp_path_factory):
    """Every test that touches Qt gets its own, empty QSettings folder (never the user's, never another test's).

    ``QSettings("spikeview", "spikeview")`` (what the app uses when no settings object is passed) then
    reads and writes a fresh folder, so parameters, layout or recent files saved by one test cannot
    change the next, whatever the order. Tests that do not use Qt do not import it.
    """
    if "qtbot" not in request.fixturenames and "PySide6.QtCore" not in sys.modules:
        yield
        return
    from PySide6 import QtCore

    folder = str(tmp_path_factory.mktemp("qsettings"))
    for fmt in (QtCore.QSettings.Format.NativeFormat, QtCore.QSettings.Format.IniFormat):
        QtCore.QSettings.setPath(fmt, QtCore.QSettings.Scope.UserScope, folder)
    yield


@pytest.fixture
def settings(tmp_path):
    """The app's settings in a file of this test's own (an INI in ``tmp_path``)."""
    from PySide6 import QtCore

    return QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)


@pytest.fixture
def window(qtbot, settings):
    """The main window, shown offscreen at 1400×900 with pyqtgraph configured as the app does; closed after the test."""
    from spikeview.gui.app import configure_pyqtgraph
    from spikeview.gui.main_window import MainWindow

    configure_pyqtgraph()
    w = MainWindow(settings=settings)
    qtbot.addWidget(w)
    w.resize(1400, 900)
    w.tile_panels()  # every panel in sight (the default layout tabs them): their previews are computed
    w.show()
    yield w
    w.close()


@pytest.fixture
def count_observations(monkeypatch):
    """The centre ticks of every :meth:`Observation.from_source` call made while the test runs, in order."""
    from spikeview.guided.observation import Observation

    calls: list[int] = []
    orig = Observation.from_source.__func__

    def counted(cls, source, center, *a, **k):
        calls.append(int(center))
        return orig(cls, source, center, *a, **k)

    monkeypatch.setattr(Observation, "from_source", classmethod(counted))
    return calls
