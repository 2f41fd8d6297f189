"""spikeview.classical.colour_cast: gray-world alpha, zero-mean fallback, site statistics."""

import numpy as np
import pytest

from spikeview.cfa import CHANNEL_INDEX, site_masks
from spikeview.classical import (ColourCastWarning, alpha_from_means, alpha_from_sfr, alpha_with_note, apply_colour_cast,
                                 apply_colour_cast_mosaic, channel_means, estimate_alpha, sequence_channel_means, site_rates)
from spikeview.classical.demosaic import demosaic
from spikeview.classical.colour_cast import sample_starts
from spikeview.errors import ParameterError
from spikeview.io import ArraySource

PATTERNS = ["RGGB", "BGGR", "GRBG", "GBRG"]


def _periodic_stream(cfa, n_frames, periods, h=8, w=8, cls=ArraySource):
    """Channel c fires every periods[c] ticks at each of its photosites (phases vary by pixel)."""
    spikes = np.zeros((n_frames, h, w), dtype=np.uint8)
    quad = [[cfa[0], cfa[1]], [cfa[2], cfa[3]]]
    for y in range(h):
        for x in range(w):
            p = periods[CHANNEL_INDEX[quad[y % 2][x % 2]]]
            if p:
                spikes[(y * w + x) % p :: p, y, x] = 1
    return cls(spikes, cfa=cfa)


