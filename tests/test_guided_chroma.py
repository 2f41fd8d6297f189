"""The guided frame's chroma smoothing (``guided.chroma``, :mod:`spikeview.guided.chroma`): colour noise removed, luma
and colour edges kept, gray frames untouched; through the pipeline for Bayer and monochrome alike, with the plan's
row and the knob's reason."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.guided.chroma import _RGB, _YCC, smooth_chroma
from spikeview.transfer import srgb_encode


def _luma_chroma(x: np.ndarray, scale: float) -> np.ndarray:
    return srgb_encode(np.clip(x / scale, 0, 1)) @ _YCC.T


def test_colour_noise_on_a_gray_scene_falls_and_the_luma_stays():
    rng = np.random.default_rng(0)
    base = np.repeat(np.linspace(0.1, 0.8, 96, dtype=np.float32)[None, :, None], 96, axis=0).repeat(3, axis=2)
    noisy = np.clip(base * (1 + 0.08 * rng.standard_normal(base.shape).astype(np.float32)), 0, 1)
    out = smooth_chroma(noisy, 2.0)
    before, after = _luma_chroma(noisy, noisy.max()), _luma_chroma(out, noisy.max())
    # the chroma's noise (the truth's chroma is 0) falls by more than half
    assert np.abs(after[..., 1:]).mean() < 0.5 * np.abs(before[..., 1:]).mean()
    # the luma is kept: only the sRGB round trip's clipping could move it
    assert np.abs(after[..., 0] - before[..., 0]).max() < 2e-3
    assert out.dtype == np.float32 and out.shape == noisy.shape


def test_colour_does_not_leak_across_a_luma_edge():
    # a dark red half beside a bright green-blue half: the colour of each side stays its own up to the edge
    x = np.zeros((64, 64, 3), np.float32)
    x[:, :32] = (0.2, 0.02, 0.02)
    x[:, 32:] = (0.3, 0.9, 0.8)
    rng = np.random.default_rng(1)
    x = np.clip(x + 0.005 * rng.standard_normal(x.shape).astype(np.float32), 0, 1)
    out = smooth_chroma(x, 2.0)
    for col in (30, 31, 32, 33):  # next to the edge
        assert np.abs(out[:, col].mean(axis=0) - x[:, col].mean(axis=0)).max() < 0.01, col


def test_a_gray_frame_and_sigma_zero_are_returned_as_they_are():
    rng = np.random.default_rng(2)
    g = rng.random((32, 32), dtype=np.float32)
    assert smooth_chroma(g, 2.0) is g
    c = rng.random((32, 32, 3), dtype=np.float32)
    assert smooth_chroma(c, 0.0) is c
    assert smooth_chroma(np.zeros((32, 32, 3), np.float32), 2.0).max() == 0
    tiny = rng.random((3, 3, 3), dtype=np.float32)  # smaller than the window
    assert smooth_chroma(tiny, 2.0) is tiny


def test_the_colour_transform_round_trips():
    assert np.allclose(_RGB @ _YCC, np.eye(3), atol=1e-5)


@pytest.mark.parametrize("cfa", ["RGGB", None])
def test_the_pipeline_smooths_colour_frames_only_and_the_plan_says_so(cfa):
    from spikeview.bench.data import make_capture
    from spikeview.pipeline import plan_window, prepare_sequence, reconstruct_windows, recipe_for_state
    from spikeview.recipe import Recipe

    cap = make_capture("astronaut", 64, n_ticks=40, seed=3, window=10, cfa=cfa)
    frames = {}
    for sigma in (0.0, 2.0):
        recipe = Recipe().with_values({"run.method": "guided", "guided.chroma": sigma, "guided.steps": 2})
        state = prepare_sequence(cap, recipe, warn=False)
        recipe = recipe_for_state(recipe, state)
        frames[sigma] = next(reconstruct_windows(cap, [20], recipe, state))
        wp = plan_window(cap, recipe, 20, state=state)
        plan, status = wp.plan, wp.knobs["guided.chroma"]
        if cfa is None:
            assert plan.chroma == 0 and "no colour" in plan.reasons["chroma"] and "no colour" in status
        else:
            assert status is None
            assert plan.chroma == sigma and ("off" in plan.reasons["chroma"]) == (sigma == 0)
        assert "chroma" in str(plan)
    if cfa is None:
        assert np.array_equal(frames[0.0], frames[2.0])
    else:
        assert not np.array_equal(frames[0.0], frames[2.0])
        # luma kept: the frames' luminance differs far less than their colour
        w = np.array([0.2126, 0.7152, 0.0722], np.float32)
        dl = np.abs(frames[0.0] @ w - frames[2.0] @ w).mean()
        dc = np.abs((frames[0.0] - (frames[0.0] @ w)[..., None]) - (frames[2.0] - (frames[2.0] @ w)[..., None])).mean()
        assert dl < dc


def test_a_negative_chroma_is_refused_in_one_sentence():
    from spikeview.errors import ParameterError
    from spikeview.guided.config import GuidedConfig

    with pytest.raises(ParameterError, match="chroma"):
        GuidedConfig(chroma=-1.0)


def test_each_channels_mean_is_kept():
    # a mostly black frame with colour noise (hubble-like): the sRGB curve would move the channel means
    rng = np.random.default_rng(4)
    x = np.clip(0.01 + 0.01 * rng.standard_normal((80, 80, 3)), 0, 1).astype(np.float32)
    x[30:40, 30:40] = (0.8, 0.6, 0.3)  # one bright, coloured object
    keep: dict = {}
    out = smooth_chroma(x, 2.0, keep=keep)
    np.testing.assert_allclose(out.reshape(-1, 3).mean(axis=0), x.reshape(-1, 3).mean(axis=0), rtol=1e-4)
    assert set(keep) == {"luma_range", "gains"}
    # handed back, the same settings give the same pixels
    assert np.array_equal(smooth_chroma(x, 2.0, keep=dict(keep)), out)


def test_the_srgb_curve_has_one_home_for_arrays_and_tensors():
    import torch

    from spikeview.transfer import srgb_decode, srgb_encode

    x = np.linspace(0, 1, 1001, dtype=np.float32)
    t = torch.from_numpy(x)
    assert isinstance(srgb_encode(t), torch.Tensor) and isinstance(srgb_encode(x), np.ndarray)
    np.testing.assert_allclose(srgb_encode(t).numpy(), srgb_encode(x), atol=1e-6)
    np.testing.assert_allclose(srgb_decode(t).numpy(), srgb_decode(x), atol=1e-6)
    np.testing.assert_allclose(srgb_decode(srgb_encode(t)).numpy(), x, atol=1e-5)
