"""A capture's own sensor defects (issue 25, item 4): hot photosites and a dead border found from the spikes, filled
before the frames, the white point and the guided observation see them, and named by ``spikeview info``. Monochrome
and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.classical.defects import find_defects
from spikeview.io.source import ArraySource

CFAS = pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
HOT = [(10, 12), (33, 40), (50, 7)]


def _capture(cfa, hot=True, dead_rows=0, ticks=300, seed=0):
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    tex = gaussian_filter(rng.random((64, 64)), 3.0)
    rate = 0.05 + 0.25 * (tex - tex.min()) / (tex.max() - tex.min())
    rates = np.broadcast_to(rate, (ticks, 64, 64)).copy()
    if hot:
        for y, x in HOT:
            rates[:, y, x] = 0.9
    if dead_rows:
        rates[:, :dead_rows] = 0.0
    return ArraySource((rng.random(rates.shape) < rates).astype(np.uint8), cfa=cfa)


@CFAS
def test_hot_photosites_and_a_dead_border_are_found_and_nothing_else(cfa):
    d = find_defects(_capture(cfa, dead_rows=3))
    assert sorted(map(tuple, np.argwhere(d.hot).tolist())) == sorted(HOT)
    assert d.border == (3, 0, 0, 0)
    clean = find_defects(_capture(cfa, hot=False, seed=1))
    assert not clean.hot.any() and clean.border == (0, 0, 0, 0)
    assert "3 hot pixels" in d.describe() and "top 3" in d.describe()


@CFAS
def test_hot_photosites_are_filled_for_the_frames_and_left_out_of_the_white_point(tmp_path, cfa, capsys):
    from spikeview.classical.calibration import attach
    from spikeview.classical.colour_cast import estimate_white
    from spikeview.cli.main import main

    src = _capture(cfa)
    plain = estimate_white(_capture(cfa, hot=False), None)
    attach(src, None)  # what the CLI and the app do with a capture opened without a camera profile
    assert src.info.camera is not None and src.info.camera.from_capture
    assert estimate_white(src, None) == pytest.approx(plain, rel=0.05)
    path = tmp_path / "c.npy"
    np.save(path, _capture(cfa).read(0, 300))
    out = tmp_path / "o.npy"
    assert main(["reconstruct", str(path), "--cfa", cfa or "none", "--method", "tfp", "--window", "100", "--at", "150",
                 "--transfer", "linear", "--out", str(out)]) == 0
    frame = np.squeeze(np.load(out))
    grey = frame.mean(axis=-1) if frame.ndim == 3 else frame
    for y, x in HOT:  # no photosite stands out from its neighbours any more
        around = grey[max(0, y - 3):y + 4, max(0, x - 3):x + 4]
        assert grey[y, x] <= np.median(around) + 5 * around.std() + 1e-6
    assert main(["info", str(path), "--cfa", cfa or "none"]) == 0
    said = capsys.readouterr().out
    assert "defects:     3 hot pixels" in said and "hot pixels filled from their neighbours" in said
