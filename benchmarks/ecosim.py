"""An independent, ecosystem-style colour spike simulator, and a score of the CLI's PNGs against its truth.

Not spikeview's simulator: display-referred RGB (the image's own values, as the ecosystem's data sets use frames)
mosaicked RGGB, integrate-and-fire with a random initial phase and no noise (Spike-Zoo's and SpikeCV's simulators
fire regularly), no colour cast (R = G = B response), no dark current; written LSB-first and flipped like SpikeCV's
``SpikeToRaw``, with no sidecar. Used in benchmarks/results/colour.md (section 9) to see what a capture unlike
spikeview's own gets from the CLI's defaults.

    python benchmarks/ecosim.py make OUT_DIR            # chelsea, coffee, astronaut, rocket: bright (0.6) and dark (0.06)
    spikeview reconstruct OUT_DIR/chelsea.dat --width 256 --height 256 --cfa RGGB --flip-vertical --method guided --out g.png
    python benchmarks/ecosim.py score g.png OUT_DIR/chelsea.truth.npy
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SCENES = ("chelsea", "coffee", "astronaut", "rocket")


def make(name: str, rate: float, ticks: int, out: Path, size: int = 256, seed: int = 1) -> None:
    import skimage.data as data
    from skimage.transform import resize

    img = getattr(data, name)()
    img = np.stack([img] * 3, -1) if img.ndim == 2 else img[..., :3]
    img = resize(img.astype(np.float64) / 255.0, (size, size), anti_aliasing=True)
    np.save(out.with_suffix(".truth.npy"), img)
    mos = np.empty((size, size))
    mos[0::2, 0::2], mos[0::2, 1::2] = img[0::2, 0::2, 0], img[0::2, 1::2, 1]
    mos[1::2, 0::2], mos[1::2, 1::2] = img[1::2, 0::2, 1], img[1::2, 1::2, 2]
    acc = np.random.default_rng(seed).random((size, size))
    base = 2 ** np.arange(8)
    with open(out, "wb") as f:
        for _ in range(ticks):
            acc += mos * rate
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
    elif len(sys.argv) == 4 and sys.argv[1] == "score":
        print("  ".join(f"{k} {v:.2f}" for k, v in score(sys.argv[2], sys.argv[3]).items()))
    else:
        print(__doc__)
        sys.exit(2)
