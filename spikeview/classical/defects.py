"""A capture's own sensor defects, found from its spikes: hot photosites, a dark border, bright edge lines.

Real spike cameras have photosites that fire far faster than anything around them (hot), rows and columns at the
frame's edge that see no light (a dark border, e.g. behind the sensor's mask) and edge lines that fire brighter
than the scene (edge artefacts). None of them is scene: left in, a hot photosite sets the white point, inflates the
noise estimate and stays a bright dot; a dark border is read as deep shadow.

:func:`find_defects` measures them once per capture from the mean rate over up to :data:`SAMPLE_TICKS` ticks
(evenly spread windows):

* **hot**: a photosite whose rate is at least :data:`HOT_RATIO` times the largest of its 8 same-colour neighbours
  and :data:`HOT_Z` binomial standard deviations above their median (a scene's bright point spreads over its
  neighbours through the optics; a hot photosite does not);
* **border**: up to :data:`BORDER_MAX` rows or columns at each edge whose mean rate is below :data:`BORDER_DARK`
  times the interior's median row (or column) mean;
* **edge lines**: the same rows or columns above :data:`EDGE_BRIGHT` times it.

Not found: short bright streaks of a few photosites along an edge (the real ``uhsr.npz`` has some at its bottom
edge, 3–6× the rate around them). A rule that took bright clusters near an edge also took scene content (a dark
coat against a bright sky at a frame's edge), so it is not used.

A colour capture's **dark rate** is measured too (:func:`dark_rate`): where the darkest patches of R, G and B fire
alike while the channels above them show the sensor's colour cast, those patches are black scene and their rate is
the sensor's dark rate (the same in every channel). A monochrome capture has no second witness: 0.

Where they go (:func:`spikeview.classical.calibration.attach`, which reads them through :func:`find_defects`): a
capture opened without a camera profile gets its hot photosites and that dark rate as a profile of its own (uniform
dark rate, unit gain), so the one rate correction
(:func:`~spikeview.classical.calibration.correct_rates`) fills them from their neighbours for the classical frames,
the guided observation (its noise estimate and plan) and the white point alike; the border and edge lines are
kept out of the white point (:func:`interior`) and named by ``spikeview info``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: ticks read to measure the defects (spread over the capture in windows of :data:`SAMPLE_WINDOW`)
SAMPLE_TICKS = 1000
SAMPLE_WINDOW = 100
#: a hot photosite fires at least this many times faster than the brightest of its same-colour neighbours
HOT_RATIO = 3.0
#: ... and this many binomial standard deviations above their median
HOT_Z = 8.0
#: rows/columns at each edge examined for a dark border or bright edge lines
BORDER_MAX = 8
#: a border row/column's mean rate below this fraction of the interior's median is dark
BORDER_DARK = 0.35
#: ... above this multiple of it, a bright edge line
EDGE_BRIGHT = 2.5


@dataclass
class Defects:
    """What :func:`find_defects` found.

    Attributes:
        hot: ``(H, W)`` bool hot photosites.
        border: ``(top, bottom, left, right)`` dark rows/columns at each edge.
        edges: ``(top, bottom, left, right)`` bright edge lines at each edge (outside the dark border).
        ticks: how many ticks were measured.
        dark: the sensor's dark rate (spikes per tick) measured on a colour capture's darkest patches (:func:`dark_rate`),
            0 where it cannot be told from scene black (a monochrome capture, or channels whose floors differ).
        floor: the capture's lowest floor in spikes per tick (:func:`darkest_floor`; monochrome too).
        pedestal: that floor where it may be a dark current, which the guided Q rule takes off; 0 on a colour capture
            without a cast (:func:`without_cast`: made from RGB frames, so its floor is light). An ecosystem-style dark
            chelsea: its floor read as a dark rate, Q's per-window grid took the light off and rounded the interval
            rates to its steps, 25.45 dB against TFI's 31.66; 33.24 dB now; panning along y it had lost its blue.
    """

    hot: np.ndarray
    border: tuple[int, int, int, int]
    edges: tuple[int, int, int, int]
    ticks: int
    dark: float = 0.0
    floor: float = 0.0
    pedestal: float = 0.0

    def describe(self) -> str:
        """One line for ``spikeview info``."""
        n = int(self.hot.sum())
        parts = [f"{n} hot pixel{'s' if n != 1 else ''} (filled from {'their' if n != 1 else 'its'} neighbours)"]
        names = ("top", "bottom", "left", "right")
        b = [f"{n} {v}" for n, v in zip(names, self.border) if v]
        e = [f"{n} {v}" for n, v in zip(names, self.edges) if v]
        parts.append("dark border: " + (", ".join(b) if b else "none"))
        parts.append("bright edge lines: " + (", ".join(e) if e else "none"))
        if self.dark > 0:
            parts.append(f"dark rate {self.dark:.3g} spikes/tick (the darkest patches, alike in R, G and B; subtracted)")
        return "; ".join(parts) + f" (measured over {self.ticks} ticks; kept out of the white point and the noise estimate)"

    def interior(self) -> tuple[slice, slice]:
        """The frame without its dark border and edge lines: ``(rows, cols)`` slices."""
        t, b, l, r = (max(x, y) for x, y in zip(self.border, self.edges))
        h, w = self.hot.shape
        return slice(t, h - b if b else h), slice(l, w - r if r else w)


def _sample_rates(source: Any) -> tuple[np.ndarray, int]:
    from spikeview.classical.tfp import window_counts

    n = int(source.n_frames)
    win = min(SAMPLE_WINDOW, n)
    k = max(1, min(SAMPLE_TICKS // max(win, 1), n // max(win, 1)))
    starts = np.linspace(0, n - win, k).astype(int) if k > 1 else np.array([0])
    total = None
    for s in starts:
        c = np.asarray(window_counts(source, int(s), int(s) + win), dtype=np.float64)
        total = c if total is None else total + c
    assert total is not None
    ticks = int(win * len(starts))
    return total / ticks, ticks


def _same_colour_stats(r: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Per photosite: the largest and the median of its 8 same-colour neighbours (edges repeated)."""
    p = np.pad(r, step, mode="edge")
    h, w = r.shape
    nb = [p[step + dy:step + dy + h, step + dx:step + dx + w]
          for dy in (-step, 0, step) for dx in (-step, 0, step) if (dy, dx) != (0, 0)]
    s = np.stack(nb)
    return s.max(axis=0), np.median(s, axis=0)


