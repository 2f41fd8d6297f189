"""Dialogs: stream settings with a live preview, keyboard shortcuts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.io import FORMATS as IO_FORMATS
from spikeview.cfa import BAYER_PATTERNS
from spikeview.errors import SpikeviewError
from spikeview.session.model import OpenedStream
from spikeview.gui.panels.rates import cfa_hint
from spikeview.gui.widgets import ImagePane

#: the format choices of the dialog: "auto" and spikeview.io.FORMATS (one list), each with its words
_FORMAT_WORDS = {"plain": "Plain packed .dat", "raw400": "Raw 400×250 camera", "raw1m": "Raw 1000×1000 camera",
                 "npz": ".npy / .npz array"}
FORMATS = (("auto", "Automatic (sidecar / suffix)"),) + tuple((f, _FORMAT_WORDS.get(f, f)) for f in IO_FORMATS)


def settings_preview(stream: OpenedStream) -> tuple[np.ndarray, np.ndarray, str, str]:
    """What the settings dialog shows for one interpretation of a file (no Qt).

    Returns the colour TFP preview (uint8 RGB, demosaicked and colour-corrected so a wrong CFA or
    flip shows as wrong colours), the raw mosaic (uint8 gray), a one-line description and a hint
    that names a likely wrong setting (or ``""``).
    """
    from spikeview.classical.colour_cast import sequence_alpha
    from spikeview.classical.config import ClassicalConfig
    from spikeview.classical.reconstruct import preview_rgb
    from spikeview.classical.tfp import counts_to_sfr, window_counts
    from spikeview.session import core

    src = stream.source
    n = src.n_frames
    window = max(1, min(32, n))
    centre = n // 2
    alpha = sequence_alpha(src, ClassicalConfig(alpha_max_windows=16), warn=False)[0]  # a quick look: 16 windows
    rgb = preview_rgb(src, centre, window, alpha=alpha, colour_cast=src.cfa is not None, eta=2.0)
    a, b = core.window_range(centre, window, n)
    sfr = counts_to_sfr(window_counts(src, a, b), b - a)  # the classical TFP of the window
    mosaic = core.to_display(sfr, 0.0, 1.0, "srgb")
    info = src.info
    desc = (f"{info.width}×{info.height}, {n} ticks ({n / src.tick_rate * 1e3:.1f} ms), CFA {info.cfa or 'none'}, "
            f"flip {'on' if info.flip_vertical else 'off'}")
    hint = ""
    if src.cfa is not None:
        hint = cfa_hint(core.site_rates(sfr, src.cfa, window).means)
    else:  # the library's check, the one `spikeview info` prints (a colour filter read as monochrome)
        from spikeview.gui.widgets import app_words
        from spikeview.io.geometry import mean_rates, monochrome_cfa_warning

        note = monochrome_cfa_warning(mean_rates(src))
        hint = app_words(f"Probably not monochrome: {note}") if note else ""
    return rgb, mosaic, desc, hint


class StreamSettingsDialog(QtWidgets.QDialog):
    """Ask for format, width/height, CFA and flip, previewing each choice live.

    ``opener(**settings) -> OpenedStream`` opens the data with the chosen settings (it raises a
    :class:`~spikeview.errors.SpikeviewError` for settings that do not fit). On accept,
    :attr:`stream` holds the opened stream and :attr:`settings` the chosen values.
    """

    def __init__(self, title: str, opener: Callable[..., OpenedStream], initial: dict[str, Any],
                 candidates: list[tuple[int, int]] | None = None, message: str = "", *, geometry: bool = True,
                 remember: bool = False, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle(title)
        self.setObjectName("stream_settings")
        self.opener = opener
        self.stream: OpenedStream | None = None
        self.settings: dict[str, Any] = {}
        self.message = QtWidgets.QLabel(message)
        self.message.setWordWrap(True)
        self.format = QtWidgets.QComboBox()
        for key, text in FORMATS:
            self.format.addItem(text, key)
        self.width_spin = QtWidgets.QSpinBox(objectName="width")
        self.height_spin = QtWidgets.QSpinBox(objectName="height")
        for sp in (self.width_spin, self.height_spin):
            sp.setRange(0, 16384)
            sp.setSpecialValueText("auto")
            sp.setKeyboardTracking(False)
        self.candidates = QtWidgets.QComboBox(objectName="candidates")
        self.candidates.addItem("sizes that fit the file…", None)
        for w, h in candidates or []:
            self.candidates.addItem(f"{w} × {h}", (w, h))
        self.candidates.setEnabled(bool(candidates))
        self.candidates.currentIndexChanged.connect(self._pick_candidate)
        self.cfa = QtWidgets.QComboBox(objectName="cfa")
        for c in BAYER_PATTERNS:
            self.cfa.addItem(c, c)
        self.cfa.addItem("none (monochrome)", "none")
        self.flip = QtWidgets.QCheckBox("Rows stored upside down (vertical flip)", objectName="flip")
        self.flip.setToolTip("The .dat ecosystem stores rows bottom-up; simulator files often do not")
        # the camera profile (``--camera``, made by ``spikeview calibrate``): dark rate, flat field, hot pixels, colour
        self.camera = QtWidgets.QLineEdit(objectName="camera")
        self.camera.setPlaceholderText("none: the capture's own hot pixels are filled")
        self.camera.setToolTip("A camera profile made by `spikeview calibrate` from a dark and/or flat capture of this "
                               "sensor: its dark rate, flat field and hot pixels correct the rates every method sees, "
                               "and White bal. auto uses its colour response. Recorded in exports and presets.")
        self.camera.setClearButtonEnabled(True)
        self.camera.editingFinished.connect(lambda: self._timer.start())
        self.camera_browse = QtWidgets.QPushButton("Browse…", objectName="camera_browse")
        self.camera_browse.clicked.connect(self._browse_camera)
        self.remember = QtWidgets.QCheckBox("Remember these settings next to the file (write a sidecar)", objectName="remember")
        self.remember.setToolTip("Writes <file>.toml, which the app and the command line read next time")
        self.remember.setVisible(remember)
        self.preview = ImagePane("colour preview (TFP, 32 ticks)", min_size=220)
        self.mosaic = ImagePane("raw mosaic", min_size=220)
        self.mosaic.link(self.preview)
        self.desc = QtWidgets.QLabel(objectName="desc")
        self.desc.setWordWrap(True)
        self.hint = QtWidgets.QLabel(objectName="hint")
        self.hint.setWordWrap(True)
        self.hint.setStyleSheet("color: #e0a000;")
        self.error = QtWidgets.QLabel(objectName="error")
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color: #ff6060;")
        self.buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.StandardButton.Ok
                                                  | QtWidgets.QDialogButtonBox.StandardButton.Cancel)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)

        form = QtWidgets.QFormLayout()
        if geometry:
            form.addRow("Format", self.format)
            size = QtWidgets.QHBoxLayout()
            size.addWidget(self.width_spin)
            size.addWidget(QtWidgets.QLabel("×"))
            size.addWidget(self.height_spin)
            size.addWidget(self.candidates, 1)
            form.addRow("Width × height", size)
        form.addRow("CFA (top-left 2×2 after flip)", self.cfa)
        form.addRow("", self.flip)
        cam = QtWidgets.QHBoxLayout()
        cam.addWidget(self.camera, 1)
        cam.addWidget(self.camera_browse)
        form.addRow("Camera profile", cam)
        previews = QtWidgets.QHBoxLayout()
        previews.addWidget(self.preview)
        previews.addWidget(self.mosaic)
        lay = QtWidgets.QVBoxLayout(self)
        lay.addWidget(self.message)
        lay.addLayout(form)
        lay.addLayout(previews, 1)
        lay.addWidget(self.desc)
        lay.addWidget(self.hint)
        lay.addWidget(self.error)
        lay.addWidget(self.remember)
        lay.addWidget(self.buttons)
        self.resize(720, 560)

        self._timer = QtCore.QTimer(self, singleShot=True, interval=120)
        self._timer.timeout.connect(self.update_preview)
        self._set_initial(initial)
        for sig in (self.format.currentIndexChanged, self.width_spin.valueChanged, self.height_spin.valueChanged,
                    self.cfa.currentIndexChanged, self.flip.toggled):
            sig.connect(lambda *_: self._timer.start())
        self.update_preview()

    def _set_initial(self, s: dict[str, Any]) -> None:
        self.format.setCurrentIndex(max(self.format.findData(s.get("format") or "auto"), 0))
        self.width_spin.setValue(int(s.get("width") or 0))
        self.height_spin.setValue(int(s.get("height") or 0))
        cfa = s.get("cfa") or "none"
        self.cfa.setCurrentIndex(max(self.cfa.findData(str(cfa).upper() if cfa != "none" else "none"), 0))
        self.flip.setChecked(bool(s.get("flip_vertical", True)))
        self.camera.setText(str(s.get("camera") or ""))

    def _browse_camera(self) -> None:
        start = self.camera.text().strip() or str(Path.home())
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Camera profile (spikeview calibrate)", start,
                                                        "Camera profiles (*.toml);;All files (*)")
        if path:
            self.camera.setText(path)
            self._timer.start()

    def _pick_candidate(self, idx: int) -> None:
        wh = self.candidates.itemData(idx)
        if wh:
            with QtCore.QSignalBlocker(self.width_spin), QtCore.QSignalBlocker(self.height_spin):
                self.width_spin.setValue(wh[0])
                self.height_spin.setValue(wh[1])
            self._timer.start()

    def current_settings(self) -> dict[str, Any]:
        fmt = self.format.currentData()
        out: dict[str, Any] = {"cfa": self.cfa.currentData(), "flip_vertical": self.flip.isChecked(),
                               "camera": self.camera.text().strip() or None}
        if fmt != "auto":
            out["format"] = fmt
        if self.width_spin.value() > 0:
            out["width"] = self.width_spin.value()
        if self.height_spin.value() > 0:
            out["height"] = self.height_spin.value()
        return out

    def update_preview(self) -> None:
        """Open with the current settings and show the result (or say why it does not fit)."""
        self._timer.stop()
        settings = self.current_settings()
        ok = self.buttons.button(QtWidgets.QDialogButtonBox.StandardButton.Ok)
        try:
            stream = self.opener(**settings)
            rgb, mosaic, desc, hint = settings_preview(stream)
        except SpikeviewError as e:
            self.stream = None
            self.error.setText(str(e))
            self.hint.setText("")
            self.preview.set_image(None)
            self.mosaic.set_image(None)
            ok.setEnabled(False)
            return
        if self.stream is not None and self.stream is not stream and self.stream.path is not None:
            self.stream.source.close()
        self.stream, self.settings = stream, settings
        self.error.setText("")
        self.preview.set_image(rgb)
        self.mosaic.set_image(mosaic)
        self.desc.setText(desc)
        default = ("Check: text and horizons the right way up, edges not slanted (a wrong width shears the rows)."
                   if settings.get("cfa") == "none" else  # monochrome: no colours or greens to compare
                   "Check: colours natural, the two greens equal, text and horizons the right way up.")
        self.hint.setText(hint or default)
        ok.setEnabled(True)

    def reject(self) -> None:
        if self.stream is not None and self.stream.path is not None:
            self.stream.source.close()
        self.stream = None
        super().reject()


SHORTCUTS = (
    ("Space", "Play / pause"),
    ("← / →", "One tick back / forward"),
    ("Shift+← / Shift+→", "One window back / forward"),
    ("Home / End", "First / last tick of the range"),
    ("I / O", "Mark in / out at the current tick"),
    ("L", "Loop on / off"),
    ("Ctrl+O", "Open a capture"),
    ("Ctrl+E", "Export (the Export panel's settings)"),
    ("Ctrl+R", "Run the guided reconstruction"),
    ("Esc", "Cancel the guided run"),
    ("Ctrl+0", "Fit the whole frame (canvas and panels)"),
    ("Ctrl+\\", "Canvas: split A | B (drag the line)"),
    ("Ctrl+Shift+S", "Canvas: swap A and B"),
    ("Ctrl+Z / Ctrl+Shift+Z", "Undo / redo a parameter change"),
    ("Ctrl+S / Ctrl+L", "Save / load a parameter preset"),
    ("F1", "This help"),
)


class ShortcutsDialog(QtWidgets.QDialog):
    """F1: the keyboard shortcuts, a few tips, and every parameter's control, flag and meaning."""

    def __init__(self, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle("spikeview — keyboard shortcuts")
        self.setObjectName("shortcuts")
        table = QtWidgets.QTableWidget(len(SHORTCUTS), 2)
        table.setObjectName("shortcuts_table")
        table.setHorizontalHeaderLabels(["Keys", "Action"])
        table.verticalHeader().setVisible(False)
        table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        for i, (k, a) in enumerate(SHORTCUTS):
            table.setItem(i, 0, QtWidgets.QTableWidgetItem(k))
            table.setItem(i, 1, QtWidgets.QTableWidgetItem(a))
        table.horizontalHeader().setStretchLastSection(True)
        table.resizeColumnsToContents()
        tips = QtWidgets.QLabel(
            "Drop a capture or a preset (.toml) on the window to open it. Drag a slider: one undo step. "
            "The ROI button draws a region on the canvas used by the rates, the degradation preview and guided runs. "
            "Hover the canvas to read a pixel (rate, shown values, the ground truth's) in the status bar. "
            "Wrong colours or unequal greens in the rates panel usually mean a wrong CFA or flip "
            "(File ▸ Stream settings (CFA, flip, camera profile)…)."
        )
        tips.setWordWrap(True)
        box = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.StandardButton.Close)
        box.rejected.connect(self.reject)
        box.accepted.connect(self.accept)
        keys = QtWidgets.QWidget()
        kl = QtWidgets.QVBoxLayout(keys)
        kl.addWidget(table)
        kl.addWidget(tips)
        from spikeview.recipe import help_rows

        rows = [r for r in help_rows() if r[2] != "—"]
        params = QtWidgets.QTableWidget(len(rows), 3)
        params.setObjectName("parameters_help")
        params.setHorizontalHeaderLabels(["Control", "Flag", "Meaning (unit, default)"])
        params.verticalHeader().setVisible(False)
        params.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        params.setWordWrap(True)
        for i, (_path, flag, label, text) in enumerate(rows):
            for j, v in enumerate((label, flag, text)):
                params.setItem(i, j, QtWidgets.QTableWidgetItem(v))
        params.horizontalHeader().setStretchLastSection(True)
        params.resizeColumnsToContents()
        params.resizeRowsToContents()
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(keys, "Shortcuts")
        self.tabs.addTab(params, "Parameters")
        lay = QtWidgets.QVBoxLayout(self)
        lay.addWidget(self.tabs)
        lay.addWidget(box)
        self.resize(720, 520)


def app_icon() -> QtGui.QIcon:
    """The window icon (resources/icons/spikeview.svg in the source tree, else a drawn one)."""
    from pathlib import Path

    here = Path(__file__).resolve().parents[2] / "resources" / "icons" / "spikeview.svg"
    if here.exists():
        return QtGui.QIcon(str(here))
    pm = QtGui.QPixmap(64, 64)
    pm.fill(QtGui.QColor(30, 30, 30))
    p = QtGui.QPainter(pm)
    for i, c in enumerate(((230, 60, 60), (60, 200, 60), (60, 200, 60), (70, 110, 255))):
        p.fillRect(8 + 24 * (i % 2), 8 + 24 * (i // 2), 22, 22, QtGui.QColor(*c))
    p.end()
    return QtGui.QIcon(pm)
