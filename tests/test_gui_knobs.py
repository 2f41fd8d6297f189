"""The guided panel's knobs follow a hand-set Q at once (issue 27: after Q was set on at 1000², k stayed greyed for the
seconds the new plan takes, and a k typed meanwhile was lost); a plan computed before the change does not grey it
again. Monochrome and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from spikeview.io.source import ArraySource  # noqa: E402
from spikeview.session import core  # noqa: E402

pytestmark = [pytest.mark.gui]

Q_OFF = "soft quantisation Q is off (rate 4 spikes per photosite per window >= 1.1); turn Q on to use k"


@pytest.mark.parametrize("cfa", ["RGGB", None])
def test_k_follows_a_hand_set_q_before_the_plan_arrives(qtbot, window, cfa):
    rng = np.random.default_rng(0)
    label = f"knobs-{cfa}"
    window.set_stream(core.memory_stream(ArraySource((rng.random((60, 32, 32)) < 0.4).astype(np.uint8), cfa=cfa), label))
    qtbot.waitUntil(lambda: window.session.stream is not None and window.session.stream.label == label, timeout=60000)
    panel, s = window.guided_panel, window.session
    s.set("quantise", "auto")
    stale = {path: None for path in panel.knob_controls}
    stale["guided.k"] = Q_OFF  # the plan of the window with Q left to the plan: off at this rate
    panel.show_knobs(stale)
    assert not panel.k.isEnabled() and "Q is off" in panel.k.toolTip()
    s.set("quantise", "on")  # at once, without a new plan
    assert panel.k.isEnabled()
    panel.show_knobs(stale)  # a plan computed before the change arrives late: k stays usable
    assert panel.k.isEnabled()
    s.set("quantise", "off")
    assert not panel.k.isEnabled() and "as set" in panel.k.toolTip()
    s.set("quantise", "auto")  # back to the plan's decision: its reason
    assert not panel.k.isEnabled() and panel.k.toolTip().endswith(Q_OFF + ".")
    no_diffusion = {path: "the plan skips diffusion for this window (…)" for path in panel.knob_controls}
    s.set("quantise", "on")
    panel.show_knobs(no_diffusion)  # Q on cannot make k act where no prior runs
    assert not panel.k.isEnabled() and "skips diffusion" in panel.k.toolTip()