def _edge_runs(means: np.ndarray, ref: float) -> tuple[int, int, int, int]:
    """Dark (first two) and bright (last two) runs at the start and end of a profile of row or column means."""
    def run(vals: np.ndarray, test: Any) -> int:
        k = 0
        for v in vals[:BORDER_MAX]:
            if not test(v):
                break
            k += 1
        return k

    dark = lambda v: v < BORDER_DARK * ref  # noqa: E731
    bright = lambda v: v > EDGE_BRIGHT * ref  # noqa: E731
    d0, d1 = run(means, dark), run(means[::-1], dark)
    b0 = run(means[d0:], bright)
    b1 = run(means[::-1][d1:], bright)
    return d0, d1, b0, b1


def find_defects(source: Any) -> Defects:
    """The capture's hot photosites, dark border and bright edge lines (see the module docstring); cached on
    ``source``."""
    cached = getattr(source, "_spikeview_defects", None)
    if cached is not None:
        return cached
    from spikeview.cfa import parse_cfa

    r, ticks = _sample_rates(source)
    h, w = r.shape
    step = 1 if parse_cfa(getattr(source, "cfa", None)) is None else 2
    hot = np.zeros((h, w), bool)
    if min(h, w) > 2 * step:
        mx, med = _same_colour_stats(r, step)
        sd = np.sqrt(np.maximum(med * (1.0 - med), 1.0 / ticks) / ticks)
        hot = (r >= HOT_RATIO * np.maximum(mx, 1.0 / ticks)) & (r > med + HOT_Z * sd)
    border = edges = (0, 0, 0, 0)
    if min(h, w) > 4 * BORDER_MAX:
        rows, cols = r.mean(axis=1), r.mean(axis=0)
        rref = float(np.median(rows[BORDER_MAX:-BORDER_MAX]))
        cref = float(np.median(cols[BORDER_MAX:-BORDER_MAX]))
        if rref > 0 and cref > 0:
            t, b, bt, bb = _edge_runs(rows, rref)
            left, right, bl, br = _edge_runs(cols, cref)
            border, edges = (t, b, left, right), (bt, bb, bl, br)
    cfa = getattr(source, "cfa", None)
    floor = darkest_floor(r, cfa, hot)
    d = Defects(hot, border, edges, ticks, dark_rate(r, cfa, hot), floor, 0.0 if without_cast(r, cfa, hot) else floor)
    try:
        source._spikeview_defects = d
    except AttributeError:  # a source with __slots__: measured again next time
        pass
    return d


