"""Exposure that keeps the scene: linear outputs are not clipped, the white point clips at most 0.1 %.

A medium-dark scene with bright highlights (the case that clipped 9.7 % of an EXR frame before):
with ``classical.clip`` off the TFP frame written to EXR keeps values above 1, and mapping it by the
sequence's white point (:func:`estimate_white`, computed once by ``prepare_sequence``) clips at most
0.1 % of its values. (Making clip-off and the white-point mapping of bounded outputs the default is
the pipeline's/export's part, see the guided section of BENCHMARKS.md.)
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio

from spikeview.classical.colour_cast import estimate_white
from spikeview.io.source import ArraySource
from spikeview.pipeline import WriteOptions, prepare_sequence, reconstruct_windows, write_sequence
from spikeview.recipe import Recipe
from test_guided_helpers import spikes_from_rates


def _highlight_scene(h=32, w=32, ticks=200):
    rng = np.random.default_rng(7)
    rates = rng.uniform(0.05, 0.2, (h, w))  # medium-dark
    rates[4:8, 4:12] = 0.95  # a lamp
    rates[20:22, 18:30] = 0.9  # a specular streak
    return ArraySource(spikes_from_rates(rates, ticks, seed=3), cfa="RGGB")


def test_unclipped_tfp_exr_is_scene_linear_and_the_white_point_clips_at_most_a_thousandth(tmp_path):
    src = _highlight_scene()
    recipe = Recipe().with_values({"classical.clip": False})
    state = prepare_sequence(src, recipe)
    assert state.white is not None and state.white > 1.0  # the highlights lie above the gray-world range
    centers = list(range(5, 195, 10))
    frames = np.stack(list(reconstruct_windows(src, centers, recipe, state)))
    assert frames.max() > 1.0  # not clipped
    # values beyond the white point are clipped when bounded: at most 0.1 % by more than half a
    # quantisation step (the white point may split the top level, whose values then clip by up to 2 %)
    assert (frames > state.white * 1.02).mean() <= 0.001
    brightest = int(np.argmax(frames.reshape(len(centers), -1).max(axis=1)))
    out = write_sequence(src, recipe, centers[brightest:brightest + 1], tmp_path / "f.exr", WriteOptions(state=state))
    img = oiio.ImageBuf(str(out[0])).get_pixels(oiio.FLOAT)
    # EXR is scene-linear relative to the white point: the frame divided by it, highlights above 1 kept
    np.testing.assert_allclose(img, frames[brightest] / state.white, rtol=2e-3, atol=1e-4)
    assert img.max() >= 1.0 and (img == 1.0).mean() < 0.01
    # with a lower white point (--white) the highlights lie above 1 in the EXR and nothing is lost
    darker = recipe.with_values({"export.white": state.white / 2})
    out = write_sequence(src, darker, centers[brightest:brightest + 1], tmp_path / "g.exr", WriteOptions(state=state))
    img2 = oiio.ImageBuf(str(out[0])).get_pixels(oiio.FLOAT)
    assert img2.max() > 1.5
    np.testing.assert_allclose(img2, 2 * img, rtol=2e-3, atol=1e-4)
    npy = write_sequence(src, recipe, centers, tmp_path / "f.npy", WriteOptions(state=state))
    # bounded: the white point maps to 1, the (at most 0.1 %) values above it clip
    np.testing.assert_array_equal(np.load(npy[0]), np.clip(frames * np.float32(1.0 / state.white), 0.0, 1.0))


def test_white_point_is_the_same_for_every_frame_of_the_sequence():
    src = _highlight_scene()
    a = prepare_sequence(src, Recipe())
    assert estimate_white(src, a.alpha, window=10, eta=2.0) == a.white  # one value, computed once
    assert a.attrs()["white"] == a.white
