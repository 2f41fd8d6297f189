"""spikeview.classical.reconstruct: config, frame pipeline, sequence alpha, preview fast path."""

import numpy as np
import pytest

import spikeview.classical.reconstruct as rec
from spikeview.classical import (ClassicalConfig, apply_colour_cast_mosaic, estimate_alpha, preview_rgb, reconstruct_frame,
                                 reconstruct_frames, to_display)
from spikeview.classical.colour_cast import sequence_alpha
from spikeview.classical.demosaic import demosaic
from spikeview.classical.tfi import tfi
from spikeview.classical.tfp import tfp
from spikeview.errors import ParameterError
from spikeview.io import ArraySource

PATTERNS = ["RGGB", "BGGR", "GRBG", "GBRG"]


def _source(cfa, shape=(60, 10, 9), seed=0):
    rng = np.random.default_rng(seed)
    rates = rng.uniform(0.05, 0.6, size=shape[1:])  # a fixed "scene" of per-photosite rates
    return ArraySource((rng.random(shape) < rates).astype(np.uint8), cfa=cfa)


def test_config_round_trip(tmp_path):
    cfg = ClassicalConfig(method="tfi", window=41, tfi_half_window=16, demosaic="malvar2004", colour_cast=False,
                          eta=3.0, alpha=[1.5, 1.0, 2.5], clip=False)
    path = cfg.save(tmp_path / "classical.toml")
    assert ClassicalConfig.load(path) == cfg
    assert ClassicalConfig.load(ClassicalConfig().save(tmp_path / "d.toml")) == ClassicalConfig()


@pytest.mark.parametrize(
    "data",
    [{"method": "tfx"}, {"window": 0}, {"demosaic": "nearest"}, {"eta": -1.0}, {"alpha": [1.0, 2.0]},
     {"alpha": [1.0, 0.0, 1.0]}, {"window": True}],
)
def test_bad_config(data):
    with pytest.raises(ParameterError):
        ClassicalConfig.from_dict(data)


def test_mono_frame_is_tfp_or_tfi():
    src = _source(None)
    np.testing.assert_array_equal(reconstruct_frame(src, 30, ClassicalConfig(window=12)), tfp(src, 30, 12))
    cfg = ClassicalConfig(method="tfi", tfi_half_window=5)
    np.testing.assert_array_equal(reconstruct_frame(src, 30, cfg), tfi(src, 30, 5))


@pytest.mark.parametrize("cfa", PATTERNS)
@pytest.mark.parametrize("method", ["bilinear", "malvar2004"])
def test_colour_frame_pipeline(cfa, method):
    src = _source(cfa)
    alpha = np.array([2.0, 1.0, 3.0])
    cfg = ClassicalConfig(window=16, demosaic=method, eta=2.0, clip=False)
    out = reconstruct_frame(src, 30, cfg, alpha=alpha)
    expected = demosaic(apply_colour_cast_mosaic(tfp(src, 30, 16), cfa, alpha, 2.0), cfa, method)
    np.testing.assert_array_equal(out, expected)
    clipped = reconstruct_frame(src, 30, cfg.replace(clip=True), alpha=alpha)
    np.testing.assert_array_equal(clipped, np.clip(expected, 0, 1))
    assert out.max() > 1  # the gains push some values above 1: clip matters


def test_colour_cast_off_and_config_alpha():
    src = _source("BGGR")
    plain = reconstruct_frame(src, 30, ClassicalConfig(colour_cast=False, clip=False))
    np.testing.assert_array_equal(plain, demosaic(tfp(src, 30, 10), "BGGR"))
    fixed = reconstruct_frame(src, 30, ClassicalConfig(alpha=[2.0, 1.0, 3.0], eta=1.0, clip=False))
    np.testing.assert_allclose(fixed, plain * np.array([2.0, 1.0, 3.0], dtype=np.float32), rtol=1e-6)


def test_sequence_uses_one_alpha(monkeypatch):
    src = _source("GRBG")
    calls = []

    def counting_estimate(*args, **kwargs):
        calls.append(args)
        return sequence_alpha(*args, **kwargs)

    monkeypatch.setattr(rec, "sequence_alpha", counting_estimate)
    cfg = ClassicalConfig(window=8, white_balance="gray-world")  # the gray-world estimate below
    frames = list(reconstruct_frames(src, [5, 20, 40, 59], cfg))
    assert len(calls) == 1 and len(frames) == 4
    alpha = estimate_alpha(src, window=10)  # window 10 x 64 windows cover all 60 ticks: exact
    for c, f in zip([5, 20, 40, 59], frames):
        np.testing.assert_array_equal(f, reconstruct_frame(src, c, cfg, alpha=alpha))


@pytest.mark.parametrize("cfa", PATTERNS)
@pytest.mark.parametrize("shape", [(40, 10, 9), (40, 7, 12), (40, 2, 2)])
def test_preview_matches_reference_pipeline(cfa, shape):
    src = _source(cfa, shape, seed=3)
    alpha = estimate_alpha(src, window=10)
    fast = preview_rgb(src, 20, 16, alpha=alpha, eta=2.0, gamma="srgb")
    ref = to_display(reconstruct_frame(src, 20, ClassicalConfig(window=16, clip=False), alpha=alpha), gamma="srgb")
    assert fast.shape == shape[1:] + (3,) and fast.dtype == np.uint8
    # exact curve (preview) vs float32 + 65,536-entry table (to_display): at most one code apart
    assert np.abs(fast.astype(int) - ref).max() <= 1


@pytest.mark.parametrize("method", ["malvar2004", "menon2007"])
def test_preview_other_methods_use_the_float_path(method):
    src = _source("RGGB", (30, 12, 12))
    alpha = [1.2, 0.9, 2.0]
    fast = preview_rgb(src, 10, 10, alpha=alpha, demosaic_method=method, gamma=1 / 2.2)
    cfg = ClassicalConfig(window=10, demosaic=method)
    np.testing.assert_array_equal(fast, to_display(reconstruct_frame(src, 10, cfg, alpha=alpha), gamma=1 / 2.2))


def test_preview_mono_and_no_cast():
    src = _source(None, (30, 6, 5))
    out = preview_rgb(src, 29, 10, gamma=1.0)  # window shifted to ticks [20, 30)
    # exact rates count / 10 (float64, as the preview's table), floor(255 v + 0.5)
    expected = np.floor(src.count(20, 30) / 10 * 255 + 0.5).astype(np.uint8)
    np.testing.assert_array_equal(out, np.repeat(expected[..., None], 3, -1))
    col = _source("RGGB", (30, 6, 6))
    raw = preview_rgb(col, 10, 10, colour_cast=False, gamma=1.0)
    ref = to_display(demosaic(tfp(col, 10, 10), "RGGB"), gamma=1.0)
    assert np.abs(raw.astype(int) - ref).max() <= 1  # float32 rounding at half-code ties


def test_preview_bad_window():
    with pytest.raises(ParameterError, match="window"):
        preview_rgb(_source("RGGB"), 10, 100, alpha=[1, 1, 1])
