"""Degradation preview panel: the forward model operator by operator, beside the observation.

Shows the current reconstruction X, then M X (mosaic), C M X (colour cast η/α), Q(C M X) (soft
quantisation with sharpness k onto the Δτ-tick grid), the observed TFP Y and the residual
Y − Q(C M X) (optionally per Laplacian pyramid level). Changing k, η, L or Δτ recomputes at once.
"""

from __future__ import annotations

from typing import Any

from PySide6 import QtWidgets

from spikeview.gui.core import RESIDUAL_RANGE
from spikeview.gui.model import Session
from spikeview.gui.widgets import (
    ImagePane,
    ParamCheck,
    ParamSlider,
    ParamSpin,
    subscribe,
)

TITLES = {
    "x": "X (reconstruction)",
    "mx": "M X (mosaic)",
    "cmx": "C M X (colour cast)",
    "qcmx": "Q(C M X) (quantised)",
    "y": "Y (observed TFP)",
    "residual": f"Y − Q(C M X)  (±{RESIDUAL_RANGE:g})",
}
MAX_BANDS = 7  # L ≤ 6 band-pass levels + the coarse residual


class DegradationPanel(QtWidgets.QWidget):
    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.panes = {k: ImagePane(t, min_size=90) for k, t in TITLES.items()}
        grid = QtWidgets.QGridLayout()
        grid.setSpacing(2)
        for i, k in enumerate(TITLES):
            grid.addWidget(self.panes[k], i // 3, i % 3)
            if k != "x":
                self.panes[k].link(self.panes["x"])
        self.bands = [ImagePane(f"level {i}", min_size=60) for i in range(MAX_BANDS)]
        self.band_box = QtWidgets.QWidget()
        bl = QtWidgets.QHBoxLayout(self.band_box)
        bl.setContentsMargins(0, 0, 0, 0)
        bl.setSpacing(2)
        for b in self.bands:
            bl.addWidget(b)
        self.band_box.setVisible(False)
        self.k = ParamSlider(session, "k", label="k")
        self.eta = ParamSlider(session, "eta", label="η")
        self.levels = ParamSlider(session, "levels", label="L")
        self.window = ParamSpin(session, "window")
        self.pyramid = ParamCheck(session, "show_pyramid", "per level")
        self.info = QtWidgets.QLabel()
        self.info.setObjectName("degradation_info")
        controls = QtWidgets.QGridLayout()
        controls.addWidget(self.k, 0, 0)
        controls.addWidget(self.eta, 0, 1)
        controls.addWidget(self.levels, 1, 0)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Δτ"))
        row.addWidget(self.window)
        row.addWidget(self.pyramid)
        controls.addLayout(row, 1, 1)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.addLayout(grid, 3)
        lay.addWidget(self.band_box, 1)
        lay.addLayout(controls)
        lay.addWidget(self.info)
        subscribe(self, session.events.param_changed, self._on_param)
        subscribe(self, session.events.source_changed, self._on_source)
        self.last: Any = None
        self.updates = 0

    def _on_source(self) -> None:
        for p in list(self.panes.values()) + self.bands:
            p.set_image(None)

    def _on_param(self, name: str, value: Any) -> None:
        if name == "show_pyramid":
            self.band_box.setVisible(bool(value))

    def show_result(self, view: Any) -> None:
        """Show a :class:`~spikeview.gui.jobs.DegradationView`."""
        self.last = view
        self.updates += 1
        r = view.result
        for k, pane in self.panes.items():
            pane.set_image(r.images.get(k))
        self.panes["x"].set_title(f"X = {view.x_label}")
        show_bands = bool(self.session.get("show_pyramid")) and bool(r.bands)
        self.band_box.setVisible(show_bands)
        for i, pane in enumerate(self.bands):
            if i < len(r.bands):
                pane.setVisible(True)
                pane.set_image(r.bands[i])
                pane.set_title(f"level {i}" + (" (low-pass)" if i == len(r.bands) - 1 else ""))
            else:
                pane.setVisible(False)
        p = self.session.params
        h, w = view.shape
        self.info.setText(f"tick {view.tick} · {w}×{h} · Δτ = {p['window']} · k = {p['k']:g} · η = {p['eta']:g} · "
                          f"residual RMS {r.rmse:.4f} (1 level = {1 / max(p['window'], 1):.3f})")
