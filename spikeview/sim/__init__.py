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

_EXPORTS = {  # name → module, imported on first use
    **dict.fromkeys(["SimConfig", "NOISE_SWITCHES"], "spikeview.sim.config"),
    **dict.fromkeys(["Scene", "ArrayScene", "StaticScene", "ImageSequenceScene", "VideoScene", "MotionScene", "Fan",
                    "ResizedScene", "open_scene"], "spikeview.sim.scenes"),
    **dict.fromkeys(["read_image", "srgb_to_linear", "linear_to_srgb"], "spikeview.sim.images"),
    **dict.fromkeys(["SensorPattern", "SpikeSimulator", "SimulatedCapture", "simulate"], "spikeview.sim.simulator"),
    **dict.fromkeys(["simulate_to_file", "load_ground_truth", "GroundTruth", "SimulationFiles"], "spikeview.sim.write"),
    **dict.fromkeys(["demo_scene", "demo_capture"], "spikeview.sim.demo"),
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
