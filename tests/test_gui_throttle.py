"""The controller's throttle for the TFI and Rates panes: at once when paused, at most once per interval during playback."""

import time
from types import SimpleNamespace

import pytest

pytest.importorskip("PySide6")

from spikeview.gui.controller import Controller  # noqa: E402


class _Timer:
    def __init__(self, active=False):
        self.active, self.started = active, []

    def isActive(self):  # noqa: N802 - QTimer's name
        return self.active

    def start(self, ms):
        self.started.append(ms)
        self.active = True


def _run(playing, last, timer):
    calls = []
    fake = SimpleNamespace(session=SimpleNamespace(playing=playing))
    Controller._throttled(fake, lambda: calls.append(1), last, 200, timer)
    return len(calls)


def test_paused_submits_at_once_whatever_the_last_time():
    t = _Timer()
    assert _run(False, time.perf_counter(), t) == 1 and t.started == []


def test_playing_submits_once_the_interval_has_passed():
    t = _Timer()
    assert _run(True, time.perf_counter() - 1.0, t) == 1 and t.started == []


def test_playing_within_the_interval_waits_for_the_rest_of_it_once():
    t = _Timer()
    assert _run(True, time.perf_counter(), t) == 0
    assert len(t.started) == 1 and 0 <= t.started[0] <= 200
    assert _run(True, time.perf_counter(), t) == 0 and len(t.started) == 1  # the timer already runs
