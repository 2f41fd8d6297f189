"""spikeview.classical.display: fixed-level LUT display mapping."""

import numpy as np
import pytest

from spikeview.classical import to_display, transfer
from spikeview.classical.display import encode8
from spikeview.errors import ParameterError


def test_hand_values():
    x = np.array([0.0, 0.18, 0.5, 1.0], dtype=np.float32)
    # linear: floor(255 * v + 0.5): 0, 45.9 -> 46, 127.5 -> 128, 255
    assert to_display(x, gamma=1.0).tolist() == [0, 46, 128, 255]
    # sRGB encoding of 18 % grey is 0.4614 -> 117.7 -> 118; of 0.5 is 0.7354 -> 187.5 -> 188
    assert to_display(x, gamma="srgb").tolist() == [0, 118, 188, 255]
    # 0.5 ** (1 / 2.2) = 0.7297 -> 186.1 -> 186
    assert to_display(x[2:3], gamma=1 / 2.2).tolist() == [186]


def test_levels_clip_and_nan():
    x = np.array([-1.0, 0.2, 0.4, 0.6, 3.0, np.nan], dtype=np.float32)
    # black 0.2, white 0.6: 0.4 is half way (128 linear), outside values clip, NaN shows black
    assert to_display(x, black=0.2, white=0.6, gamma=1.0).tolist() == [0, 0, 128, 255, 255, 0]


@pytest.mark.parametrize("gamma", ["srgb", 1 / 2.2, 1.0, 2.0])
@pytest.mark.parametrize("shape", [(16, 16), (8, 9, 3)])
def test_within_one_code_of_exact_mapping(gamma, shape):
    rng = np.random.default_rng(0)
    img = (rng.random(shape, dtype=np.float32) * 1.2 - 0.1).astype(np.float32)
    img.flat[:4] = [0.0, 1e-6, 1.0, 0.999]  # near the ends, where curves are steepest
    out = to_display(img, black=0.0, white=1.0, gamma=gamma)
    assert out.shape == shape and out.dtype == np.uint8
    exact = encode8(transfer(img, 0.0, 1.0, gamma)).astype(int)
    assert np.abs(out.astype(int) - exact).max() <= 1
    if gamma == 1.0:  # linear: the table step (1/65535) is far below a code (1/255)
        assert np.mean(out == exact) > 0.99


def test_levels_are_fixed_not_per_frame():
    dark = np.full((4, 4), 0.1, dtype=np.float32)
    assert (to_display(dark, gamma=1.0) == 26).all()  # floor(25.5 + 0.5): no stretch to white


@pytest.mark.parametrize("kwargs", [{"black": 1.0, "white": 1.0}, {"gamma": "log"}, {"gamma": -1.0}, {"white": np.nan}])
def test_bad_settings(kwargs):
    with pytest.raises(ParameterError):
        to_display(np.zeros((2, 2)), **kwargs)
