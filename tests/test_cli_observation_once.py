"""The CLI prints the first window's plan before a guided run: the run reuses that window's observation
(its neighbours are counted and aligned once, not twice at full resolution) and gives the same pixels."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main
from spikeview.guided.observation import Observation


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_the_printed_plan_s_observation_is_the_run_s(tmp_path, capsys, count_observations, cfa):
    dat = tmp_path / "c.dat"
    assert main(["simulate", "--demo", "--size", "48", "--ticks", "120", "--cfa", cfa, "--out", str(dat)]) == 0
    common = ["--method", "guided", "--steps", "2", "--temporal-radius", "2"]
    assert main(["reconstruct", str(dat), *common, "--range", "40:70:10", "--out", str(tmp_path / "r.npy")]) == 0
    assert count_observations == [40, 50, 60]  # the plan's window is not built again by the run
    assert "temporal" in capsys.readouterr().err  # the plan was printed (from that observation)
    # the same pixels as a run that builds the first window again (the reused observation is that window's)
    import spikeview.guided.video as video

    count_observations.clear()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(video, "same_window", lambda *a: False)
        assert main(["reconstruct", str(dat), *common, "--range", "40:70:10", "--out", str(tmp_path / "b.npy")]) == 0
    assert count_observations == [40, 40, 50, 60]
    assert np.array_equal(np.load(tmp_path / "r.npy"), np.load(tmp_path / "b.npy"))


def test_an_observation_of_other_settings_is_not_reused():
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.window import same_window as _same_window
    from spikeview.sim import SimConfig, demo_scene, simulate

    for cfa in ("RGGB", None):
        src = simulate(demo_scene(size=32, seed=0), SimConfig(n_ticks=60, width=32, height=32, cfa=cfa or "none", seed=0))
        a = np.array([1.0, 1.1, 1.2]) if cfa else None
        p = GuidedConfig(temporal_radius=1)
        obs = Observation.from_source(src, 30, p.window, alpha=a, eta=p.eta, radius=1)
        assert _same_window(obs, 30, p, a)
        assert not _same_window(obs, 40, p, a)
        assert not _same_window(obs, 30, p.replace(temporal_radius=2), a)
        assert not _same_window(obs, 30, p.replace(eta=p.eta * 2), a)
        if cfa:
            assert not _same_window(obs, 30, p, a * 1.01)
