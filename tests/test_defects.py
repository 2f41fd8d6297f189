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


def _rggb(img):
    from spikeview.cfa import channel_map

    cm = channel_map("RGGB", *img.shape[:2])
    return np.take_along_axis(img, cm[..., None].astype(np.int64), -1)[..., 0]


@pytest.mark.parametrize("cfa", ["RGGB", None])
def test_a_dim_capture_whose_darkest_patch_holds_a_little_light_gives_its_dark_rate(cfa):
    """Dark chelsea and logo at 0.03 spikes per tick: the darkest patch holds a trace of light in the more sensitive
    channels, so the floors are up to 1.5× apart; below DARK_DIM_RATE the lowest is then the dark rate. A brighter pedestal
    (above it) is scene light unless the floors agree within DARK_AGREE_RATIO; monochrome has no second witness."""
    from spikeview.classical.defects import DARK_AGREE_DIM, DARK_AGREE_RATIO, DARK_DIM_RATE, dark_rate

    rng = np.random.default_rng(5)
    scene = np.kron(rng.random((16, 16, 3)), np.ones((8, 8, 1))) * [0.8, 0.6, 0.5]
    scene[:32, :32] = [0.12, 0.06, 0.0]  # a dark brown corner: a little red and green, no blue
    sensor = np.array([0.6, 1.0, 0.5])
    dim = scene * sensor * 0.03 + 0.005  # 0.03 spikes per tick at white, the simulator's dark rate
    rates = _rggb(dim) if cfa else dim.mean(axis=-1)
    from spikeview.classical import white_balance as wb

    floors = wb.channel_floors(wb.cells_rgb(_rggb(dim), "RGGB"))
    assert floors.max() > DARK_AGREE_RATIO * floors.min() and floors.min() < DARK_DIM_RATE
    assert dark_rate(rates, cfa) == (pytest.approx(0.005, rel=0.05) if cfa else 0.0)
    bright = scene * sensor * 0.6 + 0.005  # the same scene in normal light: the floors are scene light
    assert dark_rate(_rggb(bright) if cfa else bright.mean(axis=-1), cfa) == 0.0
    lit = np.kron(0.3 + 0.7 * rng.random((16, 16, 3)), np.ones((8, 8, 1))) * [0.8, 0.6, 0.5]
    lit[:32, :32] = [0.3, 0.3, 0.04]  # the darkest patch, with light in every channel: floors over DARK_AGREE_DIM apart
    lit = lit * sensor * 0.03 + 0.005
    lit_floors = wb.channel_floors(wb.cells_rgb(_rggb(lit), "RGGB"))
    assert lit_floors.max() > DARK_AGREE_DIM * lit_floors.min() and lit_floors.min() < DARK_DIM_RATE
    assert dark_rate(_rggb(lit) if cfa else lit.mean(axis=-1), cfa) == 0.0  # its weakest channel's light is not taken


def test_a_colour_capture_without_a_cast_has_its_darkest_floor_read_as_light():
    """The same dim scene (no black: its darkest patch at a quarter of white) through a typical sensor (R 0.6 / G 1 /
    B 0.5) and through none (R = G = B, as captures made from RGB frames are): the first's floor may be a dark current
    (the guided Q rule takes it off), the second's is its darkest patch's light (Defects.pedestal 0)."""
    from spikeview.classical.defects import darkest_floor, without_cast

    import skimage.data
    from skimage.transform import resize

    img = resize(skimage.data.astronaut()[..., :3].astype(np.float64) / 255.0, (128, 128), anti_aliasing=True)
    img = 0.25 + 0.75 * img
    for gains, kept in (((0.6, 1.0, 0.5), True), ((1.0, 1.0, 1.0), False)):
        lit = img * np.asarray(gains)
        mos = np.empty((128, 128))
        mos[0::2, 0::2], mos[0::2, 1::2] = lit[0::2, 0::2, 0], lit[0::2, 1::2, 1]
        mos[1::2, 0::2], mos[1::2, 1::2] = lit[1::2, 0::2, 1], lit[1::2, 1::2, 2]
        rates = 0.05 * mos
        assert darkest_floor(rates, "RGGB") > 0.005  # TFI's reach reads it either way
        assert without_cast(rates, "RGGB") != kept, gains
    assert not without_cast(0.05 * img.mean(axis=-1), None)  # monochrome cannot tell: kept
