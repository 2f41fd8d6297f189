"""The degradation preview runs the sampler's forward model on X at the sampler's own exposure.

Found by trying the app on the demo: on a Bayer capture A X = Q(C M X) came out about 2.7x brighter than
the observed Y (residual RMS 0.19 instead of the noise's ~0.04), because X went in at the output's linear
units (Y·α/η, white point about 2.7) instead of the sampler's exposure (white at EXPOSURE_LEVEL).
Monochrome and Bayer both covered.
"""

from __future__ import annotations

import numpy as np
import pytest

from test_gui_model import Ctx  # the worker's job context, as the app's jobs see it


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_forward_model_of_x_matches_the_observation(cfa):
    from spikeview.session.core import memory_stream
    from spikeview.session.jobs import PreviewRequest, degradation_job
    from spikeview.session.model import Session
    from spikeview.sim.demo import demo_capture

    s = Session()
    s.open_stream(memory_stream(demo_capture(size=48, n_ticks=80, cfa=cfa), "demo"))
    s.set_tick(40)
    view = degradation_job(PreviewRequest(s.source, 40, dict(s.params), None, recipe=s.recipe()), Ctx())
    img = view.result.images
    ax, y = img["qcmx"].astype(np.float64).mean(), img["y"].astype(np.float64).mean()
    assert abs(ax - y) < 0.1 * y, (cfa, ax, y)  # same brightness: A X models Y
    assert view.result.rmse < 0.1, (cfa, view.result.rmse)  # the residual is noise, not the picture
    # M X is shown like X (scene side, the session's display): the same exposure, not a darker one
    x, mx = img["x"].astype(np.float64).mean(), img["mx"].astype(np.float64).mean()
    assert abs(mx - x) < 0.25 * x, (cfa, mx, x)
