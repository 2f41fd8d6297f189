"""`spikeview info FILE | head -3`: a reader that stops early is not a bug report."""

from __future__ import annotations

import subprocess
import sys

import numpy as np


def test_info_into_a_closed_pipe_is_quiet(tmp_path):
    path = tmp_path / "s.npy"
    rng = np.random.default_rng(0)
    np.save(path, (rng.random((40, 16, 16)) < 0.3).astype(np.uint8))
    code = "import sys; from spikeview.cli.main import main; sys.exit(main())"
    p = subprocess.Popen([sys.executable, "-c", code, "info", str(path), "--cfa", "none"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # the reader is gone before the first line is written (like `| head -0`)
    with p.stderr:
        err = p.stderr.read().decode()
    rc = p.wait(timeout=120)
    assert "bug" not in err and "Traceback" not in err and "Exception ignored" not in err, err
    assert err == "", err
    assert rc == 1


def test_info_into_an_open_pipe_still_works(tmp_path):
    path = tmp_path / "s.npy"
    np.save(path, (np.random.default_rng(1).random((40, 16, 16)) < 0.3).astype(np.uint8))
    code = "import sys; from spikeview.cli.main import main; sys.exit(main())"
    r = subprocess.run([sys.executable, "-c", code, "info", str(path), "--cfa", "none"], capture_output=True, timeout=120)
    assert r.returncode == 0, r.stderr.decode()
    assert b"16 x 16" in r.stdout
