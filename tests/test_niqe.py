"""NIQE (Mittal et al. 2013), the no-reference score of ``spikeview bench --real`` / ``--low-light``
(spikeview.bench.niqe): its value, its ranking of a truth against a blur and noise, its errors, its packaged model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from spikeview.bench.niqe import half_size, model, niqe, niqe_gray, to_display_luma
from spikeview.errors import ParameterError
from spikeview.transfer import srgb_decode


def _camera() -> np.ndarray:
    """skimage's camera, 256² from its middle, in linear light."""
    import skimage.data

    return srgb_decode(skimage.data.camera()[128:384, 128:384] / 255.0)


def _astronaut() -> np.ndarray:
    import skimage.data

    return srgb_decode(skimage.data.astronaut()[:256, 200:456] / 255.0)


def test_known_values():
    """Pinned from this implementation, which matched basicsr 1.4.2's port of the MATLAB release to 1e-13 on these
    and 6 other images when that port's imresize ran in float64 (MATLAB's precision); as shipped, basicsr resizes in
    float32 and differs by up to ~1e-2 (here 3.93820, 5e-4 off): a 1e-7 change can move the AGGD shape to the next
    grid step."""
    import skimage.data

    assert niqe_gray(skimage.data.camera()[:288, :288].astype(np.float64)) == pytest.approx(3.938673014961895, abs=1e-9)
    assert niqe(_camera()) == pytest.approx(3.570455393505401, abs=1e-9)


def test_half_size_is_matlab_imresize_by_half():
    """An impulse gives MATLAB's ×0.5 bicubic antialiased weights 0.5·cubic(0.5·d) at d = ±0.5 … ±3.5."""
    x = np.zeros((32, 32))
    x[15, 15] = 1.0
    y = half_size(x)
    assert y.shape == (16, 16)
    r = np.zeros(16)
    r[6:10] = [-0.03515625, 0.43359375, 0.11328125, -0.01171875]  # output o sits at input 2o + 0.5: d = 2.5 … −3.5
    assert y == pytest.approx(np.outer(r, r), abs=1e-15)
    assert y.sum() == pytest.approx(0.25, abs=1e-12)  # a mean-preserving ×0.5: a quarter of the sum
    assert half_size(np.full((10, 12), 7.0)) == pytest.approx(np.full((5, 6), 7.0), abs=1e-12)  # edges mirrored


@pytest.mark.parametrize("scene", [_camera, _astronaut], ids=["mono", "rgb"])
def test_the_truth_ranks_better_than_a_strong_blur_and_heavy_noise(scene):
    truth = scene()
    assert truth.ndim == (2 if scene is _camera else 3)
    sigma = (3.0, 3.0, 0.0)[:truth.ndim]
    blur = gaussian_filter(truth, sigma)
    noisy = np.random.default_rng(0).poisson(truth * 5) / 5  # 5 photons at white
    t, b, n = niqe(truth), niqe(blur), niqe(noisy)
    assert t < 6 and b > t + 3 and n > t + 5, (t, b, n)


def test_mono_and_rgb_views():
    """A mono frame is its value × 255, an RGB frame the MATLAB luma (16..235); white is the 99.5th percentile."""
    ramp = np.tile(np.linspace(0.0, 2.0, 128), (100, 1))
    y = to_display_luma(ramp)
    assert y.min() == 0 and y.max() == 255 and np.array_equal(y, np.round(y))
    rgb = to_display_luma(np.repeat(ramp[..., None], 3, axis=-1))
    assert rgb.min() == 16 and rgb.max() == 235
    assert to_display_luma(ramp[..., None]) == pytest.approx(y)  # (H, W, 1) is mono
    assert 0 < niqe(np.repeat(_camera()[..., None], 3, axis=-1)) < 6


@pytest.mark.parametrize("bad, words", [
    (np.ones((95, 200)), "at least 96×96"),
    (np.ones((200, 95, 3)), "at least 96×96"),
    (np.ones((128, 128, 2)), "mono (H, W) or RGB"),
    (np.zeros((128, 128)), "black"),
    (np.full((192, 192), 0.5), "two 96×96 blocks with texture"),
])
def test_bad_input_gives_one_sentence(bad, words):
    with pytest.raises(ParameterError, match=words.replace("(", r"\(").replace(")", r"\)")):
        niqe(bad)


def test_nan_is_refused():
    x = _camera()
    x[10, 10] = np.nan
    with pytest.raises(ParameterError, match="NaN"):
        niqe(x)
    with pytest.raises(ParameterError, match="NaN"):
        niqe_gray(np.full((100, 100), np.inf))


def test_the_model_ships_with_the_package():
    """The pristine model and its notice are package data, found through the installed package."""
    import tomllib
    from importlib.resources import files
    from pathlib import Path

    data = files("spikeview.bench").joinpath("data")
    assert data.joinpath("niqe_pris_params.npz").is_file()
    notice = data.joinpath("NIQE_NOTICE.txt").read_text(encoding="utf-8")
    assert "Copyright (c) 2011 The University of Texas at Austin" in notice and "LIVE" in notice and "CPS" in notice
    mu, cov, win = model()
    assert mu.shape == (36,) and cov.shape == (36, 36) and win.shape == (7, 7)
    assert mu.dtype == cov.dtype == np.float64 and np.allclose(cov, cov.T) and win.sum() == pytest.approx(1.0)
    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text(encoding="utf-8"))
    shipped = pyproject["tool"]["setuptools"]["package-data"]["spikeview"]
    assert {"bench/data/niqe_pris_params.npz", "bench/data/NIQE_NOTICE.txt"} <= set(shipped)


def test_the_bench_report_has_a_niqe_column_and_truth_rows():
    from spikeview.bench.lowlight import TRUTH, no_reference, report

    assert np.isnan(no_reference(np.ones((64, 64))))  # too small: "—", not an error in the middle of a bench
    rows = [{"capture": "camera none", "tick": 200, "method": TRUTH, "niqe": 3.57},
            {"capture": "camera none", "tick": 200, "method": "tfp", "psnr": 12.0, "detail": 0.1, "patchiness": 1.2,
             "noise": 30.0, "niqe": 15.2}]
    text = report(rows, "T")
    assert "| NIQE (lower is better) |" in text
    assert "| camera none (tick 200) | truth | — | — | — | — | — | — | 3.57 |" in text
    # a gray frame has no ΔE00 or white balance: "—"; a colour frame shows both
    assert "| camera none (tick 200) | tfp | 12.00 | — | — | 0.100 | 1.20 | 30.0 | 15.20 |" in text
    rows.append({"capture": "camera RGGB", "tick": 200, "method": "tfp", "psnr": 11.0, "delta_e00": 9.5, "wb_angle": 3.25,
                 "detail": 0.1, "patchiness": 1.2, "noise": 30.0, "niqe": 15.2})
    assert "| camera RGGB (tick 200) | tfp | 11.00 | 9.5 | 3.2° | 0.100 | 1.20 | 30.0 | 15.20 |" in report(rows, "T")
