"""Degradation preview panel: the forward model operator by operator, beside the observation.

Shows the stages of the very forward model the guided sampler runs on this window (its data term:
the plan's M, C and Q, the noise weights and the pyramid): the current reconstruction X, M X, C M X,
A X = Q(C M X) (Q only when the plan turns it on), the observed TFP Y and the noise-weighted residual
√w̃ (Y − A X) (optionally per pyramid band). Changing k, η, L, Q or Δτ recomputes at once; a knob
that cannot act on this window is disabled with the plan's reason.
"""

from __future__ import annotations

from typing import Any

from PySide6 import QtCore, QtWidgets

from spikeview.session.core import RESIDUAL_RANGE
from spikeview.session.model import SPECS, Session
from spikeview.gui.widgets import (
    ElidedLabel,
    ImagePane,
    ParamCheck,
    ParamSlider,
    ParamSpin,
    set_colour_only,
    subscribe,
)

TITLES = {
    "x": "X (reconstruction)",
    "mx": "M X (mosaic)",
    "cmx": "C M X (colour cast)",
    "qcmx": "Q(C M X) (quantised)",
    "y": "Y (observed TFP)",
    "residual": f"√w̃ (Y − A X), noise-weighted  (±{RESIDUAL_RANGE:g})",
}
MAX_BANDS = 7  # L ≤ 6 band-pass levels + the coarse residual
#: what the panes area shows: all six stages, or fewer, larger panes to judge k and the residual by eye
LAYOUTS = {
    "all": ("All six stages", tuple(TITLES)),
    "compare": ("Q(C M X) beside Y", ("qcmx", "y")),
    "residual": ("Y beside the residual", ("y", "residual")),
    "x": ("X beside Y", ("x", "y")),
}


class DegradationPanel(QtWidgets.QWidget):
    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.panes = {k: ImagePane(t, min_size=90) for k, t in TITLES.items()}
        self.grid = grid = QtWidgets.QGridLayout()
        grid.setSpacing(2)
        self.layout_combo = QtWidgets.QComboBox(objectName="degradation_layout")
        for key, (text, _keys) in LAYOUTS.items():
            self.layout_combo.addItem(text, key)
        self.layout_combo.setToolTip("Show all stages, or two large panes side by side")
        self.layout_combo.currentIndexChanged.connect(lambda _i: self.set_layout(self.layout_combo.currentData()))
        self.fit_btn = QtWidgets.QToolButton(text="Fit", objectName="degradation_fit")
        self.fit_btn.setToolTip("Reset the zoom: show the whole image in every pane (or double-click a pane)")
        self.fit_btn.clicked.connect(self.reset_zoom)
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
        self.colour_only = {self.eta: self.eta.toolTip()}
        self.levels = ParamSlider(session, "levels", label="L")
        self.window = ParamSpin(session, "window")
        self.pyramid = ParamCheck(session, "show_pyramid", "per level")
        self.info = ElidedLabel()  # one status line: shortened with "…" (full text in its tooltip) on a small screen
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
        bottom = QtWidgets.QHBoxLayout()
        bottom.addWidget(self.info, 1)
        self.info.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Preferred)
        bottom.addWidget(QtWidgets.QLabel("Show"))
        bottom.addWidget(self.layout_combo)
        bottom.addWidget(self.fit_btn)
        lay.addLayout(bottom)
        subscribe(self, session.events.param_changed, self._on_param)
        subscribe(self, session.events.source_changed, self._on_source)
        subscribe(self, session.events.playback_changed, self._on_playback)
        self.last: Any = None
        self.updates = 0
        self.set_layout("all")

    # ------------------------------------------------------------------------------ view
    def set_layout(self, key: str) -> None:
        """Arrange the panes: ``"all"`` six in a 3 × 2 grid, or two large ones (see :data:`LAYOUTS`)."""
        keys = LAYOUTS[key][1]
        for p in self.panes.values():
            self.grid.removeWidget(p)
            p.setVisible(False)
        cols = 3 if len(keys) > 2 else 2
        for i, k in enumerate(keys):
            self.grid.addWidget(self.panes[k], i // cols, i % cols)
            self.panes[k].setVisible(True)
        for c in range(3):
            self.grid.setColumnStretch(c, 1 if c < cols else 0)
        # the shown panes zoom and pan together; a hidden one is left out (its stale geometry, linked, broke Fit in
        # the two-pane views without X) and fits its image when shown again
        for p in self.panes.values():
            p.unlink()
        for k in keys[1:]:
            self.panes[k].link(self.panes[keys[0]])
        self._shown = keys
        with QtCore.QSignalBlocker(self.layout_combo):
            self.layout_combo.setCurrentIndex(self.layout_combo.findData(key))
        self.reset_zoom()

    def reset_zoom(self) -> None:
        """Show the whole image in every pane again (after the user zoomed or panned)."""
        for p in self.panes.values():
            p.fit = True
        self.panes[self._shown[0]].reset_zoom()
        for b in self.bands:
            b.reset_zoom()

    def _on_source(self) -> None:
        for p in list(self.panes.values()) + self.bands:
            p.set_image(None)
        colour = set_colour_only(self.colour_only, self.session.source)
        self.panes["mx"].set_title(TITLES["mx"] if colour else "M X (no mosaic: monochrome)")
        self.panes["cmx"].set_title(TITLES["cmx"] if colour else "C M X (no cast: monochrome)")

    def _on_playback(self, playing: bool) -> None:
        if playing and self.last is not None:  # the preview stays on its tick while the stream plays: say so
            self.info.setText(f"Preview of tick {self.last.tick}; it follows the stream when playback pauses.")

    def _on_param(self, name: str, value: Any) -> None:
        if name == "show_pyramid":
            self.band_box.setVisible(bool(value))

    def show_result(self, view: Any) -> None:
        """Show a :class:`~spikeview.session.jobs.DegradationView`."""
        self.last = view
        self.updates += 1
        r = view.result
        for k, pane in self.panes.items():
            pane.set_image(r.images.get(k))
        self.panes["x"].set_title(f"X = {view.x_label}")
        self.panes["qcmx"].set_title(TITLES["qcmx"] if getattr(view, "quantise", True)
                                     else "A X = C M X (Q off for this window)")
        show_bands = bool(self.session.get("show_pyramid")) and bool(r.bands)
        self.band_box.setVisible(show_bands)
        for i, pane in enumerate(self.bands):
            if i < len(r.bands):
                pane.setVisible(True)
                pane.set_image(r.bands[i])
                pane.set_title(f"level {i}" + (" (low-pass)" if i == len(r.bands) - 1 else ""))
            else:
                pane.setVisible(False)
        for path, control in (("guided.k", self.k), ("guided.levels", self.levels)):
            why = getattr(view, "knobs", {}).get(path)
            control.setEnabled(why is None)
            control.setToolTip(SPECS[path.split(".")[1]].help if why is None else f"No effect on this window: {why}.")
        p = self.session.params
        h, w = view.shape
        eta = f"η = {p['eta']:g} · " if view.colour else ""  # η scales the colour cast only
        self.info.setText(f"tick {view.tick} · {w}×{h} · Δτ = {p['window']} · k = {p['k']:g} · {eta}"
                          f"residual RMS {r.rmse:.4f} (1 level = {1 / max(p['window'], 1):.3f})")
