"""Tick windows: which ticks ``[a, b)`` a reconstruction centred on tick ``c`` reads.

Every classical reconstruction of spikeview looks at a window of ``Δτ`` consecutive ticks around a
centre tick. :func:`window_range` is the one place that decides which ticks those are, so the CLI,
the GUI, the exporters and the benchmarks all agree.
"""

from __future__ import annotations

import operator

from spikeview.errors import ParameterError


def _as_int(name: str, value: object) -> int:
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise ParameterError(f"{name} must be an integer number of ticks, got {value!r}; pass a whole number.") from None


def window_range(center: int, window: int, n_frames: int) -> tuple[int, int]:
    """The tick range ``[a, b)`` of a ``window``-tick window centred on tick ``center``.

    Centring: ``a = center - window // 2`` and ``b = a + window``, so for an odd ``window`` the
    centre tick sits exactly in the middle and for an even ``window`` it is the first tick of the
    second half (``window=10`` around tick 100 reads ticks 95…104).

    Edge handling: near the start or end of the stream the window is **shifted** (not shortened)
    until it lies inside ``[0, n_frames)``, so every window holds exactly ``window`` ticks and every
    frame of a sequence has the same noise level and the same set of SFR values
    ``{0, 1/Δτ, …, 1}``. The centre tick is then no longer in the middle of the window, but it is
    always inside it.

    Args:
        center: centre tick, ``0 <= center < n_frames``.
        window: window length Δτ in ticks, ``1 <= window <= n_frames``.
        n_frames: number of ticks in the stream.

    Returns:
        ``(a, b)`` with ``0 <= a <= center < b <= n_frames`` and ``b - a == window``.

    Raises:
        ParameterError: ``window`` is below 1 or longer than the stream, or ``center`` lies
            outside the stream.
    """
    center = _as_int("center", center)
    window = _as_int("window", window)
    n_frames = _as_int("n_frames", n_frames)
    if n_frames < 1:
        raise ParameterError("The stream holds no complete frame, so there is no window to read: check the file and its width/height.")
    if window < 1:
        raise ParameterError(f"window must be at least 1 tick, got {window}; pass a positive window length.")
    if window > n_frames:
        raise ParameterError(
            f"window of {window} ticks is longer than the stream's {n_frames} ticks; choose a window of at most {n_frames}."
        )
    if not 0 <= center < n_frames:
        raise ParameterError(
            f"center tick {center} is outside the stream, which holds ticks [0, {n_frames}); choose a tick inside it."
        )
    a = center - window // 2
    a = min(max(a, 0), n_frames - window)
    return a, a + window