#: :func:`dark_rate`: the three channels' floors must agree within this ratio to be the dark rate ...
DARK_AGREE_RATIO = 1.3
#: ... or within this one where the lowest floor is below :data:`DARK_DIM_RATE` (a dim capture: its darkest patch
#: holds a little light in the more sensitive channels, and the lowest floor is the dark rate plus a trace of its
#: weakest channel: dark chelsea at 0.03 spikes per tick had floors 1.37× apart, its dark rate left in, 16° off once Q's
#: floor no longer hid it, 2.7° with it taken off). Not wider: at 3× the bench's coins_rgb took 0.0074 spikes per tick
#: for its dark rate (the simulator's is 0.005) and its white balance went 8.6° → 22°; its rocket and coffee, 2.2× and
#: 2.4× apart, keep theirs (benchmarks/results/colour.md, section 8) ...
DARK_AGREE_DIM = 1.5
#: ... spikes per tick: a pedestal below this (one spike per 50 ticks) common to the channels' darkest patches is taken
#: for a dark current; a brighter one is scene light unless the floors agree within DARK_AGREE_RATIO
DARK_DIM_RATE = 0.02
#: ... while the channels' means above the floor differ by at least this ratio (the sensor's colour cast, which scene
#: light in the darkest patch would show too)
DARK_WITNESS_RATIO = 1.5


def dark_rate(rates: np.ndarray, cfa: str | None, hot: np.ndarray | None = None) -> float:
    """The sensor's dark rate from a colour capture's mean rates ``(H, W)``, or 0.

    Each channel's floor is the 2nd percentile of its 8×8-cell block means
    (:func:`spikeview.classical.white_balance.channel_floors`, hot photosites replaced by the median). The
    dark rate is the same in every channel (the colour filter does not see it), while scene light in the darkest
    patch follows the sensor's colour response (G about twice R and B): the floors are taken for the dark rate only when
    they agree within :data:`DARK_AGREE_RATIO` (:data:`DARK_AGREE_DIM` below :data:`DARK_DIM_RATE`) while the channels' means above the floor differ by
    :data:`DARK_WITNESS_RATIO` or more (without a cast, agreeing floors could be a gray patch's light), and the lowest
    is returned. A monochrome capture has no second witness:
    0 (its dark rate cannot be told from scene black without a dark capture; ``spikeview calibrate --dark``).
    """
    from spikeview.cfa import parse_cfa

    stats = None if parse_cfa(cfa) is None else _floor_stats(rates, cfa, hot)
    if stats is None:
        return 0.0
    floors, means = stats
    light = means - floors.min()  # each channel's mean above the floor
    agree = DARK_AGREE_DIM if floors.min() < DARK_DIM_RATE else DARK_AGREE_RATIO
    if not ((floors > 0).all() and (light > 0).all()) or floors.max() > agree * floors.min():
        return 0.0
    if light.max() < DARK_WITNESS_RATIO * light.min():
        return 0.0  # channels alike above the floor (a sensor without a cast): agreeing floors prove nothing
    return float(floors.min())


