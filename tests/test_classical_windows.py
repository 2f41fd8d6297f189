"""spikeview.classical.windows: centred tick windows shifted inside the stream."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from spikeview.classical import window_range
from spikeview.errors import ParameterError


def test_centred_inside_stream():
    # window=10 around tick 100: a = 100 - 10 // 2 = 95, b = 95 + 10 (the documented convention)
    assert window_range(100, 10, 1000) == (95, 105)
    # odd window: the centre tick is exactly in the middle (20 ticks on each side)
    assert window_range(100, 41, 1000) == (80, 121)
    assert window_range(7, 1, 10) == (7, 8)


def test_shifted_at_start():
    # centre 2 would start at -3: shifted to start at 0, still 10 ticks long
    assert window_range(2, 10, 50) == (0, 10)
    assert window_range(0, 10, 50) == (0, 10)


def test_shifted_at_end():
    # centre 48 would end at 53 > 50: shifted to end at 50
    assert window_range(48, 10, 50) == (40, 50)
    assert window_range(49, 10, 50) == (40, 50)


def test_whole_stream_window():
    assert window_range(0, 50, 50) == (0, 50)
    assert window_range(49, 50, 50) == (0, 50)


@given(n=st.integers(1, 500), data=st.data())
def test_every_window_has_full_length_and_contains_centre(n, data):
    window = data.draw(st.integers(1, n))
    c = data.draw(st.integers(0, n - 1))
    a, b = window_range(c, window, n)
    assert b - a == window
    assert 0 <= a <= c < b <= n
    if window // 2 <= c <= n - window + window // 2:  # far enough from both ends: not shifted
        assert a == c - window // 2


@pytest.mark.parametrize(
    "center, window, n, word",
    [(5, 0, 10, "window"), (5, 11, 10, "window"), (-1, 3, 10, "center"), (10, 3, 10, "center"), (1.5, 3, 10, "center")],
)
def test_bad_arguments_raise(center, window, n, word):
    with pytest.raises(ParameterError, match=word):
        window_range(center, window, n)
