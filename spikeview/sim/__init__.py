"""Simulated chromatic spike captures with ground truth: scenes, the sensor model, file output.

Quick start::

    from spikeview.sim import SimConfig, VideoScene, simulate, simulate_to_file, demo_capture

    cap = demo_capture()                                   # 256×256, 1000 ticks, no input file
    cap = simulate(VideoScene("clip.mp4"), SimConfig(n_ticks=4000, width=512, height=512))
    simulate_to_file("clip.mp4", SimConfig(n_ticks=20000), "out/clip.dat")

Names are imported lazily, so ``import spikeview.sim`` does not load numba, PyAV or OpenImageIO
(the CLI's ``--help`` must stay quick). The sensor model and its units are documented in
:mod:`spikeview.sim.config`.
"""

from __future__ import annotations

from spikeview._lazy import lazy_exports

_EXPORTS = {
    "SimConfig": "spikeview.sim.config",
    "NOISE_SWITCHES": "spikeview.sim.config",
    "Scene": "spikeview.sim.scenes",
    "ArrayScene": "spikeview.sim.scenes",
    "StaticScene": "spikeview.sim.scenes",
    "ImageSequenceScene": "spikeview.sim.scenes",
    "VideoScene": "spikeview.sim.scenes",
    "MotionScene": "spikeview.sim.scenes",
    "Fan": "spikeview.sim.scenes",
    "ResizedScene": "spikeview.sim.scenes",
    "open_scene": "spikeview.sim.scenes",
    "read_image": "spikeview.sim.images",
    "srgb_to_linear": "spikeview.sim.images",
    "linear_to_srgb": "spikeview.sim.images",
    "SensorPattern": "spikeview.sim.simulator",
    "SpikeSimulator": "spikeview.sim.simulator",
    "SimulatedCapture": "spikeview.sim.simulator",
    "simulate": "spikeview.sim.simulator",
    "simulate_to_file": "spikeview.sim.write",
    "load_ground_truth": "spikeview.sim.write",
    "GroundTruth": "spikeview.sim.write",
    "SimulationFiles": "spikeview.sim.write",
    "demo_scene": "spikeview.sim.demo",
    "demo_capture": "spikeview.sim.demo",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
