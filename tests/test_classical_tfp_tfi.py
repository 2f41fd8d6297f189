"""spikeview.classical.tfp / tfi against hand cases and slow references."""

import numpy as np
import pytest

from spikeview.classical import tfi_array, tfp_array, window_counts, window_range
from spikeview.classical.tfi import tfi
from spikeview.classical.tfp import tfp
from spikeview.errors import ParameterError
from spikeview.io import ArraySource


def _random_spikes(seed, shape, p=0.3):
    rng = np.random.default_rng(seed)
    return (rng.random(shape) < p).astype(np.uint8)


# --- TFP ---------------------------------------------------------------------------------------
def test_tfp_is_count_over_window():
    spikes = np.zeros((20, 2, 3), dtype=np.uint8)
    spikes[::2, 0, 0] = 1  # every other tick: any 10-tick window holds 5 spikes -> 0.5
    spikes[::5, 0, 1] = 1  # every fifth tick: 2 spikes per 10 ticks -> 0.2
    spikes[:, 1, 2] = 1  # every tick -> 1.0
    out = tfp(ArraySource(spikes), center=10, window=10)
    assert out.dtype == np.float32 and out.shape == (2, 3)
    np.testing.assert_array_equal(out, np.array([[0.5, 0.2, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32))


def test_tfp_matches_numpy_on_random_stream_at_edges_and_inside():
    spikes = _random_spikes(0, (40, 8, 8))
    src = ArraySource(spikes)
    for center in (0, 3, 20, 39):
        a, b = window_range(center, 9, 40)
        expected = spikes[a:b].sum(axis=0) / 9.0
        np.testing.assert_allclose(tfp(src, center, 9), expected, rtol=0, atol=1e-7)
    # edge windows are shifted, not shortened: values stay multiples of 1/9
    out = tfp(src, 0, 9) * 9
    np.testing.assert_allclose(out, np.round(out), atol=1e-5)


def test_tfp_array_mean_over_time():
    spikes = _random_spikes(1, (7, 5, 6))
    np.testing.assert_allclose(tfp_array(spikes), spikes.mean(axis=0), atol=1e-7)
    with pytest.raises(ParameterError):
        tfp_array(spikes[0])


def test_window_counts_beyond_uint16():
    # 70,000 ticks overflow SpikeSource.count's uint16: counted in chunks (uint32 result)
    spikes = np.ones((70_000, 2, 2), dtype=np.uint8)
    spikes[:, 0, 0] = 0
    counts = window_counts(ArraySource(spikes), 0, 70_000)
    assert counts.dtype == np.uint32
    np.testing.assert_array_equal(counts, [[0, 70_000], [70_000, 70_000]])


# --- TFI ---------------------------------------------------------------------------------------
def _tfi_reference(spikes, t, hw):
    """Slow TFI straight from the definition in spikeview.classical.tfi's docstring."""
    n, h, w = spikes.shape
    out = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            cut_lo, cut_hi = t - hw < 0, t + hw >= n  # the stream cuts the search
            before = [k for k in range(t, max(0, t - hw) - 1, -1) if spikes[k, y, x]]  # nearest first
            after = [k for k in range(t + 1, min(n - 1, t + hw) + 1) if spikes[k, y, x]]
            # the side the stream does not cut is searched 2·hw deep for a whole interval
            deep_after = [k for k in range(t + 1, min(n - 1, t + 2 * hw) + 1) if spikes[k, y, x]]
            deep_before = [k for k in range(t, max(0, t - 2 * hw) - 1, -1) if spikes[k, y, x]]
            if before and after:
                interval = after[0] - before[0]
            elif not before and cut_lo and len(deep_after) >= 2:  # the stream's start cut the search
                interval = deep_after[1] - deep_after[0]
            elif not after and cut_hi and len(deep_before) >= 2:  # its end did
                interval = deep_before[0] - deep_before[1]
            else:
                interval = 2 * hw
            interval = min(interval, 2 * hw)
            out[y, x] = 1.0 / interval
    return out


def test_tfi_regular_spikes_every_4_ticks():
    spikes = np.zeros((64, 3, 4), dtype=np.uint8)
    for y in range(3):
        for x in range(4):
            spikes[(x + y) % 4 :: 4, y, x] = 1  # every 4 ticks, different phases
    out = tfi(ArraySource(spikes), center=30, half_window=8)
    np.testing.assert_array_equal(out, np.full((3, 4), 0.25, dtype=np.float32))


def test_tfi_hand_cases():
    spikes = np.zeros((20, 1, 4), dtype=np.uint8)
    spikes[10, 0, 0] = spikes[13, 0, 0] = 1  # spike at t itself counts as "previous": 1/3
    spikes[:, 0, 1] = 1  # every tick: interval 1
    spikes[9, 0, 2] = 1  # no later spike within half_window: capped at 2 * 5
    out = tfi_array(spikes, t=10, half_window=5)
    np.testing.assert_allclose(out, [[1 / 3, 1.0, 1 / 10, 1 / 10]], rtol=1e-6)
    assert np.isfinite(out).all()


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_tfi_at_the_ends_of_a_stream_reads_the_nearest_whole_interval(cfa):
    """At the first and last ticks the search is cut by the stream, not by the photosite: TFI takes the nearest
    whole interval on the other side instead of the cap (a Spike-Zoo clip's last TFI frame was black, 0.03 against
    0.45 a tick before); a dark photosite (no second spike within reach) keeps the cap."""
    n, h, w = 300, 4, 6
    spikes = np.zeros((n, h, w), np.uint8)
    periods = np.array([[3, 4, 5, 6, 7, 9]] * h)
    for y in range(h):
        for x in range(w):
            spikes[(y + x) % periods[y, x]::periods[y, x], y, x] = 1
    spikes[:, 0, 0] = 0
    spikes[150, 0, 0] = 1  # one spike in the whole stream: dark wherever it is imaged from
    src = ArraySource(spikes, cfa=cfa)
    want = 1.0 / periods
    want[0, 0] = 1 / 64
    for t in (0, 1, 150, 298, 299):
        got = tfi(src, t, 32)
        np.testing.assert_allclose(got[1:], want[1:], rtol=1e-6, err_msg=f"tick {t}")
        np.testing.assert_allclose(got[0, 1:], want[0, 1:], rtol=1e-6, err_msg=f"tick {t}")
        if t != 150:
            assert got[0, 0] == np.float32(1 / 64)


@pytest.mark.parametrize("seed, hw, n, p", [(0, 3, 30, 0.15), (1, 6, 30, 0.15), (2, 1, 30, 0.15), (3, 8, 30, 0.05),
                                           (4, 20, 30, 0.1), (5, 40, 30, 0.05), (6, 5, 7, 0.3)])
def test_tfi_matches_slow_reference_on_random_streams(seed, hw, n, p):
    """Both ends of the stream (search cut there, one end or both: streams shorter than the search) and inside."""
    spikes = _random_spikes(seed, (n, 6, 7), p=p)
    src = ArraySource(spikes)
    for t in sorted({0, 1, 2, n // 2, n - 3, n - 2, n - 1} & set(range(n))):
        expected = _tfi_reference(spikes, t, hw)
        np.testing.assert_allclose(tfi(src, t, hw), expected, rtol=1e-6)
        np.testing.assert_allclose(tfi_array(spikes.astype(bool), t, hw), expected, rtol=1e-6)


def test_tfi_range():
    spikes = _random_spikes(3, (50, 8, 8), p=0.05)
    out = tfi(ArraySource(spikes), 25)  # default half_window 32
    assert out.dtype == np.float32
    assert out.min() >= 1 / 64 and out.max() <= 1


@pytest.mark.parametrize("kwargs", [{"center": 20}, {"center": -1}, {"center": 3, "half_window": 0}])
def test_tfi_bad_arguments(kwargs):
    with pytest.raises(ParameterError):
        tfi(ArraySource(np.zeros((20, 2, 2), dtype=np.uint8)), **kwargs)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_the_app_preview_s_tfi_is_the_cli_s_at_both_ends_of_a_stream(cfa):
    """The Stream panel reads one block for TFP and TFI: its TFI must be cut where the stream is, not where the block
    is (it read the cap at a stream's ends where the CLI read the photosite's interval)."""
    from spikeview.classical.tfi import tfi_block, tfi_span
    from spikeview.session import core
    from spikeview.session.model import Session

    n, h, w = 200, 8, 8
    spikes = np.zeros((n, h, w), np.uint8)
    rng = np.random.default_rng(0)
    for y in range(h):
        for x in range(w):
            period = int(rng.integers(20, 60))
            spikes[int(rng.integers(0, period))::period, y, x] = 1
    src = ArraySource(spikes, cfa=cfa)
    for t in (0, 3, 100, 196, 199):
        lo, hi = tfi_span(t, 32, n)
        np.testing.assert_array_equal(tfi_block(spikes[max(0, lo - 5):], max(0, lo - 5), t, 32, n), tfi(src, t, 32))
        params = dict(Session().params, tfi_half_window=32, colour_cast=False)
        frames = core.stream_frames(src, t, params, None)
        np.testing.assert_array_equal(frames.tfi, core.tfi_frame(src, t, params, None))
    with pytest.raises(ParameterError, match="does not cover"):
        tfi_block(spikes[10:], 10, 0, 32, n)