class CountingSource(ArraySource):
    """Records the tick ranges counted."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls = []

    def count(self, a, b):
        self.calls.append((a, b))
        return super().count(a, b)


@pytest.mark.parametrize("cfa", PATTERNS)
def test_estimate_alpha_exact_rates(cfa):
    # R fires every 2 ticks, G every 4, B every 8: any 8-tick-aligned window holds rates 1/2, 1/4, 1/8
    src = _periodic_stream(cfa, 80, (2, 4, 8))
    np.testing.assert_allclose(estimate_alpha(src, window=8), [2.0, 4.0, 8.0], rtol=1e-6)


def test_estimate_alpha_samples_long_streams_evenly():
    src = _periodic_stream("RGGB", 800, (2, 4, 8), cls=CountingSource)
    alpha = estimate_alpha(src, window=8, max_windows=5)
    np.testing.assert_allclose(alpha, [2.0, 4.0, 8.0], rtol=1e-6)
    # 5 windows from the first to the last 8 ticks: starts linspace(0, 792, 5) = 0, 198, 396, 594, 792
    assert src.calls == [(0, 8), (198, 206), (396, 404), (594, 602), (792, 800)]


def test_estimate_alpha_averages_over_the_sequence():
    # first half of the stream dark, second half bright: the sequence mean is half the bright rate
    spikes = np.zeros((100, 4, 4), dtype=np.uint8)
    spikes[50:] = 1
    alpha = estimate_alpha(ArraySource(spikes, cfa="RGGB"), window=10)  # 10 windows cover it all
    np.testing.assert_allclose(alpha, [2.0, 2.0, 2.0], rtol=1e-6)


def test_sample_starts():
    assert sample_starts(30, 10, 64) == [0, 10, 20]  # whole stream in 3 windows
    assert sample_starts(25, 10, 64) == [0, 10, 20]  # last window is cut at the end
    assert sample_starts(1000, 10, 3) == [0, 495, 990]
    with pytest.raises(ParameterError):
        sample_starts(5, 10, 3)


def test_alpha_from_sfr_single_array_and_stack():
    y = np.zeros((6, 6), dtype=np.float32)
    y[0::2, 0::2] = 0.5  # R of RGGB
    y[0::2, 1::2] = 0.2  # Gr
    y[1::2, 0::2] = 0.3  # Gb -> G mean 0.25
    y[1::2, 1::2] = 0.1  # B
    np.testing.assert_allclose(alpha_from_sfr(y, "RGGB"), [2.0, 4.0, 10.0], rtol=1e-6)
    np.testing.assert_allclose(alpha_from_sfr(np.stack([y, y]), "RGGB"), [2.0, 4.0, 10.0], rtol=1e-6)
    np.testing.assert_allclose(alpha_from_sfr(y, None), [1 / y.mean()], rtol=1e-6)


def test_zero_channel_warns_and_falls_back_to_other_channels():
    src = _periodic_stream("BGGR", 40, (2, 0, 8))  # no green spike at all
    with pytest.warns(ColourCastWarning, match="channel G"):
        alpha = estimate_alpha(src, window=8)
    # R mean 1/2, B mean 1/8: G gets 1 / mean(1/2, 1/8) = 1 / 0.3125 = 3.2
    np.testing.assert_allclose(alpha, [2.0, 3.2, 8.0], rtol=1e-6)


def test_all_dark_warns_and_uses_one():
    with pytest.warns(ColourCastWarning, match="alpha = 1"):
        alpha = estimate_alpha(ArraySource(np.zeros((20, 4, 4), dtype=np.uint8), cfa="RGGB"))
    np.testing.assert_array_equal(alpha, [1.0, 1.0, 1.0])
    with pytest.warns(ColourCastWarning):
        assert alpha_from_means([0.0]).tolist() == [1.0]
    with pytest.warns(ColourCastWarning):
        assert np.isfinite(alpha_from_means([np.nan, 0.5, 0.25])).all()


def test_apply_colour_cast_inverts_forward_model():
    rng = np.random.default_rng(0)
    x = rng.random((5, 6, 3), dtype=np.float32)
    alpha, eta = np.array([2.0, 4.0, 10.0]), 2.0
    y = x * (eta / alpha)  # forward model of METHOD.md: Y_c = (eta / alpha_c) X_c
    np.testing.assert_allclose(apply_colour_cast(y, alpha, eta), x, rtol=1e-6)
    big = apply_colour_cast(np.full((2, 2, 3), 0.5, np.float32), alpha, 1.0, clip=True)
    np.testing.assert_array_equal(big, 1.0)  # 0.5 * 2, 0.5 * 4, 0.5 * 10 all clipped to 1


@pytest.mark.parametrize("cfa", PATTERNS)
def test_mosaic_correction_commutes_with_bilinear(cfa):
    rng = np.random.default_rng(1)
    y = rng.random((12, 10), dtype=np.float32)
    alpha = [1.5, 0.8, 3.0]
    before = demosaic(apply_colour_cast_mosaic(y, cfa, alpha, 2.0), cfa, "bilinear")
    after = apply_colour_cast(demosaic(y, cfa, "bilinear"), alpha, 2.0)
    np.testing.assert_allclose(before, after, rtol=1e-6)


def test_gray_world_maps_channel_means_to_one_over_eta():
    rng = np.random.default_rng(2)
    y = rng.random((16, 16), dtype=np.float32) * np.where(np.indices((16, 16)).sum(0) % 2, 0.3, 0.9)
    alpha = alpha_from_sfr(y, "GRBG")
    corrected = apply_colour_cast_mosaic(y, "GRBG", alpha, 2.0)
    np.testing.assert_allclose(channel_means(corrected, "GRBG"), [0.5, 0.5, 0.5], rtol=1e-5)


@pytest.mark.parametrize("cfa", PATTERNS)
def test_site_rates_names_match_cfa_site_masks(cfa):
    # site_masks (spikeview.cfa) is an independent definition of R/Gr/Gb/B positions
    masks = site_masks(cfa, 6, 7)
    frame = np.zeros((6, 7), dtype=np.float32)
    values = {"R": 0.1, "Gr": 0.2, "Gb": 0.3, "B": 0.4}
    for name, v in values.items():
        frame[masks[name]] = v
    rates = site_rates(frame, cfa)
    assert list(rates) == ["R", "Gr", "Gb", "B"]
    for name, v in values.items():
        assert rates[name] == pytest.approx(v, rel=1e-6)


def test_site_rates_mono_and_stack():
    stack = np.stack([np.full((4, 4), 0.2), np.full((4, 4), 0.4)])
    assert site_rates(stack, None) == {"Y": pytest.approx(0.3)}
    with pytest.raises(ParameterError):
        site_rates(np.zeros(5), "RGGB")


@pytest.mark.parametrize("alpha, eta", [([1.0, 0.0, 1.0], 2.0), ([1.0, 2.0], 2.0), ([1.0, 1.0, 1.0], 0.0)])
def test_bad_alpha_or_eta(alpha, eta):
    with pytest.raises(ParameterError):
        apply_colour_cast(np.zeros((2, 2, 3)), alpha, eta)


def test_alpha_with_note_returns_the_sentence_without_warning():
    alpha, note = alpha_with_note([0.5, 0.0, 0.125])  # raises if it warned (warnings are errors)
    np.testing.assert_allclose(alpha, [2.0, 3.2, 8.0], rtol=1e-6)  # 1 / mean(0.5, 0.125) = 3.2
    assert "channel G" in note
    assert alpha_with_note([0.5, 0.25, 0.125])[1] is None


def test_sequence_channel_means():
    src = _periodic_stream("GBRG", 64, (2, 4, 8))
    np.testing.assert_allclose(sequence_channel_means(src, window=8), [0.5, 0.25, 0.125], rtol=1e-12)


# --- white point (exposure) ----------------------------------------------------------------------
def test_estimate_white_exact_on_periodic_stream():
    from spikeview.classical.colour_cast import estimate_white

    # R every 2 ticks, G every 4, B every 5: a 20-tick window counts 10, 5, 4 spikes at every site
    src = _periodic_stream("RGGB", 200, (2, 4, 5))
    alpha = np.array([2.0, 4.0, 5.0])  # gray-world of those rates: every corrected value is 1
    # every count stands for the rates within half a quantisation step (B: 5/20 = 0.25 corrected), so
    # the white point lies within half the largest step above the common value
    assert 1.0 < estimate_white(src, alpha, window=20, eta=1.0) <= 1.125 + 1e-9
    assert 0.5 < estimate_white(src, alpha, window=20, eta=2.0) <= 0.5625 + 1e-9
    # without gains the brightest channel (R at 0.5 spikes per tick, step 1/20) sets the white point
    assert 0.5 < estimate_white(src, None, window=20, eta=1.0) <= 0.525 + 1e-9


def test_estimate_white_clips_at_most_the_percentile():
    from spikeview.classical.colour_cast import estimate_white, sample_starts
    from spikeview.classical.tfp import window_counts

    rng = np.random.default_rng(4)
    rates = rng.uniform(0.02, 0.7, (32, 32))
    spikes = (rng.uniform(size=(400, 32, 32)) < rates).astype(np.uint8)
    src = ArraySource(spikes, cfa="GRBG")
    alpha = estimate_alpha(src, window=10)
    white = estimate_white(src, alpha, window=10, eta=2.0, percentile=99.0)
    gains = np.array([[alpha[1], alpha[0]], [alpha[2], alpha[1]]])  # GRBG
    vals = np.concatenate([(window_counts(src, s, s + 10) / 10 * np.tile(gains, (16, 16)) / 2.0).ravel()
                           for s in sample_starts(400, 10, 64)])
    assert (vals >= white - 1e-9).mean() <= 0.01  # at most 1 % AT or above it (shown at full scale)
    step = float(np.max(alpha)) / 10 / 2.0  # the largest quantisation step of the corrected values
    assert (vals >= white - step - 1e-9).mean() > 0.01  # and within one step of where the 1 % begin


def test_estimate_white_of_quantised_monochrome_puts_at_most_the_tail_at_full_scale():
    """TFP values are multiples of 1/Δτ: the plain 99.9th percentile fell on a level holding 3 % of a
    Spike-Zoo clip's photosites, all shown at full scale; the white point splits that level instead."""
    from spikeview.classical.colour_cast import estimate_white
    from test_guided_helpers import spikes_from_rates

    rng = np.random.default_rng(5)
    # 2 % of the photosites fire at 0.5 per tick, one (0.05 %) at 0.6, the rest at 0.1–0.3 (a 10-tick
    # window: levels 0.1 apart; integrate-and-fire counts exactly 5 and 6 spikes at 0.5 and 0.6)
    rates = rng.uniform(0.1, 0.3, (40, 50))
    idx = rng.choice(rates.size, 41, replace=False)
    rates.flat[idx[:40]] = 0.5
    rates.flat[idx[40]] = 0.6
    spikes = spikes_from_rates(rates, 400, seed=2)
    src = ArraySource(spikes, cfa=None)
    white = estimate_white(src, None, window=10, eta=2.0)
    vals = np.concatenate([spikes[s:s + 10].mean(axis=0).ravel() for s in range(0, 400, 10)])
    assert (vals >= white - 1e-9).mean() <= 0.001  # the 2 % at 0.5 are below it, not at full scale
    assert 0.5 < white <= 0.55  # Y units (no η for monochrome frames): within the 0.5 level's half step


