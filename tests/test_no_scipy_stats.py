"""The guided path's statistics come from scipy.special (scipy.stats costs ~0.3-0.5 s of start-up on every
CLI run): same values as scipy.stats, and neither the plan nor the noise module imports scipy.stats."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("keep", [0.5, 0.9, 0.99])
def test_trim_factor_is_the_truncated_normal_moment(keep):
    from scipy.stats import norm

    from spikeview.classical.noise import trim_factor

    a = norm.ppf(0.5 + keep / 2)
    assert trim_factor(keep) == pytest.approx(keep - 2 * a * norm.pdf(a), rel=1e-12)


def test_changed_blocks_threshold_is_the_chi2_quantile():
    from scipy.special import chdtri
    from scipy.stats import chi2

    for k in (16, 256):
        for alpha in (1e-3, 0.05):
            assert chdtri(k, alpha) == pytest.approx(chi2.ppf(1 - alpha, k), rel=1e-12)


def test_the_guided_plan_does_not_import_scipy_stats():
    code = ("import sys, spikeview.guided.plan, spikeview.classical.noise, spikeview.guided.temporal; "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"
