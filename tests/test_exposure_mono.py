"""One exposure for every CFA: monochrome and Bayer captures come out right by default.

The white point and the frames share one unit (``Y·α/η`` with gray-world gains, the plain rate ``Y``
for monochrome, whose frames carry no η). Before, a monochrome white point was in ``Y/η`` units while
its frames were ``Y``: Spike-Zoo's clips came out with 37–86 % of their pixels at full scale and the
guided output 11× darker than TFP. Every test runs the command line (the user's path) on a monochrome
and on a Bayer capture of the same scene: a dim one, like the public monochrome clips (rates ≤ 0.55).
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from spikeview.cli.main import main
from spikeview.io.plain import write_plain
from test_guided_helpers import spikes_from_rates

H = W = 32
TICKS = 200
#: ``--cfa`` value and the number of output channels
CFAS = {"none": 1, "RGGB": 3}


def _rates(cfa: str) -> np.ndarray:
    """A smooth dim scene (0.03–0.55 spikes per tick); Bayer: a green cast like real sensors."""
    from scipy.ndimage import zoom

    rng = np.random.default_rng(11)
    img = zoom(rng.uniform(0.06, 1.0, (6, 6)), (H / 6 + 1e-9, W / 6 + 1e-9), order=1)[:H, :W] * 0.55
    if cfa == "none":
        return img
    from spikeview.cfa import channel_map

    return img * np.array([0.6, 1.0, 0.5])[channel_map(cfa, H, W)]


@pytest.fixture(scope="module", params=list(CFAS))
def capture(request, tmp_path_factory):
    cfa = request.param
    path = tmp_path_factory.mktemp(f"cap_{cfa}") / "cap.dat"
    write_plain(path, spikes_from_rates(_rates(cfa), TICKS, seed=3))
    return path, cfa


def _run(capture, out, *extra) -> None:
    path, cfa = capture
    argv = ["reconstruct", str(path), "--width", str(W), "--height", str(H), "--cfa", cfa, "--out", str(out), *map(str, extra)]
    assert main(argv) == 0


def _white(out) -> float:
    import tomllib

    with open(f"{out}.preset.toml", "rb") as fh:
        return float(tomllib.load(fh)["export"]["white"])


def test_npy_defaults_put_at_most_half_a_percent_at_full_scale(capture, tmp_path):
    """The issue's check on a capture like Spike-Zoo's: ≤ 0.5 % of the pixels at 1.0, not blown out."""
    _run(capture, tmp_path / "z.npy", "--range", "10:190:20")
    z = np.load(tmp_path / "z.npy")
    assert z.shape[-1:] == ((W,) if capture[1] == "none" else (3,))
    assert (z >= 0.999).mean() <= 0.005
    assert 0.2 < z.mean() < 0.7  # neither white nor black: the white point is the frames' own bright end


def test_white_point_is_in_the_units_of_the_frames(capture, tmp_path):
    """The recorded white point divides the linear (EXR) frame: monochrome white = the 99.9th
    percentile of the rates Y themselves (a white point in Y/η units would be half of it)."""
    path, cfa = capture
    _run(capture, tmp_path / "f.exr", "--at", "100")
    white = _white(tmp_path / "f.exr")
    img = oiio.ImageBuf(str(tmp_path / "f.exr")).get_pixels(oiio.FLOAT)
    if cfa == "none":
        from spikeview.io import open_source

        with open_source(path, width=W, height=H, cfa=None) as src:
            from spikeview.classical.tfp import tfp

            y = tfp(src, 100, 10)
        np.testing.assert_allclose(img[..., 0], y / white, rtol=2e-3, atol=1e-3)
        rates = spikes_from_rates(_rates("none"), TICKS, seed=3).reshape(-1, 10, H, W).mean(axis=1)
        assert white == pytest.approx(np.sort(rates.ravel())[int(0.999 * rates.size)], abs=0.1 + 1e-9)
    assert 0.75 < img.max() < 1.5  # the frame's brightest values sit near 1 in the EXR (a white point in Y/η: 1.7)


def test_png_mp4_exr_and_npy_share_the_exposure(capture, tmp_path):
    from spikeview.export.display import srgb_encode

    _run(capture, tmp_path / "z.npy", "--at", "100")
    z = np.load(tmp_path / "z.npy")[0]
    _run(capture, tmp_path / "f.exr", "--at", "100")
    exr = oiio.ImageBuf(str(tmp_path / "f.exr")).get_pixels(oiio.FLOAT)
    exr = exr[..., 0] if z.ndim == 2 else exr
    np.testing.assert_allclose(np.clip(exr, 0, 1), z, atol=2e-3)  # half floats
    _run(capture, tmp_path / "f.png", "--at", "100")
    png = oiio.ImageBuf(str(tmp_path / "f.png")).get_pixels(oiio.UINT8).astype(np.float64)
    png = png[..., 0] if z.ndim == 2 else png
    want = np.round(255 * srgb_encode(z))
    assert np.abs(png - want).max() <= 1
    import av

    _run(capture, tmp_path / "v.mp4", "--range", "90:111:10")
    with av.open(str(tmp_path / "v.mp4")) as c:
        frame = next(iter(c.decode(video=0))).to_ndarray(format="rgb24").astype(np.float64)
    # H.264 4:2:0 at crf 18: the mean level within 3 codes of the PNG's (first frame = tick 90)
    _run(capture, tmp_path / "g.png", "--at", "90")
    ref = oiio.ImageBuf(str(tmp_path / "g.png")).get_pixels(oiio.UINT8).astype(np.float64)
    assert abs(frame.mean() - ref.mean()) < 3.0


def test_guided_and_tfp_agree_in_exposure(capture, tmp_path):
    """Guided frames come back in the units of the classical frames: the same mapping gives means
    within ±20 % (monochrome: the sampler sees Y itself; its start is not divided by η)."""
    _run(capture, tmp_path / "t.npy", "--at", "100")
    _run(capture, tmp_path / "g.npy", "--at", "100", "--method", "guided", "--steps", "2", "--seed", "1")
    t, g = np.load(tmp_path / "t.npy"), np.load(tmp_path / "g.npy")
    assert g.shape == t.shape
    assert 0.8 < g.mean() / t.mean() < 1.2
    assert (g >= 0.999).mean() <= 0.005


def test_guided_monochrome_start_is_the_plain_rate():
    """The sampler's monochrome start estimate is the TFP rate Y (no η: monochrome has no cast)."""
    from spikeview.guided.baseline import start_estimate
    from spikeview.guided.observation import Observation

    y = np.random.default_rng(0).integers(0, 6, (16, 16)) / 10.0
    obs = Observation(y, None, 10, None, eta=3.0)
    np.testing.assert_allclose(start_estimate(obs, False, False), y, atol=1e-6)


