"""An independent, ecosystem-style colour spike simulator, and a score of the CLI's PNGs against its truth.

Not spikeview's simulator: display-referred RGB (the image's own values, as the ecosystem's data sets use frames)
mosaicked RGGB, integrate-and-fire with a random initial phase and no noise (Spike-Zoo's and SpikeCV's simulators
fire regularly), no colour cast (R = G = B response), no dark current; written LSB-first and flipped like SpikeCV's
``SpikeToRaw``, with no sidecar. Used in benchmarks/results/colour.md (section 9) to see what a capture unlike
spikeview's own gets from the CLI's defaults.

    python benchmarks/ecosim.py make OUT_DIR            # chelsea, coffee, astronaut, rocket: bright (0.6) and dark (0.06)
    python benchmarks/ecosim.py make-pans OUT_DIR       # chelsea, astronaut at 0.06, panning 0.1 and 0.02 px a tick
    spikeview reconstruct OUT_DIR/chelsea.dat --width 256 --height 256 --cfa RGGB --flip-vertical --method guided --out g.png
    python benchmarks/ecosim.py score g.png OUT_DIR/chelsea.truth.npy
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SCENES = ("chelsea", "coffee", "astronaut", "rocket")


def make(name: str, rate: float, ticks: int, out: Path, size: int = 256, seed: int = 1, pan: float = 0.0,
         mono: bool = False) -> None:
    """``pan``: photosites per tick along x (the scene slides left; the truth is the frame at the middle tick);
    ``mono``: no colour filter (the luminance, written as one channel)."""
    import skimage.data as data
    from scipy.ndimage import shift
    from skimage.transform import resize

    img = getattr(data, name)()
    img = np.stack([img] * 3, -1) if img.ndim == 2 else img[..., :3]
    margin = int(np.ceil(abs(pan) * ticks)) + 2
    big = resize(img.astype(np.float64) / 255.0, (size, size + margin), anti_aliasing=True)

    def frame(t: float) -> np.ndarray:
        x = shift(big, (0, -pan * t, 0), order=1, mode="nearest") if pan else big
        return x[:, :size]

    truth = frame(ticks / 2)
    np.save(out.with_suffix(".truth.npy"), np.repeat(truth.mean(-1, keepdims=True), 3, -1) if mono else truth)

    def light(t: float) -> np.ndarray:
        im = frame(t)
        if mono:
            return im.mean(-1)
        mos = np.empty((size, size))
        mos[0::2, 0::2], mos[0::2, 1::2] = im[0::2, 0::2, 0], im[0::2, 1::2, 1]
        mos[1::2, 0::2], mos[1::2, 1::2] = im[1::2, 0::2, 1], im[1::2, 1::2, 2]
        return mos

    still = light(0) if not pan else None
    acc = np.random.default_rng(seed).random((size, size))
    base = 2 ** np.arange(8)
    with open(out, "wb") as f:
        for t in range(ticks):
            acc += (still if still is not None else light(t + 0.5)) * rate
            s = acc >= 1.0
            acc[s] -= 1.0
            f.write((np.flipud(s).astype(np.uint8).reshape(-1, 8) * base).sum(1).astype(np.uint8).tobytes())


def score(png: str, truth: str) -> dict[str, float]:
    from skimage.io import imread

    from spikeview.metrics import colour_scores

    t = np.load(truth)
    x = imread(png).astype(np.float64) / 255.0
    x = np.stack([x] * 3, -1) if x.ndim == 2 else x[..., :3]
    out = {"direct": float(10 * np.log10(1.0 / np.mean((x - t) ** 2)))}
    out.update({k: float(v) for k, v in colour_scores(x, t).items()})
    return out


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "make":
        d = Path(sys.argv[2])
        d.mkdir(parents=True, exist_ok=True)
        for s in SCENES:
            make(s, 0.6, 200, d / f"{s}.dat")
            make(s, 0.06, 400, d / f"{s}_dark.dat")
    elif len(sys.argv) >= 3 and sys.argv[1] == "make-pans":  # dim pans, a photosite a window and a fifth of one
        d = Path(sys.argv[2])
        d.mkdir(parents=True, exist_ok=True)
        for s in ("chelsea", "astronaut"):
            for pan in (0.1, 0.02):
                make(s, 0.06, 400, d / f"{s}_pan{pan:g}.dat", pan=pan)
                make(s, 0.06, 400, d / f"{s}_pan{pan:g}_mono.dat", pan=pan, mono=True)
    elif len(sys.argv) == 4 and sys.argv[1] == "score":
        print("  ".join(f"{k} {v:.2f}" for k, v in score(sys.argv[2], sys.argv[3]).items()))
    else:
        print(__doc__)
        sys.exit(2)
