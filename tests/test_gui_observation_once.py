"""The app's guided job builds the window's observation once: the plan it reports and the run share it
(at 1000x1000 the neighbours' counts and alignment cost ~1 s each time), with the same pixels. Mono and RGGB,
whole frame and ROI."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import spikeview.guided.video as video
from spikeview.session import jobs
from spikeview.session.model import default_params
from spikeview.gui.workers import JobContext
from spikeview.io.source import ArraySource
from spikeview.recipe import Recipe

SIZE, TICKS, TICK = 48, 120, 60


def capture(cfa):
    rng = np.random.default_rng(1)
    tex = rng.random((SIZE + 40, SIZE + 40)).astype(np.float32)
    rates = np.stack([tex[4:4 + SIZE, int(0.3 * t):int(0.3 * t) + SIZE] for t in range(TICKS)]) * 0.6
    return ArraySource((rng.random(rates.shape) < rates).astype(np.uint8), cfa=cfa)


def run_job(src, roi):
    recipe = Recipe().with_values({"guided.steps": 2, "guided.temporal_radius": 2})
    req = jobs.GuidedRequest(src, TICK, default_params(), None, roi, None, 1, recipe)
    return jobs.guided_job(req, JobContext(1, "guided", threading.Event(), {}, lambda _u: None))


@pytest.mark.parametrize("roi", [None, (8, 6, 24, 30)], ids=["whole", "roi"])
@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_the_guided_job_builds_the_window_once(cfa, roi, monkeypatch, count_observations):
    src = capture(cfa)
    calls = count_observations
    once = run_job(src, roi)
    assert calls == [TICK]
    monkeypatch.setattr(video, "same_window", lambda *a: False)  # the old way: the run builds it again
    twice = run_job(src, roi)
    assert calls == [TICK, TICK, TICK]
    assert np.array_equal(once.image, twice.image)
    assert once.plan == twice.plan


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_a_knob_change_reuses_the_pooled_window_and_gives_the_fresh_pixels(cfa, count_observations):
    """A second run in the same worker after a sampler knob changed (s) re-plans and re-samples but does not count and
    pool the window again; its pixels are those of a fresh worker at the same settings. Another tick is pooled anew."""
    src = capture(cfa)
    calls = count_observations
    state: dict = {}

    def run(values, tick=TICK, st=state):
        recipe = Recipe().with_values({"guided.steps": 2, "guided.temporal_radius": 2, **values})
        req = jobs.GuidedRequest(src, tick, default_params(), None, (8, 6, 24, 30), None, 1, recipe)
        return jobs.guided_job(req, JobContext(1, "guided", threading.Event(), st, lambda _u: None))

    run({})
    assert calls == [TICK]
    kept = run({"guided.s": 0.7})
    assert calls == [TICK]  # reused
    fresh = run({"guided.s": 0.7}, st={})
    assert calls == [TICK, TICK] and np.array_equal(kept.image, fresh.image)
    run({"guided.s": 0.7}, tick=TICK + 10)
    assert calls == [TICK, TICK, TICK + 10]
