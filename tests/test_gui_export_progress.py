"""The Export panel's progress line (issue 27): frames done, time taken, time left and the ETA, as the CLI's bar."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("PySide6")

from spikeview.gui.panels.export import progress_text


def test_progress_says_frames_time_left_and_eta():
    now = time.mktime((2026, 1, 2, 10, 0, 0, 0, 0, -1))  # local 10:00:00
    text = progress_text(10, 40, 20.0, now)  # 2 s a frame, 30 frames to go: 60 s left
    assert text.startswith("10 / 40 frames · 0:20 elapsed · 1:00 left · ETA 10:01:00")
    assert text.endswith("(2.0 s/frame)")
    assert progress_text(30, 40, 3.0, now).endswith("(10.0 frames/s)")
    assert progress_text(0, 40, 5.0, now) == "0 / 40 frames · 0:05 elapsed · time left after the first frame"
    assert "1:00:00 left" in progress_text(1, 2, 3600.0, now)  # an hour shows its hours
