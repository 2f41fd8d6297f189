"""Benchmark sets of the guided reconstruction: simulated captures with ground truth, and Spike-Zoo clips.

**Synthetic colour set.** Each scene is a linear-RGB still under a camera motion
(:class:`spikeview.sim.MotionScene`), simulated with the realistic sensor model (all noise terms of
:class:`spikeview.sim.SimConfig` on, RGGB, rate 0.6, default spectral gains). Frames are 10-tick
TFP windows; the ground truth is the clean linear frame at the window's centre tick. Scenes come in
four groups, each with tuning scenes (defaults may be chosen on them) and held-out scenes (only
reported):

* ``natural``: ``skimage.data`` photographs as they are;
* ``high-key``: bright scenes, most of the frame in the upper half of the range;
* ``low-key``: dark scenes (a few spikes per window: integer counts dominate);
* ``highlights``: medium-dark scenes with small regions near full scale (lamps, speculars).

The reconstruction is run on the **user's path**: nothing from the simulator's calibration is
used; the colour cast (α by the default white balance, auto) and the exposure (white point) are estimated from the spikes,
as the CLI does.

**Spike-Zoo clips.** The monochrome 400×250 plain ``.dat`` clips with ground-truth PNGs that ship
inside the ``spikezoo`` package (Spike-Zoo, Chen et al., https://github.com/chenkang455/Spike-Zoo,
MIT licence; files ``spikezoo/data/base/{train,test}/{spike,gt}``): 301 ticks each, LSB-first,
stored upside down (DOMAIN.md), ground truth at the centre tick. Get them without importing the
package: ``pip download spikezoo --no-deps`` and unzip the wheel; pass the folder holding
``spikezoo/`` (or ``data/base``) as ``spikezoo_dir``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spikeview.transfer import srgb_decode

#: scene name -> (group, tuning?, image recipe, pan (vx, vy) px/s, rotation deg/s, zoom per s)
SCENES: dict[str, tuple[str, bool, str, tuple[float, float], float, float]] = {
    "astronaut": ("natural", True, "astronaut", (1200.0, 400.0), 0.0, 1.0),
    "coffee": ("natural", True, "coffee", (-800.0, 900.0), 0.0, 1.0),
    "rocket": ("natural", False, "rocket", (900.0, 0.0), 0.0, 1.0),
    "coins_rgb": ("natural", False, "coins_rgb", (1500.0, 0.0), 0.0, 1.0),
    "chelsea_bright": ("high-key", True, "highkey:chelsea", (0.0, 0.0), 40.0, 1.2),
    "immunohistochemistry": ("high-key", False, "immunohistochemistry", (-600.0, -600.0), 20.0, 1.0),
    "page_bright": ("high-key", False, "highkey:page", (700.0, 300.0), 0.0, 1.0),
    "coffee_dark": ("low-key", True, "lowkey:coffee", (-800.0, 900.0), 0.0, 1.0),
    "astronaut_dark": ("low-key", False, "lowkey:astronaut", (1000.0, -500.0), 0.0, 1.0),
    "hubble_deep_field": ("low-key", False, "hubble_deep_field", (800.0, 400.0), 0.0, 1.0),
    "astronaut_lamps": ("highlights", True, "lamps:astronaut", (1200.0, 400.0), 0.0, 1.0),
    "rocket_lamps": ("highlights", False, "lamps:rocket", (900.0, 0.0), 0.0, 1.0),
    "colorwheel": ("highlights", False, "colorwheel", (600.0, 600.0), 10.0, 1.0),
}
GROUPS = ("natural", "high-key", "low-key", "highlights")
#: scenes on which defaults may be tuned; every other scene is held out
TUNE_SCENES = tuple(n for n, s in SCENES.items() if s[1])


@dataclass
class Case:
    """One benchmark window: its source, centre tick and clean linear ground truth."""

    scene: str
    group: str
    source: object
    center: int
    gt: np.ndarray

    @property
    def tuning(self) -> bool:
        return self.scene in TUNE_SCENES


def _photo(name: str) -> np.ndarray:
    from skimage import data

    if name in ("coins_rgb", "page"):  # gray photographs tinted, so every channel carries texture
        g = getattr(data, name.split("_")[0])().astype(np.float32) / 255.0
        return np.clip(np.stack([g * 1.0, g * 0.85, g * 0.6], axis=-1) * 255, 0, 255).astype(np.uint8)
    img = getattr(data, name)()
    if img.ndim == 2:
        img = np.stack([img] * 3, axis=-1)
    return img[..., :3]


def scene_image(recipe: str) -> np.ndarray:
    """The linear-RGB float image (values in [0, 1]) of an image recipe of :data:`SCENES`.

    ``name``: the photograph, sRGB-decoded; ``highkey:name``: ``1 − (1 − x)³`` (bright, smooth,
    nothing flat at 1); ``lowkey:name``: ``0.12 · x``; ``lamps:name``: ``0.25 · x`` with the
    brightest 2 % of its pixels (by luminance) raised to full scale in their own hue.
    """
    kind, _, name = recipe.rpartition(":")
    x = srgb_decode(_photo(name).astype(np.float64) / 255.0)
    if kind == "highkey":
        x = 1.0 - (1.0 - x) ** 3
    elif kind == "lowkey":
        x = 0.12 * x
    elif kind == "lamps":
        lum = x @ np.array([0.2126, 0.7152, 0.0722])
        hot = lum >= np.quantile(lum, 0.98)
        base = 0.25 * x
        base[hot] = x[hot] / np.maximum(x[hot].max(axis=-1, keepdims=True), 1e-6)
        x = base
    return np.clip(x, 0.0, 1.0).astype(np.float32)


def make_capture(name: str, size: int = 256, n_ticks: int = 60, seed: int = 0, window: int = 10,
                 pan: tuple[float, float] | None = None, **overrides):
    """Simulate scene ``name`` (see :data:`SCENES`) for ``n_ticks`` ticks at ``size × size``.

    ``pan`` (px/s) replaces the scene's own camera pan.
    """
    from spikeview.sim import MotionScene, SimConfig, simulate

    _, _, recipe, pan0, rot, zoom = SCENES[name]
    pan = pan0 if pan is None else pan
    scene = MotionScene(scene_image(recipe), size=(size, size), pan=pan, rotation=rot, zoom=zoom)
    cfg = SimConfig(n_ticks=n_ticks, seed=seed, gt_every=window, **overrides)
    return simulate(scene, cfg)


def make_cases(names=None, size: int = 256, frames: int = 2, window: int = 10, seed: int = 0,
               n_ticks: int = 200) -> list[Case]:
    """``frames`` windows per scene from an ``n_ticks``-tick capture (10 ms at 20 kHz), centred at
    ticks spread over its middle; the whole capture is the sequence α and the white point are
    estimated from (as the CLI does)."""
    names = list(names or SCENES)
    out = []
    for k, name in enumerate(names):
        cap = make_capture(name, size, n_ticks=n_ticks, seed=seed + k, window=window)
        for i in range(frames):
            c = int(round((i + 1) * n_ticks / (frames + 1))) // window * window + window // 2
            out.append(Case(name, SCENES[name][0], cap, c, cap.gt_at(c)))
    return out


# ------------------------------------------------------------------------------------ Spike-Zoo
@dataclass
class ZooClip:
    """One Spike-Zoo clip: the spike file, its ground truth (float in [0, 1]) and its name."""

    name: str
    path: Path
    gt: np.ndarray


def spikezoo_clips(root: str | Path) -> list[ZooClip]:
    """The ``.dat`` clips and ground-truth PNGs under ``root`` (a folder holding ``spikezoo/data/base``,
    ``data/base`` or ``base``), train and test, sorted by name. Empty when none are found."""
    from PIL import Image

    root = Path(root)
    for sub in ("spikezoo/data/base", "data/base", "base", "."):
        base = root / sub
        if (base / "test" / "spike").is_dir():
            break
    else:
        return []
    out = []
    for split in ("test", "train"):
        for dat in sorted((base / split / "spike").glob("*.dat")):
            png = base / split / "gt" / (dat.stem + ".png")
            if png.exists():
                gt = np.asarray(Image.open(png).convert("L"), dtype=np.float32) / 255.0
                out.append(ZooClip(f"{split}/{dat.stem}", dat, gt))
    return out
