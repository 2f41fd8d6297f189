"""The simulated camera: replay of a spike source, simulated scenes, pacing, ROI, latest window."""

from __future__ import annotations

import time

import numpy as np
import pytest

from spikeview.errors import ParameterError
from spikeview.io import ArraySource, open_source
from spikeview.live import LiveStatus, SimCamera
from spikeview.sim.config import SimConfig
from spikeview.sim.demo import demo_scene
from spikeview.sim.simulator import SpikeSimulator

WAIT_S = 30


@pytest.fixture(scope="module")
def spikes() -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.integers(0, 2, (30, 16, 24), dtype=np.uint8)


def test_replay_to_the_end(tmp_path, spikes):
    cam = SimCamera(ArraySource(spikes, cfa="GRBG"), slowdown=0, loop=False, chunk_ticks=7)
    cam.start_recording(tmp_path / "replay.dat")
    cam.start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.ENDED and "30 frames" in cam.status_message
    assert cam.n_frames == 30 and cam.cfa == "GRBG"
    np.testing.assert_array_equal(cam.read(0, 30), spikes)
    np.testing.assert_array_equal(cam.latest(5), spikes[-5:])
    np.testing.assert_array_equal(cam.count(3, 9), spikes[3:9].sum(0))
    with open_source(tmp_path / "replay.dat") as src:
        assert src.cfa == "GRBG"
        np.testing.assert_array_equal(src.read(0, src.n_frames), spikes)
    cam.close()


def test_replay_loops_with_roi_and_frame_step(spikes):
    cam = SimCamera(ArraySource(spikes), slowdown=0, roi=[2, 4, 8, 16], frame_step=3, chunk_ticks=11)
    cam.start()
    assert cam.wait_frames(25, WAIT_S)
    cam.close(timeout=WAIT_S)
    n = cam.n_frames
    ticks = (np.arange(n) * 3) % 30  # every third tick, wrapping at the end of the source
    np.testing.assert_array_equal(cam.read(0, n), spikes[ticks][:, 2:10, 4:20])
    assert cam.tick_rate == pytest.approx(20_000 / 3)


def test_simulated_scene_matches_the_simulator():
    cam = SimCamera.demo(size=16, seed=3, slowdown=0, chunk_ticks=20)
    assert cam.cfa == "RGGB"
    cam.start()
    assert cam.wait_frames(60, WAIT_S)
    cam.close(timeout=WAIT_S)
    want = SpikeSimulator(demo_scene(16, 3), SimConfig(n_ticks=1, seed=3)).run(60)
    np.testing.assert_array_equal(cam.read(0, 60), want)


def test_a_finite_scene_ends():
    sim = SpikeSimulator(short_scene(), SimConfig(n_ticks=1, tick_rate=1000.0, cfa="none"))
    cam = SimCamera(sim, slowdown=0, chunk_ticks=4).start()
    assert cam.wait(WAIT_S)
    assert cam.status is LiveStatus.ENDED
    assert 0 < cam.n_frames <= 11  # the 10 ms scene at 1 kHz
    cam.close()


def short_scene():
    """Two grey frames at 200 fps: a 10 ms scene."""
    from spikeview.sim.scenes import ArrayScene

    return ArrayScene(np.full((2, 8, 8, 3), 0.5, np.float32), fps=200.0)


def test_pacing_waits_and_close_interrupts_it(spikes):
    # at 1e6× slower each tick takes 50 s of wall time: only the first chunk can be out, and close
    # must not wait for the next one
    cam = SimCamera(ArraySource(spikes), slowdown=1e6, chunk_ticks=1).start()
    time.sleep(0.3)
    assert cam.n_frames <= 1
    assert cam.stop(timeout=WAIT_S)
    assert cam.status is LiveStatus.STOPPED
    cam.close()


def test_rejects_what_it_cannot_play():
    with pytest.raises(ParameterError, match="SpikeSource or a SpikeSimulator"):
        SimCamera(np.zeros((3, 8, 8)))
    with pytest.raises(ParameterError, match="slowdown"):
        SimCamera(ArraySource(np.zeros((3, 8, 8), np.uint8)), slowdown=-1)
