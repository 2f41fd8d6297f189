"""Compare panel: the scores of the canvas's A and B against the ground truth, and the histogram of what is shown.

Scores are those of :func:`spikeview.session.jobs.score_frame`: PSNR and SSIM at the sampler's exposure against
the ground truth aligned to the observation (how the guided runs are scored, ROI runs included), the PSNR after
one global gain (a colour cast costs) and the mean CIEDE2000 ΔE00. They exist where the capture has a ground
truth: a simulated capture's ``.gt.npz``, or an image loaded with File ▸ Load ground truth… (a Spike-Zoo clip's
PNG of the same stem). The histogram counts the displayed values (0–255) of A, and of B when it is shown, per
channel (64 bins; the clipped values at 0 and 255 are given as shares beside it, so that they do not flatten
the plot).
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from spikeview.session.model import Session
from spikeview.gui.canvas import SOURCES, ImageCanvas
from spikeview.gui.widgets import ElidedLabel, subscribe

#: the score columns: key in the scores, header, format
COLUMNS = (("psnr", "PSNR dB", "{:.2f}"), ("ssim", "SSIM", "{:.3f}"), ("psnr_1gain", "PSNR 1 gain", "{:.2f}"),
           ("delta_e00", "ΔE00", "{:.2f}"))
#: histogram bins over the display values 0–255
HIST_BINS = 64
#: histogram pens per channel (A solid, B dashed)
_PENS = ((235, 80, 80), (90, 200, 90), (90, 140, 255))


class ComparePanel(QtWidgets.QWidget):
    """Scores and histogram of the canvas's A and B (see module docstring)."""

    load_truth_requested = QtCore.Signal()

    def __init__(self, session: Session, canvas: ImageCanvas, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session, self.canvas = session, canvas
        self.table = QtWidgets.QTableWidget(2, len(COLUMNS), objectName="compare_scores")
        self.table.setHorizontalHeaderLabels([c[1] for c in COLUMNS])
        self.table.setVerticalHeaderLabels(["A", "B"])
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.verticalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        self.table.setVerticalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.table.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        h = self.table.horizontalHeader().sizeHint().height() + 2 * self.table.verticalHeader().defaultSectionSize() + 4
        self.table.setFixedHeight(h)
        self.table.setToolTip("Against the ground truth, aligned to the observation as the guided runs are scored "
                              "(PSNR/SSIM at the sampler's exposure; PSNR 1 gain: one gain for all channels, so a "
                              "colour cast costs; ΔE00: mean CIEDE2000)")
        self.names = ElidedLabel()
        self.names.setObjectName("compare_names")
        self.note = QtWidgets.QLabel(objectName="compare_note")
        self.note.setWordWrap(True)
        self.load_btn = QtWidgets.QPushButton("Load ground truth…", objectName="compare_load_truth")
        self.load_btn.setToolTip("An image of the same scene (PNG, EXR, npy) to score against, for a capture without "
                                 "a .gt.npz (e.g. a Spike-Zoo clip's PNG of the same stem)")
        self.load_btn.clicked.connect(self.load_truth_requested)
        self.hist = pg.PlotWidget(background=(24, 24, 24))
        self.hist.setObjectName("compare_histogram")
        self.hist.setMenuEnabled(False)
        self.hist.setMouseEnabled(False, False)
        self.hist.hideButtons()
        self.hist.setLabel("bottom", "displayed value")
        self.hist.getAxis("left").setStyle(showValues=False)
        self.hist.setXRange(0, 256, padding=0.01)
        self.hist.setMinimumHeight(90)
        # the plot takes the height there is (its own hint asked for more than a 768-pixel screen's column has)
        self.hist.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Ignored)
        self.curves = {(w, c): self.hist.plot(pen=pg.mkPen(_PENS[c], width=1,
                                                        style=QtCore.Qt.PenStyle.SolidLine if w == "A" else QtCore.Qt.PenStyle.DashLine),
                                             stepMode="center")
                       for w in ("A", "B") for c in range(3)}
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.addWidget(self.names)
        lay.addWidget(self.table)
        lay.addWidget(self.note)
        lay.addWidget(self.load_btn)
        title = QtWidgets.QLabel("Histogram of what is shown (A solid, B dashed, each to its own peak)")
        title.setWordWrap(True)
        lay.addWidget(title)
        self.clipped = QtWidgets.QLabel(objectName="compare_clipped")
        self.clipped.setWordWrap(True)
        self.clipped.setToolTip("Share of the shown values at black (0) and white (255), over all channels")
        lay.addWidget(self.clipped)
        lay.addWidget(self.hist, 1)
        self._timer = QtCore.QTimer(self, singleShot=True, interval=100)  # one redraw per burst of frames
        self._timer.timeout.connect(self.redraw)
        canvas.changed.connect(self._timer.start)
        subscribe(self, session.events.source_changed, lambda: self._timer.start())
        self.redraw()

    def redraw(self) -> None:
        a_key, mode, b_key = self.canvas.view()
        A, B = self.canvas.shown()
        self.names.setText(f"A: {SOURCES[a_key]}" + (f"   B: {SOURCES[b_key]}" if mode != "single" else ""))
        for row, img in enumerate((A, B)):
            for col, (key, _h, fmt) in enumerate(COLUMNS):
                v = None if img is None else img.scores.get(key)
                item = QtWidgets.QTableWidgetItem("–" if v is None else fmt.format(v))
                item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
                self.table.setItem(row, col, item)
        self.table.setVerticalHeaderLabels(["A", "B" if B is not None else "B (off)"])
        st = self.session.stream
        if st is None or st.ground_truth is None:
            self.note.setText("No ground truth for this capture: load an image of the same scene to score against.")
        else:
            roi = self.session.roi
            where = f"the ROI {roi[2]}×{roi[3]} at ({roi[0]}, {roi[1]})" if roi else "the whole frame"
            pending = [SOURCES[k] for k, img in ((a_key, A), (b_key, B)) if img is not None and not img.scores
                       and k != "truth" and not k.startswith("deg:") and k != "spikes"]
            self.note.setText(f"Scored on {where} at tick {self.session.tick}."
                              + (f" Waiting for: {', '.join(pending)}." if pending else ""))
        clipped = []
        for which, img in (("A", A), ("B", B)):
            hists = []
            for c in range(3):
                curve = self.curves[(which, c)]
                if img is None or (img.image.ndim == 2 and c > 0):
                    curve.setData([], [])
                    continue
                chan = img.image if img.image.ndim == 2 else img.image[..., c]
                counts = np.bincount(chan.ravel(), minlength=256).astype(np.float64)
                counts /= max(counts.sum(), 1.0)
                hists.append((curve, counts.reshape(HIST_BINS, -1).sum(axis=1)))
                curve.setPen(pg.mkPen((200, 200, 200) if img.image.ndim == 2 else _PENS[c], width=1,
                                      style=QtCore.Qt.PenStyle.SolidLine if which == "A" else QtCore.Qt.PenStyle.DashLine))
            # each image scaled to its own highest bin between the ends (the clipped values at 0 and 255 are said in
            # words: their bins would flatten the rest), so that a smooth estimate and a quantised TFP both show
            top = max((float(b[1:-1].max(initial=0.0)) for _, b in hists), default=0.0)
            for curve, b in hists:
                curve.setData(np.arange(HIST_BINS + 1, dtype=np.float64) * (256 / HIST_BINS), b / max(top, 1e-9))
            if img is not None:
                lo, hi = float((img.image == 0).mean()), float((img.image == 255).mean())
                clipped.append(f"{which}: {lo:.1%} at 0, {hi:.1%} at 255")
        self.hist.setYRange(0, 1.15, padding=0)
        self.clipped.setText("Clipped: " + "; ".join(clipped) if clipped else "")

    def scores(self) -> tuple[dict[str, float], dict[str, float]]:
        """The scores of A and B as shown (tests)."""
        A, B = self.canvas.shown()
        return (dict(A.scores) if A is not None else {}), (dict(B.scores) if B is not None else {})

