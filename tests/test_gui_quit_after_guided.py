"""Quitting the app after a guided run ends the process cleanly (exit 0), in a child process: a crash
at exit kills the process, not just a test. Issue 15: OpenVINO infer requests kept in a
``threading.local`` were destroyed while the guided worker thread's Python state was torn down, and
the app died with a segmentation fault on quitting after any guided run."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("PySide6")

CHILD = textwrap.dedent("""
    import sys
    from PySide6 import QtCore
    from spikeview.gui.app import make_application
    from spikeview.gui.main_window import MainWindow
    from spikeview.guided.priors import ffdnet

    ffdnet.OV_MIN_LAYER_BYTES = 0  # OpenVINO (where installed) on this small frame too, as on a full-size one

    app = make_application()
    # settings of this run only (never the user's): a file in the test's folder
    w = MainWindow(settings=QtCore.QSettings("settings.ini", QtCore.QSettings.Format.IniFormat))
    w.show()
    w.open_demo(size=int(sys.argv[1]), n_ticks=120)
    state = {"started": False}
    deadline = QtCore.QDeadlineTimer(240_000)

    def poll():
        c = w.controller
        if deadline.hasExpired():
            print("timed out", flush=True)
            app.exit(3)
        elif not state["started"] and w.session.stream is not None and c.last_frames is not None:
            w.session.set("steps", 3)
            c.run_guided()
            state["started"] = True
        elif c.guided_result is not None:
            print("guided run finished", c.guided_result.image.shape, flush=True)
            w.close()  # the workers stop here: the guided worker thread ends
            app.quit()
            return
        QtCore.QTimer.singleShot(50, poll)

    QtCore.QTimer.singleShot(0, poll)
    code = app.exec()
    print("event loop over", code, flush=True)
    sys.exit(code)
""")


@pytest.mark.parametrize("size", [96])
def test_quit_after_a_guided_run_exits_cleanly(size, tmp_path):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONFAULTHANDLER="1")
    r = subprocess.run([sys.executable, "-c", CHILD, str(size)], capture_output=True, text=True, timeout=300,
                       env=env, cwd=tmp_path)
    out = r.stdout + r.stderr
    assert "guided run finished" in r.stdout, out[-3000:]
    assert r.returncode == 0, f"exit {r.returncode}:\n{out[-3000:]}"
    assert "event loop over 0" in r.stdout