#: :func:`without_cast`: a colour capture whose edges' colour lies within this angle of R = G = B has no cast (the
#: ecosystem-style captures: 1.5-7.8°; spikeview's simulator and real sensors: 17° and more off)
NO_CAST_DEG = 8.0


def darkest_floor(rates: np.ndarray, cfa: str | None, hot: np.ndarray | None = None) -> float:
    """A capture's lowest floor in spikes per tick (a colour capture's darkest patches' weakest channel; a monochrome
    one's darkest 8×8 blocks): ~0 where the scene has black and the sensor no dark rate (0.0002–0.0015 on such
    simulated scenes at 0.03–0.15 spikes per tick), the dark rate or more where one is in the rates (0.005 in the
    simulator; 0.016 on the real `uhsr.npz`). The guided plan's Q rule reads it
    (:meth:`spikeview.guided.observation.Observation.quantise_window`); unlike :func:`dark_rate` it does not say the
    floor IS a dark rate (a monochrome capture cannot tell)."""
    stats = _floor_stats(rates, cfa, hot)
    return 0.0 if stats is None else float(stats[0].min())


def without_cast(rates: np.ndarray, cfa: str | None, hot: np.ndarray | None = None) -> bool:
    """Whether a colour capture has no colour cast: its edges' and highlights' colour
    (:func:`~spikeview.classical.white_balance.illuminant` ``combined``) within :data:`NO_CAST_DEG` of R = G = B and
    nearer it than the typical response. Such a capture was made from display-referred RGB frames (the ecosystem's
    simulators, spike streams converted from video; colour spike cameras have a cast), without a dark current: its
    darkest floor is its darkest patch's light, not a pedestal (:attr:`Defects.pedestal`). ``False`` in monochrome."""
    from spikeview.cfa import TYPICAL_RESPONSE, parse_cfa
    from spikeview.classical import white_balance as wb

    if parse_cfa(cfa) is None:
        return False
    if min(np.shape(rates)) < 2 * wb.DARK_BLOCK:
        return False
    e = wb.illuminant(wb.cells_rgb(_filled(rates, hot), cfa), "combined")  # a hot photosite: white-patch's brightest
    if not (e > 0).all():
        return False
    off = wb.angle_deg(e, np.ones(3))
    return off <= NO_CAST_DEG and off < wb.angle_deg(e, np.asarray(TYPICAL_RESPONSE, dtype=np.float64))


def _filled(rates: np.ndarray, hot: np.ndarray | None) -> np.ndarray:
    """The mean rates as float64, hot photosites replaced by the median (a copy where any was replaced)."""
    r = np.asarray(rates, dtype=np.float64)
    if hot is not None and hot.any():
        r = r.copy()
        r[hot] = np.median(r)
    return r


def _floor_stats(rates: np.ndarray, cfa: str | None, hot: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    """``(floors, means)`` per channel of a capture's mean rates (hot photosites replaced by the median): a colour
    capture's R, G, B cells, a monochrome one's photosites (its one channel three times), or ``None`` (too small)."""
    from spikeview.cfa import parse_cfa
    from spikeview.classical import white_balance as wb

    cfa = parse_cfa(cfa)
    r = _filled(rates, hot)
    img = np.repeat(r[..., None], 3, axis=-1) if cfa is None else wb.cells_rgb(r, cfa)
    if min(img.shape[:2]) < 2 * wb.DARK_BLOCK:
        return None
    return wb.channel_floors(img), img.reshape(-1, 3).mean(axis=0)
