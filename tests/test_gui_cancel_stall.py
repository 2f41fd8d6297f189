"""Cancel while a guided run is still building its window (issue 15, item 3): the sequence's α and white
point, the observation (the neighbouring windows' counts and their alignment: seconds at 1000×1000) and the
plan run inside the job's cancel scope, so Cancel stops them at the next count, the next alignment tile
comparison or the plan — before any step, with no plan reported. Monochrome and RGGB.

No wall-clock assertions: hooks on the source's ``count`` and on the alignment's ``_tile_chi`` set the job's
flag at a chosen call and count the calls that still ran after it (0 expected). Cancel inside the prior's
passes: tests/test_cancel_latency.py.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from spikeview.errors import Cancelled, cancel_scope
from spikeview.session import jobs
from spikeview.session.model import default_params
from spikeview.gui.workers import JobContext
from spikeview.io.source import ArraySource
from spikeview.recipe import Recipe

SIZE, TICKS, TICK = 48, 120, 60


class CountingSource(ArraySource):
    """An in-memory capture whose ``count`` calls are numbered; at call ``stop_at`` it sets ``flag``."""

    def __init__(self, spikes: np.ndarray, cfa: str | None):
        super().__init__(spikes, cfa=cfa)
        self.calls = 0
        self.stop_at: int | None = None
        self.flag: threading.Event | None = None
        self.after = 0  # counts made after the flag was set

    def count(self, a: int, b: int) -> np.ndarray:
        if self.flag is not None and self.flag.is_set():
            self.after += 1
        self.calls += 1
        if self.stop_at is not None and self.calls == self.stop_at and self.flag is not None:
            self.flag.set()
        return super().count(a, b)


def capture(cfa: str | None) -> CountingSource:
    """A textured scene panned by 0.3 px per tick (the pooling aligns neighbours: the search runs)."""
    rng = np.random.default_rng(0)
    tex = rng.random((SIZE + 40, SIZE + 40)).astype(np.float32)
    tex = (tex + np.roll(tex, 1, 0) + np.roll(tex, 1, 1) + np.roll(tex, 1, (0, 1))) / 4
    rates = np.stack([tex[4:4 + SIZE, int(0.3 * t):int(0.3 * t) + SIZE] for t in range(TICKS)]) * 0.6
    return CountingSource((rng.random(rates.shape) < rates).astype(np.uint8), cfa)


def request(src) -> jobs.GuidedRequest:
    recipe = Recipe().with_values({"guided.steps": 2})
    return jobs.GuidedRequest(src, TICK, default_params(), None, None, None, 1, recipe)


def context() -> tuple[JobContext, list]:
    reports: list = []
    return JobContext(1, "guided", threading.Event(), {}, reports.append), reports


def stages(src) -> dict[str, int]:
    """Count calls per stage of one uncancelled build (α/white, observation), without the sampler."""
    from spikeview.guided.window import observe_window
    from spikeview.pipeline import sampler_params

    ctx, _ = context()
    req = request(src)
    recipe = req.recipe.with_values({"run.method": "guided"})
    src.calls = 0
    state = jobs.sequence_state(src, recipe, None, ctx)
    n_seq = src.calls
    cfg = sampler_params(recipe, state)
    obs = observe_window(src, TICK, cfg, state.alpha).whole
    assert obs.pooling is not None and obs.pooling.offsets  # neighbours were pooled: the alignment ran
    out = {"sequence": n_seq, "observation": src.calls - n_seq}
    src.calls = 0
    return out


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
@pytest.mark.parametrize("where", ["sequence", "observation"])
def test_cancel_stops_the_counts_of_the_window(cfa, where):
    src = capture(cfa)
    n = stages(src)
    assert n["sequence"] >= 2 and n["observation"] >= 4
    ctx, reports = context()
    src.flag = ctx.cancelled
    # the flag is set inside the stage's second count: the next count must not start
    src.stop_at = 2 if where == "sequence" else n["sequence"] + 2
    with pytest.raises(Cancelled, match="counting spikes"):
        jobs.guided_job(request(src), ctx)
    assert src.after == 0
    assert reports == []  # no plan, no step
    assert "sampler" not in ctx.state  # the sampler was never built


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_cancel_stops_the_alignment_of_the_neighbours(cfa, monkeypatch):
    import spikeview.guided.temporal as temporal

    src = capture(cfa)
    ctx, reports = context()
    original = temporal._tile_chi
    seen = {"calls": 0, "after": 0}

    def hooked(*args, **kwargs):
        seen["calls"] += 1
        if seen["calls"] == 5:  # inside the motion search
            ctx.cancelled.set()
        out = original(*args, **kwargs)
        if ctx.cancelled.is_set() and seen["calls"] > 5:
            seen["after"] += 1  # a comparison computed after Cancel
        return out

    monkeypatch.setattr(temporal, "_tile_chi", hooked)
    with pytest.raises(Cancelled, match="aligning"):
        jobs.guided_job(request(src), ctx)
    assert seen["calls"] == 5 and seen["after"] == 0  # the comparison asked for after Cancel checked the flag first
    assert reports == [] and "sampler" not in ctx.state


def cancel_on_call(monkeypatch, module, name: str, ctx) -> None:
    """Replace ``module.name`` by a wrapper that sets the job's Cancel flag, then runs the original."""
    original = getattr(module, name)

    def hooked(*args, **kwargs):
        ctx.cancelled.set()
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, hooked)


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_cancel_stops_the_plan(cfa, monkeypatch):
    import spikeview.guided.plan as plan_module

    src = capture(cfa)
    ctx, reports = context()
    cancel_on_call(monkeypatch, plan_module, "start_variance", ctx)  # Cancel pressed as the plan starts its noise estimate
    with pytest.raises(Cancelled, match="planning"):
        jobs.guided_job(request(src), ctx)
    assert reports == [] and "sampler" not in ctx.state


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_an_unset_flag_changes_nothing(cfa):
    """The checks change no number: the observation built inside a scope whose flag stays unset is the same."""
    from spikeview.guided.window import observe_window
    from spikeview.pipeline import sampler_params

    src = capture(cfa)
    ctx, _ = context()
    recipe = request(src).recipe.with_values({"run.method": "guided"})
    state = jobs.sequence_state(src, recipe, None, ctx)
    cfg = sampler_params(recipe, state)
    plain = observe_window(src, TICK, cfg, state.alpha).whole
    with cancel_scope(threading.Event()):
        scoped = observe_window(src, TICK, cfg, state.alpha).whole
    assert np.array_equal(plain.y, scoped.y) and np.array_equal(plain.dtau, scoped.dtau)


@pytest.mark.parametrize("cfa", [None, "RGGB"], ids=["mono", "bayer"])
def test_cancel_stops_the_pooling_of_the_neighbours(cfa, monkeypatch):
    """After the alignment, each neighbouring window's pooling (≈0.1 s at 1000×1000) checks the flag."""
    import spikeview.guided.temporal as temporal

    src = capture(cfa)
    ctx, reports = context()
    cancel_on_call(monkeypatch, temporal, "_box_same_colour", ctx)  # the pooling loop's first 3×3 sums: Cancel pressed here
    with pytest.raises(Cancelled, match="pooling"):
        jobs.guided_job(request(src), ctx)
    assert reports == [] and "sampler" not in ctx.state
