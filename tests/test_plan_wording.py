"""The plan's reasons print numbers a reader can check against each other (a Spike-Zoo clip once read
"TFP noise σ = 4.0/255 is above the target 4.00/255"), and frame sizes as width x height, like every other
line (the tiles row, ``spikeview info``)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from test_guided_helpers import make_source


def _obs(cfa, h=16, w=24):
    src = make_source("ramp", h, w, ticks=60, cfa=cfa)
    alpha = np.array([2.0, 2.0, 2.0]) if cfa else None
    return Observation.from_source(src, src.n_frames // 2, 10, alpha=alpha, eta=2.0, radius=0)


@pytest.mark.parametrize("cfa", ["RGGB", None])
def test_sigma_just_above_the_target_prints_above_it(cfa):
    obs = _obs(cfa)
    smax = 255 * float(make_plan(obs, GuidedConfig()).judged_sigma)  # the σ the rule compares (its worst block, its white)
    plan = make_plan(obs, GuidedConfig(noise_target=(smax - 0.012) / 255))  # σ 0.012/255 above the target
    assert plan.diffusion
    sigma, target = map(float, re.match(r"TFP noise σ = ([\d.]+)/255 (?:\(.*\) )?is above the target ([\d.]+)/255",
                                        plan.reasons["diffusion"]).groups())
    assert sigma > target, plan.reasons["diffusion"]
    assert abs(sigma - smax) <= 0.005 + 1e-9  # the measured σ, to the target's precision


@pytest.mark.parametrize("cfa", ["RGGB", None])
@pytest.mark.parametrize("delta", [0.002, -0.002, 0.0004])
def test_sigma_a_hair_from_the_target_prints_unequal_numbers(cfa, delta):
    # a Spike-Zoo clip read "TFP noise σ = 4.00/255 is above the target 4.00/255" (its σ 4.003/255)
    obs = _obs(cfa)
    smax = 255 * float(make_plan(obs, GuidedConfig()).judged_sigma)  # the σ the rule compares (its worst block, its white)
    plan = make_plan(obs, GuidedConfig(noise_target=(smax - delta) / 255))
    assert plan.diffusion == (delta > 0)
    sigma, target = map(float, re.match(r"TFP noise σ = ([\d.]+)/255 (?:\(.*\) )?(?:is above|already meets) the target ([\d.]+)/255",
                                        plan.reasons["diffusion"]).groups())
    assert (sigma > target) if delta > 0 else (sigma < target), plan.reasons["diffusion"]


@pytest.mark.parametrize("cfa", ["RGGB", None])
def test_levels_reason_names_the_frame_width_x_height(cfa):
    plan = make_plan(_obs(cfa, h=16, w=24), GuidedConfig())
    assert "a 24x16 frame" in plan.reasons["levels"], plan.reasons["levels"]