def test_estimate_white_of_a_dark_stream_is_the_gray_world_mean_and_bad_percentile_is_refused():
    from spikeview.classical.colour_cast import estimate_white

    src = ArraySource(np.zeros((30, 8, 8), dtype=np.uint8), cfa=None)
    assert estimate_white(src, None, window=10, eta=2.0) == 1.0  # monochrome frames are Y: no η
    bayer = ArraySource(np.zeros((30, 8, 8), dtype=np.uint8), cfa="RGGB")
    assert estimate_white(bayer, np.ones(3), window=10, eta=2.0) == 0.5  # Y·α/η: the gray-world mean 1/η
    with pytest.raises(ParameterError, match="percentile"):
        estimate_white(src, None, percentile=0.0)


def test_exposed_eta_maps_the_white_point_to_the_level():
    from spikeview.guided.observation import exposed_eta

    eta = exposed_eta(2.0, white=1.6, level=0.8)
    assert 1.6 * 2.0 / eta == pytest.approx(0.8)  # the linear value 1.6 (frame Y·α/2) lands at 0.8
    with pytest.raises(ParameterError, match="white"):
        exposed_eta(2.0, 0.0)


def test_estimate_white_leaves_out_a_partial_last_window():
    from spikeview.classical.colour_cast import estimate_white

    src = _periodic_stream("RGGB", 210, (2, 4, 5))  # 10 full 20-tick windows and a 10-tick rest
    full = _periodic_stream("RGGB", 200, (2, 4, 5))
    alpha = np.array([2.0, 4.0, 5.0])
    assert estimate_white(src, alpha, window=20, eta=1.0) == estimate_white(full, alpha, window=20, eta=1.0)
