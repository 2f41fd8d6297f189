"""The pooling map of the guided panel: Δτ_eff per photosite of the current window, colour-mapped.

The map is the library's: :attr:`spikeview.guided.temporal.Pooling.dtau` of the very observation the
sampler uses (:func:`spikeview.pipeline.plan_window`, reported with the degradation preview and
with a guided run's plan); nothing here pools. Colours count the neighbouring windows a photosite took
(``Δτ_eff / Δτ − 1``: 0 = its own window only … 2R = every window of ±R); the caption is the plan's
``temporal`` reason. Where the pooling cannot act (``temporal_radius = 0``, a capture too short) there
is no map and the panel says why (:func:`pooling_unavailable`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from spikeview.gui.widgets import ImagePane
from spikeview.session import core
from spikeview.session.core import pooling_image, pooling_unavailable  # noqa: F401 (the panel's names)


def palette(n: int) -> np.ndarray:
    """``(n + 1, 3)`` uint8 colours for 0 … n pooled neighbouring windows (viridis: dark = own window only)."""
    lut = pg.colormap.get("viridis").getLookupTable(0.0, 1.0, nPts=max(n, 1) + 1, alpha=False)
    return np.asarray(lut[:, :3], dtype=np.uint8)[: n + 1]


# the session's jobs colour the map in their worker with the app's palette (spikeview.session.core.pooling_display)
core.POOLING_PALETTE = palette


class PoolingMap(QtWidgets.QWidget):
    """An image pane of Δτ_eff per photosite with its legend and the plan's temporal reason."""

    def __init__(self, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.setObjectName("pooling_map")
        self.pane = ImagePane("Pooling map: Δτ_eff per photosite", min_size=120)
        self.legend = QtWidgets.QLabel(objectName="pooling_legend")
        self.legend.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.legend.setWordWrap(True)
        self.caption = QtWidgets.QLabel(objectName="pooling_caption")
        self.caption.setWordWrap(True)
        self.caption.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Preferred)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(1)
        lay.addWidget(self.pane, 1)
        lay.addWidget(self.legend)
        lay.addWidget(self.caption)
        #: the Δτ_eff map shown (ticks per photosite, the library's array), or None
        self.dtau: np.ndarray | None = None
        self.pooling: Any = None
        #: why there is no map (None while one is shown)
        self.why_not: str | None = "no window has been planned yet"

    def show_pooling(self, pool: Any, knobs: dict[str, str | None] | None = None, tick: int | None = None,
                     image: np.ndarray | None = None) -> None:
        """Show a :class:`~spikeview.guided.temporal.Pooling` (or say why there is no map); ``image`` is its
        :func:`pooling_display`, made by the worker that computed ``pool`` (made here when not given)."""
        self.pooling = pool
        self.why_not = pooling_unavailable(pool, knobs)
        if self.why_not is not None:
            self.dtau = None
            self.pane.set_image(None)
            self.pane.set_title("Pooling map: none for this window")
            self.legend.setText("")
            self.caption.setText(f"No pooling map: {self.why_not}.")
            return
        n = len(pool.offsets)
        self.dtau = pool.dtau
        self.pane.set_image(image if image is not None else pooling_image(pool.dtau, pool.window, n))
        at = "" if tick is None else f" · tick {tick}"
        self.pane.set_title(f"Pooling map{at}")  # short: the pane is narrow on a 1366-pixel screen
        self.pane.title.setToolTip("Δτ_eff per photosite: how many neighbouring windows each photosite pooled")
        cols = palette(n)
        sw = "".join(f'<span style="background-color:#{c[0]:02x}{c[1]:02x}{c[2]:02x}">&nbsp;&nbsp;&nbsp;</span>' for c in cols)
        top = (f"±{pool.radius} windows" if n == 2 * pool.radius else f"{n} neighbouring windows")
        self.legend.setText(f"own window only {sw} {top}<br>Δτ_eff {pool.window} … {pool.window * (n + 1)} ticks "
                            f"(mean {float(np.mean(pool.dtau)):.0f})")
        self.caption.setText(pool.reason)
        self.caption.setToolTip(pool.reason)

