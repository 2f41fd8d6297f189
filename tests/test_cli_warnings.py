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


def test_a_dark_capture_tells_a_tfp_user_what_to_do(tmp_path):
    """A capture whose 10-tick windows hold under 3 spikes at the white (its white point came from longer windows):
    TFP's frame is single spikes, and the CLI says so with the two ways out; a bright capture gets no such note; the
    guided method none either. Monochrome and Bayer."""
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(1)
    for cfa in ("RGGB", "none"):
        for name, p in (("dark", 0.02), ("bright", 0.4)):
            s = (rng.random((200, 32, 32)) < p * np.linspace(0.2, 1.0, 32)[None, None, :]).astype(np.uint8)
            path = tmp_path / f"{name}_{cfa}.dat"
            write_plain(path, s, cfa=None if cfa == "none" else cfa)
            for method in ("tfp", "guided") if name == "dark" else ("tfp",):
                r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(path), "--cfa", cfa,
                                    "--width", "32", "--height", "32", "--method", method, "--at", "100",
                                    "--out", str(tmp_path / f"{name}_{cfa}_{method}.png")],
                                   capture_output=True, text=True, timeout=300)
                assert r.returncode == 0, r.stderr
                said = "note: a dark capture for a 10-tick window" in r.stderr and "--method guided" in r.stderr
                assert said == (name == "dark" and method == "tfp"), (name, cfa, method, r.stderr)
