"""Firing rates and colour cast panel: per-site SFR histograms and gray-world α over time."""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtWidgets

from spikeview.session.model import Session
from spikeview.gui.widgets import subscribe

SITE_PENS = {"R": (230, 60, 60), "Gr": (60, 200, 60), "Gb": (20, 130, 90), "B": (70, 110, 255), "all": (220, 220, 220)}
CHANNEL_PENS = ((230, 60, 60), (60, 200, 60), (70, 110, 255))


class RatesPanel(QtWidgets.QWidget):
    """Histograms of the current window (or ROI) per Bayer site and α_c over time."""

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.hist_plot = pg.PlotWidget()
        self.hist_plot.setObjectName("hist_plot")
        self.hist_plot.setLabel("bottom", "SFR (spikes per tick)")
        self.hist_plot.setLabel("left", "fraction of photosites")
        self.hist_plot.addLegend(offset=(-5, 5), labelTextSize="8pt")
        self.hist_plot.setMouseEnabled(x=False, y=False)
        self.hist_plot.setMenuEnabled(False)
        self.hist_plot.getAxis("left").enableAutoSIPrefix(False)
        self.hist_curves: dict[str, pg.PlotDataItem] = {}
        self.alpha_plot = pg.PlotWidget()
        self.alpha_plot.setObjectName("alpha_plot")
        self.alpha_plot.setLabel("bottom", "tick")
        self.alpha_plot.setLabel("left", "gray-world α")
        self.alpha_plot.addLegend(offset=(-5, 5), labelTextSize="8pt")
        self.alpha_plot.setMenuEnabled(False)
        # lines only, and the tick marker moves with the (throttled) rates during playback: this plot
        # must not be redrawn at the display's frame rate
        self.alpha_curves = [self.alpha_plot.plot([], [], pen=pg.mkPen(c, width=2), name=n)
                             for c, n in zip(CHANNEL_PENS, ("α R", "α G", "α B"))]
        self.seq_lines = [pg.InfiniteLine(angle=0, pen=pg.mkPen(c, style=pg.QtCore.Qt.PenStyle.DashLine)) for c in CHANNEL_PENS]
        for ln in self.seq_lines:
            ln.setVisible(False)
            self.alpha_plot.addItem(ln, ignoreBounds=True)
        self.tick_line = pg.InfiniteLine(angle=90, pen=pg.mkPen((255, 170, 0)))
        self.alpha_plot.addItem(self.tick_line, ignoreBounds=True)
        self.summary = QtWidgets.QLabel()
        self.summary.setObjectName("rates_summary")
        self.summary.setWordWrap(True)
        self.hint = QtWidgets.QLabel()
        self.hint.setObjectName("rates_hint")
        self.hint.setWordWrap(True)
        self.hint.setStyleSheet("color: #e0a000;")
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.addWidget(self.hist_plot, 3)
        lay.addWidget(self.summary)
        lay.addWidget(self.hint)
        lay.addWidget(self.alpha_plot, 2)
        subscribe(self, session.events.tick_changed, self._on_tick)
        subscribe(self, session.events.source_changed, self._on_source)
        self.last: Any = None

    def _on_source(self) -> None:
        for c in self.hist_curves.values():
            self.hist_plot.removeItem(c)
        self.hist_curves.clear()
        self.hist_plot.plotItem.legend.clear()
        for ln in self.seq_lines:
            ln.setVisible(False)
        self.summary.setText("")
        self.hint.setText("")
        # monochrome: one channel and no colour cast, so no α R/G/B curves or legend
        src = self.session.source
        colour = src is None or getattr(src, "cfa", None) is not None
        for curve in self.alpha_curves:
            curve.setVisible(colour)
        self.alpha_plot.plotItem.legend.setVisible(colour)
        # …and no α plot at all: an empty plot whose axis title did not fit at 1366×768 told nothing
        self.alpha_plot.setVisible(colour)
        self.alpha_plot.setLabel("left", "gray-world α (ticks/spike)" if colour else "gray-world α (none: monochrome)")

    def _on_tick(self, tick: int) -> None:
        if not self.session.playing:
            self.tick_line.setValue(tick)

    def show_rates(self, r: Any) -> None:
        """Show a :class:`~spikeview.session.core.RatesResult`."""
        self.last = r
        self.tick_line.setValue(r.tick)
        for name, hist in r.hists.items():
            curve = self.hist_curves.get(name)
            if curve is None:
                c = SITE_PENS.get(name, (200, 200, 200))
                curve = self.hist_plot.plot(stepMode="center", pen=pg.mkPen(c, width=2), name=name)
                self.hist_curves[name] = curve
            curve.setData(r.edges, hist)
        self.hist_plot.setXRange(0, 1, padding=0.02)
        s = self.session
        where = "ROI" if s.roi is not None else "frame"
        means = "  ".join(f"{k} {v:.3f}" for k, v in r.means.items())
        alpha = ", ".join(f"{a:.2f}" for a in r.alpha)
        note = " (refreshed 4×/s while playing)" if s.playing else ""
        colour = getattr(s.source, "cfa", None) is not None
        # α = 1/mean SFR in ticks per spike, the quantity the plan divides the sampler's η by (its "gains η/α")
        alpha_text = f"   ·   window α = 1/mean SFR = ({alpha}) ticks/spike" if colour else ""  # monochrome: no cast, no α
        self.summary.setText(f"Mean SFR ({where}, tick {r.tick}{note}): {means}{alpha_text}")
        self.hint.setText(cfa_hint(r.means))

    def show_alpha_history(self, data: tuple[np.ndarray, np.ndarray]) -> None:
        ticks, alphas = data
        for i, curve in enumerate(self.alpha_curves):
            if alphas.ndim == 2 and alphas.shape[0] and i < alphas.shape[1]:
                curve.setData(ticks, alphas[:, i])
            else:
                curve.setData([], [])

    def show_sequence_alpha(self, alpha: np.ndarray | None) -> None:
        for i, ln in enumerate(self.seq_lines):
            ok = alpha is not None and i < len(alpha)
            ln.setVisible(bool(ok))
            if ok:
                ln.setValue(float(alpha[i]))


def cfa_hint(means: dict[str, float]) -> str:
    """A warning when the site statistics suggest a wrong CFA, flip or width, else ``""``.

    On a correctly set Bayer sensor the two greens see the same light, so their mean rates agree
    closely; a clear Gr/Gb mismatch means the rows are shifted (wrong flip or CFA phase), and a
    'green' site darker than both R and B means R/B and G are swapped.
    """
    if not {"Gr", "Gb", "R", "B"} <= set(means):
        return ""
    gr, gb, r, b = means["Gr"], means["Gb"], means["R"], means["B"]
    g = (gr + gb) / 2
    if g <= 0:
        return ""
    if abs(gr - gb) / g > 0.25:
        return (f"The two green sites differ by {100 * abs(gr - gb) / g:.0f} %: the CFA phase or the vertical flip is "
                "probably wrong (File ▸ Stream settings (CFA, flip, camera profile)…).")
    if g < min(r, b):
        return "The green sites are darker than red and blue: the CFA is probably wrong (try another pattern in File ▸ Stream settings (CFA, flip, camera profile)…)."
    return ""
