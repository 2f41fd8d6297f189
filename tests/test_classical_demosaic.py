"""spikeview.classical.demosaic against the colour-demosaicing reference, all four CFA phases.

colour-demosaicing names patterns by the explicit top-left 2x2 in reading order, like spikeview
(its ``masks_CFA_Bayer`` puts pattern[0] at (0, 0), pattern[1] at (0, 1), ...), so the names are
passed through unchanged. Its bilinear and Malvar filters use scipy's default ``mode="reflect"``
(half-sample symmetric: the pixel outside the border copies the border pixel, a different colour),
while spikeview mirrors about the edge pixel (``mode="mirror"``, same colour). So the full images are
compared against the reference run on the input mirror-padded by 2 pixels (an even pad keeps the
phase) and cropped back, and the plain reference is compared on the interior only.
"""

import sys
from unittest import mock
import warnings

import numpy as np
import pytest
from skimage import data

from spikeview.classical.demosaic import demosaic
from spikeview.errors import ParameterError

_MODULES_BEFORE = set(sys.modules)
with warnings.catch_warnings():
    # colour_demosaicing imports from the deprecated scipy.ndimage.filters namespace
    warnings.simplefilter("ignore")
    import colour_demosaicing as cd
# Without matplotlib installed (it is optional), colour-science puts MagicMock objects in sys.modules
# under "matplotlib", "matplotlib.pyplot", …; every later importlib.util.find_spec("matplotlib") in this
# process then raises ValueError (diffusers does that on import: the --prior sd test failed whenever this
# module was collected first, i.e. in every full run of a fresh install). Take the stubs out again.
for _name in set(sys.modules) - _MODULES_BEFORE:
    if isinstance(sys.modules[_name], mock.MagicMock):
        del sys.modules[_name]

PATTERNS = ["RGGB", "BGGR", "GRBG", "GBRG"]
REFERENCE = {
    "bilinear": cd.demosaicing_CFA_Bayer_bilinear,
    "malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004,
}
#: kernel radius: the rows/columns at the border that depend on the border mode
RADIUS = {"bilinear": 1, "malvar2004": 2}


@pytest.fixture(scope="module")
def natural():
    """A 64x63 crop (odd width on purpose) of skimage's astronaut, float64 in [0, 1]."""
    return data.astronaut()[100:164, 200:263].astype(np.float64) / 255.0


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("method", list(REFERENCE))
def test_matches_reference(natural, pattern, method):
    mosaic = cd.mosaicing_CFA_Bayer(natural, pattern)
    ours = demosaic(mosaic.astype(np.float32), pattern, method)
    assert ours.dtype == np.float32 and ours.shape == natural.shape
    ref = REFERENCE[method]
    padded = ref(np.pad(mosaic, 2, mode="reflect"), pattern)[2:-2, 2:-2]
    # float32 arithmetic against float64: inputs are in [0, 1], kernel weights sum to <= 2.5
    np.testing.assert_allclose(ours, padded, rtol=0, atol=1e-6)
    r = RADIUS[method]
    plain = ref(mosaic, pattern)
    np.testing.assert_allclose(ours[r:-r, r:-r], plain[r:-r, r:-r], rtol=0, atol=1e-6)


@pytest.mark.parametrize("pattern", PATTERNS)
def test_menon_matches_reference_in_float64(natural, pattern):
    mosaic = cd.mosaicing_CFA_Bayer(natural, pattern)
    ours = demosaic(mosaic, pattern, "menon2007")  # float64 in: computed in float64 like the reference
    assert ours.dtype == np.float32
    ref = cd.demosaicing_CFA_Bayer_Menon2007(mosaic, pattern)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-6)


@pytest.mark.parametrize("pattern", PATTERNS)
def test_menon_float32_differs_only_at_near_ties(natural, pattern):
    # In float32 a few near-tied directional decisions flip; measured 1.2-3.3 % of the pixels of
    # this crop for the four phases (the bound below leaves room, the median must stay exact).
    mosaic = cd.mosaicing_CFA_Bayer(natural, pattern)
    ours = demosaic(mosaic.astype(np.float32), pattern, "menon2007")
    err = np.abs(ours - cd.demosaicing_CFA_Bayer_Menon2007(mosaic, pattern)).max(axis=-1)
    assert np.median(err) < 1e-6
    assert np.mean(err > 1e-5) < 0.05


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("method", ["bilinear", "malvar2004", "menon2007"])
def test_constant_image_stays_constant(pattern, method):
    # every kernel's weights sum to 1 per channel, so a flat grey mosaic demosaics to that grey
    out = demosaic(np.full((9, 8), 0.3, dtype=np.float32), pattern, method)
    np.testing.assert_allclose(out, 0.3, atol=1e-6)


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("method", ["bilinear", "malvar2004"])
def test_photosites_keep_their_own_value(pattern, method):
    rng = np.random.default_rng(4)
    mosaic = rng.random((10, 11), dtype=np.float32)
    out = demosaic(mosaic, pattern, method)
    from spikeview.cfa import channel_map

    cmap = channel_map(pattern, 10, 11)
    np.testing.assert_array_equal(np.take_along_axis(out, cmap[..., None].astype(np.intp), -1)[..., 0], mosaic)


def test_bilinear_stays_in_input_range():
    rng = np.random.default_rng(5)
    out = demosaic(rng.random((16, 16), dtype=np.float32), "GRBG", "bilinear")
    assert out.min() >= 0 and out.max() <= 1


def test_smallest_bilinear_image():
    # 2x2 RGGB quad: mirroring copies the opposite photosite, so every pixel sees the quad's values
    out = demosaic(np.array([[0.1, 0.2], [0.3, 0.4]], dtype=np.float32), "RGGB")
    np.testing.assert_allclose(out[0, 0], [0.1, 0.25, 0.4], atol=1e-7)
    np.testing.assert_allclose(out[1, 1], [0.1, 0.25, 0.4], atol=1e-7)


@pytest.mark.parametrize(
    "image, cfa, method, word",
    [
        (np.zeros((4, 4)), None, "bilinear", "CFA"),
        (np.zeros((4, 4)), "XYZW", "bilinear", "CFA"),
        (np.zeros((4, 4, 3)), "RGGB", "bilinear", "shape"),
        (np.zeros((2, 8)), "RGGB", "malvar2004", "too small"),
        (np.zeros((4, 4)), "RGGB", "nearest", "method"),
    ],
)
def test_bad_input(image, cfa, method, word):
    with pytest.raises(ParameterError, match=word):
        demosaic(image, cfa, method)
