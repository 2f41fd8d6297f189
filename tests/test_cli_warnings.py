"""A warning reaches a CLI user as one line like the CLI's other messages, without a source path or code line
(here the colour cast of a Bayer capture whose blue photosites never fire; the same formatting serves
OpenVINO giving up mid-run)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np


def test_a_warning_is_one_plain_line(tmp_path):
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(0)
    s = (rng.random((60, 16, 16)) < 0.3).astype(np.uint8)
    s[:, 1::2, 1::2] = 0  # RGGB: the blue photosites never fire
    write_plain(tmp_path / "noblue.dat", s, cfa="RGGB")
    r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(tmp_path / "noblue.dat"), "--method", "tfp",
                        "--at", "30", "--out", str(tmp_path / "nb.png")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "channel B has no spikes" in ln]
    assert len(lines) == 1 and lines[0].startswith("spikeview: warning: Colour cast:"), r.stderr
    assert ".py:" not in r.stderr and "Warning:" not in r.stderr and "warnings.warn" not in r.stderr
