"""A demo scene and capture that need no input file (built from scikit-image's shipped images).

The desktop app opens on :func:`demo_capture` at start-up, so it is kept cheap: a 256×256,
1000-tick capture (50 ms of scene time, all noise on) takes about 1 s of CPU once the kernels are
compiled (numba caches them on disk; the first run in a fresh checkout adds ~5 s of compilation).
``benchmarks/bench_sim.py`` measures it.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from spikeview.errors import ParameterError
from spikeview.sim.config import SimConfig
from spikeview.sim.images import to_linear_rgb
from spikeview.sim.scenes import Fan, MotionScene
from spikeview.sim.simulator import SimulatedCapture, simulate

#: content speed of the demo pan, in multiples of the output size per second
DEMO_PAN_PER_SIZE = 0.3
#: revolutions per second of the demo fan
DEMO_FAN_REV_PER_S = 6.0
#: key frames per second of the demo scene (see :func:`demo_scene`)
DEMO_RENDER_RATE = 4000.0


@functools.lru_cache(maxsize=4)
def _demo_canvas(height: int) -> np.ndarray:
    """Coffee | astronaut | chelsea side by side, each resized to ``height``, linear RGB (read-only).

    At ``height = 512`` the astronaut spans x in [768, 1280).
    """
    from skimage import data
    from skimage.transform import resize

    parts = []
    for name in ("coffee", "astronaut", "chelsea"):
        img = to_linear_rgb(getattr(data, name)(), name=f"skimage.data.{name}")
        h, w = img.shape[:2]
        width = round(w * 512 / h * height / 512)
        parts.append(resize(img, (height, width), order=1, anti_aliasing=h > height, preserve_range=True))
    canvas = np.ascontiguousarray(np.concatenate(parts, axis=1), dtype=np.float32)
    canvas.setflags(write=False)
    return canvas


def demo_scene(size: int = 256, seed: int = 0, render_rate: float | None = DEMO_RENDER_RATE) -> MotionScene:
    """A colourful moving scene: a gentle pan over three photographs and a rotating fan.

    The view (``size × size``) shows a 384-pixel-tall window of a 512-pixel-tall strip (coffee
    cup, astronaut, cat from ``skimage.data``), centred near the astronaut; the camera pans right
    (the content moves left) at ``0.3 · size`` pixels per second, and a four-blade fan with
    saturated red, yellow, cyan and magenta blades turns clockwise at 6 rev/s in the lower right.
    ``seed`` shifts the view, the pan direction (within ±20°) and the fan's phase.

    Key frames are rendered at 4 kHz (every 5 ticks at 20 kHz) and blended in between: rendering
    every tick costs 1.1 ms at 256×256, twice the sensor itself, while between two key frames the
    fastest point (the blade tips, 0.2·size from the hub) moves 0.5 px at size 256, so the blend
    only softens the blade edges by half a pixel. Ground truth is the same blend, so it stays
    exactly what the sensor integrated.

    Args:
        size: output height and width in pixels (≥ 16).
        seed: variation of the view (any int ≥ 0).
        render_rate: key frames per second (``None``: render every tick exactly).
    """
    if size < 16:
        raise ParameterError(f"A demo scene of {size}x{size} pixels is too small: use at least 16 (--size 16).")
    rng = np.random.default_rng([seed, 7])
    # the strip is built at the output scale (the view shows 384 of its 512 nominal rows)
    k = size / 384.0
    canvas = _demo_canvas(round(512 * k))
    cx = ((768 + 256 + rng.uniform(-120, 120)) * k)
    cy = ((256 + rng.uniform(-40, 40)) * k)
    angle = math.radians(rng.uniform(-20, 20))
    speed = DEMO_PAN_PER_SIZE * size
    fan = Fan(
        center=(0.74 * size, 0.72 * size), radius=0.2 * size, rev_per_s=DEMO_FAN_REV_PER_S, n_blades=4, blade_fraction=0.5,
        colours=((0.85, 0.04, 0.03), (0.9, 0.75, 0.02), (0.02, 0.6, 0.8), (0.7, 0.05, 0.75)),
        hub_radius=0.04 * size, hub_colour=(0.3, 0.3, 0.3), phase_deg=float(rng.uniform(0, 90)),
    )
    return MotionScene(canvas, size=(size, size), pan=(-speed * math.cos(angle), -speed * math.sin(angle)),
                       fans=[fan], center=(cx, cy), scale=1.0, render_rate=render_rate)


def demo_capture(size: int = 256, n_ticks: int = 1000, seed: int = 0, **config: object) -> SimulatedCapture:
    """Simulate :func:`demo_scene` with default sensor settings (RGGB, rate 0.6, all noise on).

    Args:
        size: output height and width in pixels.
        n_ticks: ticks to simulate (1000 ticks = 50 ms at 20 kHz).
        seed: seeds both the scene variation and the sensor noise.
        **config: further :class:`SimConfig` settings (e.g. ``cfa="none"``, ``shot_noise=False``).
    """
    cfg = SimConfig(n_ticks=n_ticks, seed=seed, **config)  # type: ignore[arg-type]
    return simulate(demo_scene(size, seed), cfg)