def test_zarr_store_then_export_matches_a_plain_npy_run(tmp_path):
    """Monochrome through the batch path: the store exported to .npy has the plain run's exposure."""
    pytest.importorskip("zarr")
    path = tmp_path / "m.dat"
    write_plain(path, spikes_from_rates(_rates("none"), TICKS, seed=3))
    cap = (path, "none")
    _run(cap, tmp_path / "ref.npy", "--range", "10:190:20")
    _run(cap, tmp_path / "s.zarr", "--range", "10:190:20")
    assert main(["export", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "e.npy")]) == 0
    ref, exp = np.load(tmp_path / "ref.npy"), np.load(tmp_path / "e.npy")
    assert exp.shape == ref.shape
    np.testing.assert_allclose(exp, ref, atol=1e-6)
    assert (exp >= 0.999).mean() <= 0.005


def test_guided_and_tfp_agree_on_a_white_balanced_bayer_sensor(tmp_path):
    """Gains neutral in colour (every site at the same rate scale): the plan dropped C as 'neutral', and with
    it the exposure the sampler sees, so guided came out at 0.6× TFP; C stays on unless it is the identity."""
    path = tmp_path / "wb.dat"
    rates = _rates("none")  # the same scene behind every filter site: gray-world gains all alike
    write_plain(path, spikes_from_rates(rates, TICKS, seed=3))
    cap = (path, "RGGB")
    _run(cap, tmp_path / "t.npy", "--at", "100")
    _run(cap, tmp_path / "g.npy", "--at", "100", "--method", "guided", "--steps", "2", "--seed", "1")
    t, g = np.load(tmp_path / "t.npy"), np.load(tmp_path / "g.npy")
    assert 0.8 < g.mean() / t.mean() < 1.2
