"""Stream panel: raw spikes, TFP and TFI of the current window, transport and display controls."""

from __future__ import annotations

from typing import Any

import numpy as np

from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.session.model import Session, format_us
from spikeview.gui.widgets import (
    ImagePane,
    RoiRect,
    ParamCheck,
    ParamCombo,
    ParamSlider,
    ParamSpin,
    set_colour_only,
    subscribe,
    tool_button,
)

SPEED_TEXT = {"realtime": "Real time", "slowmo": "Slow motion ×1/N", "window": "Every window"}


class ScrubBar(QtWidgets.QSlider):
    """The tick slider, with the marked range painted under the groove."""

    def __init__(self) -> None:
        super().__init__(QtCore.Qt.Orientation.Horizontal)
        self.marks: tuple[int | None, int | None] = (None, None)
        self.setObjectName("scrub")
        self.setToolTip("Scrub through the stream (ticks); Home/End jump to the ends, ←/→ step one tick")

    def paintEvent(self, ev: QtGui.QPaintEvent) -> None:
        lo, hi = self.marks
        if (lo is not None or hi is not None) and self.maximum() > self.minimum():
            p = QtGui.QPainter(self)
            span = self.maximum() - self.minimum()
            w = self.width() - 12
            x0 = 6 + w * ((lo if lo is not None else self.minimum()) - self.minimum()) / span
            x1 = 6 + w * ((hi if hi is not None else self.maximum()) - self.minimum()) / span
            p.fillRect(QtCore.QRectF(x0, self.height() - 5, max(x1 - x0, 2), 4), QtGui.QColor(255, 170, 0))
            p.end()
        super().paintEvent(ev)


class StreamPanel(QtWidgets.QWidget):
    """Three linked image panes and the transport (see module docstring)."""

    #: frame pixels per screen pixel changed (zoom or resize): the images should be this coarse
    display_factor_changed = QtCore.Signal(int)
    #: a sentence for the user (a white balance refused)
    error = QtCore.Signal(str)

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        st = self.style()
        # --- images
        self.raw = ImagePane("Spikes at tick")
        self.tfp = ImagePane("TFP")
        self.tfi = ImagePane("TFI")
        self.tfp.link(self.raw)
        self.tfi.link(self.raw)
        self.roi_rect = RoiRect(session, self.tfp.vb)
        self.tfi_tick: int | None = None
        self._factor = 1
        self._factor_timer = QtCore.QTimer(self, singleShot=True, interval=150)
        self._factor_timer.timeout.connect(self._check_factor)
        self.raw.vb.sigRangeChanged.connect(lambda *_: self._factor_timer.start())
        self.raw.vb.sigResized.connect(lambda *_: self._factor_timer.start())
        images = QtWidgets.QHBoxLayout()
        images.setSpacing(2)
        for pane in (self.raw, self.tfp, self.tfi):
            images.addWidget(pane, 1)

        # --- transport
        self.play_btn = tool_button("", "Play / pause (Space)", lambda: session.toggle_playing(),
                                    icon=st.standardIcon(QtWidgets.QStyle.StandardPixmap.SP_MediaPlay), name="play")
        self.home_btn = tool_button("", "First tick of the range (Home)", lambda: session.go_start(),
                                    icon=st.standardIcon(QtWidgets.QStyle.StandardPixmap.SP_MediaSkipBackward))
        self.back_btn = tool_button("", "One tick back (←)", lambda: session.step(-1),
                                    icon=st.standardIcon(QtWidgets.QStyle.StandardPixmap.SP_MediaSeekBackward), name="step_back")
        self.fwd_btn = tool_button("", "One tick forward (→)", lambda: session.step(1),
                                   icon=st.standardIcon(QtWidgets.QStyle.StandardPixmap.SP_MediaSeekForward), name="step_fwd")
        self.end_btn = tool_button("", "Last tick of the range (End)", lambda: session.go_end(),
                                   icon=st.standardIcon(QtWidgets.QStyle.StandardPixmap.SP_MediaSkipForward))
        self.scrub = ScrubBar()
        self.scrub.valueChanged.connect(lambda v: session.set_tick(v))
        self.time_label = QtWidgets.QLabel()
        self.time_label.setObjectName("time")
        self.time_label.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Preferred)
        self.time_label.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        transport = QtWidgets.QHBoxLayout()
        for w in (self.home_btn, self.back_btn, self.play_btn, self.fwd_btn, self.end_btn):
            transport.addWidget(w)
        transport.addWidget(self.scrub, 1)

        # --- playback options, window, marks
        self.speed = ParamCombo(session, "speed", SPEED_TEXT)
        self.speed.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.speed.setMinimumContentsLength(7)  # the list shows the full names
        self.slowmo = ParamSpin(session, "slowmo")
        self.slowmo.spin.setPrefix("N = ")
        self.loop = ParamCheck(session, "loop")
        self.window = ParamSpin(session, "window")
        self.mark_in = tool_button("In", "Mark the start of the range at this tick (I)", lambda: session.set_mark_in(), name="mark_in")
        self.mark_out = tool_button("Out", "Mark the end of the range at this tick (O)", lambda: session.set_mark_out(), name="mark_out")
        self.mark_clear = tool_button("×", "Clear the marked range", lambda: session.clear_marks())
        self.marks_label = QtWidgets.QLabel()
        self.roi_btn = tool_button("ROI", "Draw a region of interest: rates, degradation and guided runs use it", self._toggle_roi,
                                   checkable=True, name="roi")
        self.tfi_check = QtWidgets.QCheckBox("TFI")
        self.tfi_check.setChecked(True)
        self.tfi_check.setToolTip("Compute the TFI preview (costs time on large frames)")
        self.tfi_check.toggled.connect(self.tfi.setVisible)
        # short rows: the panel fits a narrow column beside the central image on a 1366-pixel-wide screen
        options = QtWidgets.QHBoxLayout()
        options.addWidget(QtWidgets.QLabel("Speed"))
        options.addWidget(self.speed, 1)  # narrow when the window is, its whole name when there is room
        options.addWidget(self.slowmo)
        options.addWidget(self.loop)
        window_row = QtWidgets.QHBoxLayout()
        window_row.addWidget(QtWidgets.QLabel("Window Δτ"))
        window_row.addWidget(self.window, 1)
        window_row.addWidget(self.tfi_check)
        window_row.addWidget(self.roi_btn)
        marks = QtWidgets.QHBoxLayout()
        marks.addWidget(QtWidgets.QLabel("Range"))
        for w in (self.mark_in, self.mark_out, self.mark_clear):
            marks.addWidget(w)
        marks.addWidget(self.marks_label, 1)
        self.marks_label.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Preferred)

        # --- display
        self.black = ParamSlider(session, "black", label="Black")
        self.white = ParamSlider(session, "white", label="White")
        for slider in (self.black, self.white):
            slider.label.setMinimumWidth(38)
        self.curve = ParamCombo(session, "transfer", {"auto": "Auto", "srgb": "sRGB", "gamma": "Gamma",
                                                      "linear": "Linear"})
        self.demosaic = ParamCombo(session, "demosaic", {"bilinear": "Bilinear", "malvar2004": "Malvar 2004", "menon2007": "Menon 2007"})
        self.cast = ParamCheck(session, "colour_cast", "Colour cast")
        #: controls that act only through a colour filter, with their tooltips for a colour capture
        # --- white balance: the recipe's classical.white_balance (an estimator, or fixed gains R,G,B shown and
        # editable here); Pick takes the gains that make a clicked neutral patch neutral (session.core.neutral_gains)
        from spikeview.classical.white_balance import CHOICES

        self.wb = QtWidgets.QComboBox(objectName="white_balance")
        self.wb.setEditable(True)
        self.wb.addItems(list(CHOICES))
        self.wb.setToolTip("White balance: how the colour-cast gains are estimated (auto, gray-world, gray-edge, ...), "
                           "or fixed gains R,G,B: type them, or press Pick and click a white or gray surface.")
        self.wb.lineEdit().editingFinished.connect(lambda: self._set_wb(self.wb.currentText()))
        self.wb.activated.connect(lambda _i: self._set_wb(self.wb.currentText()))
        self.wb_pick = QtWidgets.QToolButton(text="Pick", objectName="white_balance_pick", checkable=True)
        self.wb_pick.setToolTip("Click a white or gray surface on the image: its gains become the white balance.")
        #: the gains the sequence got (relative to G), the CLI's whole line (which estimator, why) as its tooltip
        self.wb_gains = QtWidgets.QLabel("", objectName="white_balance_gains")
        wb_row = QtWidgets.QHBoxLayout()
        wb_row.addWidget(QtWidgets.QLabel("White bal."))
        wb_row.addWidget(self.wb, 1)
        wb_row.addWidget(self.wb_gains)
        wb_row.addWidget(self.wb_pick)
        self.colour_only = {c: c.toolTip() for c in (self.demosaic, self.cast, self.wb, self.wb_pick)}
        curve_row = QtWidgets.QHBoxLayout()
        curve_row.addWidget(self.curve)
        curve_row.addWidget(self.demosaic, 1)
        curve_row.addWidget(self.cast)

        #: the three small image panes (spikes, TFP, TFI); the window shows them large on its central canvas
        #: and hides these (:meth:`set_images_visible`)
        self.images_box = QtWidgets.QWidget()
        self.images_box.setLayout(images)
        images.setContentsMargins(0, 0, 0, 0)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.setSpacing(3)
        lay.addWidget(self.images_box, 1)
        lay.addLayout(transport)
        lay.addWidget(self.time_label)
        lay.addLayout(options)
        lay.addLayout(window_row)
        lay.addLayout(marks)
        lay.addWidget(self.black)
        lay.addWidget(self.white)
        lay.addLayout(curve_row)
        lay.addLayout(wb_row)
        self._stretch = QtWidgets.QWidget()  # takes the spare height while the images are hidden
        lay.addWidget(self._stretch, 0)

        ev = session.events
        subscribe(self, ev.source_changed, self._on_source)
        subscribe(self, ev.tick_changed, self._on_tick)
        subscribe(self, ev.playback_changed, self._on_playback)
        subscribe(self, ev.marks_changed, self._on_marks)
        subscribe(self, ev.param_changed, self._on_param)
        subscribe(self, ev.roi_changed, self._on_roi)
        self._on_source()

    def show_white_balance(self, line: str, alpha: np.ndarray | None = None) -> None:
        """The sequence's white balance: its gains ``alpha`` relative to G beside the choice (none: monochrome or colour
        cast off), the CLI's line ``line`` (which estimator auto took, why, how far the prior moved it) as tooltip."""
        a = None if alpha is None else np.asarray(alpha, dtype=np.float64).reshape(-1)
        ok = a is not None and a.size == 3 and a[1] > 0
        self.wb_gains.setText(f"{a[0] / a[1]:.3g} : 1 : {a[2] / a[1]:.3g}" if ok else "")
        self.wb_gains.setToolTip(line or "")
        if self.wb.isEnabled():  # a monochrome capture's combo keeps its reason for being disabled
            self.wb.setToolTip((line + "\n\n" if line else "") + self.colour_only.get(self.wb, ""))

    def set_images_visible(self, on: bool) -> None:
        """Show or hide the panel's own small image panes (hidden while the central canvas shows the images)."""
        self.images_box.setVisible(on)
        lay = self.layout()
        lay.setStretchFactor(self._stretch, 0 if on else 1)

    # ------------------------------------------------------------------------------ model → view
    def _on_source(self) -> None:
        s = self.session
        with QtCore.QSignalBlocker(self.scrub):
            self.scrub.setRange(0, max(s.n_frames - 1, 0))
            self.scrub.setValue(s.tick)
            self.scrub.setPageStep(max(1, int(s.get("window"))))
        self.window.spin.setMaximum(max(1, min(4096, s.n_frames or 4096)))
        for pane in (self.raw, self.tfp, self.tfi):
            pane.set_image(None)
        self.tfi_tick = None
        set_colour_only(self.colour_only, s.source)
        self._on_tick(s.tick)
        self._on_marks(s.mark_in, s.mark_out)
        self._on_roi(s.roi)
        self._update_window_note()

    def _on_tick(self, tick: int) -> None:
        with QtCore.QSignalBlocker(self.scrub):
            self.scrub.setValue(tick)
        self.time_label.setText(self.session.time_text())

    def _on_playback(self, playing: bool) -> None:
        icon = QtWidgets.QStyle.StandardPixmap.SP_MediaPause if playing else QtWidgets.QStyle.StandardPixmap.SP_MediaPlay
        self.play_btn.setIcon(self.style().standardIcon(icon))

    def _on_marks(self, lo: int | None, hi: int | None) -> None:
        self.scrub.marks = (lo, hi)
        self.scrub.update()
        if lo is None and hi is None:
            self.marks_label.setText("no range marked")
        else:
            a, b = self.session.play_range()
            self.marks_label.setText(f"range {a}–{b} ({b - a + 1} ticks)")

    def _set_wb(self, text: str) -> None:
        """The typed or chosen white balance, checked as the CLI checks --white-balance (refused: said, and the
        control shows the setting again)."""
        from spikeview.classical.white_balance import parse_white_balance
        from spikeview.errors import ParameterError

        text = text.strip()
        if text == str(self.session.get("white_balance")):
            return
        try:
            wb = parse_white_balance(text, "White balance")
        except ParameterError as e:
            self.wb.setEditText(str(self.session.get("white_balance")))
            self.error.emit(str(e))
            return
        self.session.set("white_balance", wb if isinstance(wb, str) else ",".join(f"{v:.4g}" for v in wb))

    def pick_white(self, x: int, y: int) -> str | None:
        """Set the white balance to the gains that make the patch around frame pixel ``(x, y)`` neutral; returns the
        refusal sentence when there is one (a monochrome capture, a dark patch)."""
        from spikeview.errors import ParameterError
        from spikeview.session import core

        self.wb_pick.setChecked(False)
        s = self.session
        if s.source is None:
            return "Open a capture first."
        try:
            g = core.neutral_gains(s.source, s.tick, int(x), int(y))
        except ParameterError as e:
            return str(e)
        s.set("white_balance", ",".join(f"{v:.4g}" for v in g))
        return None

    def _on_param(self, name: str, value: Any) -> None:
        if name == "white_balance" and self.wb.currentText() != str(value):
            self.wb.setEditText(str(value))
        if name == "window":
            self.scrub.setPageStep(max(1, int(value)))
            self._update_window_note()
        if name == "speed":
            self.slowmo.setEnabled(value == "slowmo")

    def _update_window_note(self) -> None:
        s = self.session
        w = int(s.get("window"))
        self.window.note.setText(f"= {format_us(s.ticks_to_us(w))}")
        self.slowmo.setEnabled(s.get("speed") == "slowmo")

    def _check_factor(self) -> None:
        f = self.raw.display_factor()
        if f != self._factor:
            self._factor = f
            self.display_factor_changed.emit(f)

    def show_frames(self, f: Any) -> None:
        """Show a :class:`~spikeview.session.core.StreamFrames` (from the controller)."""
        self.raw.set_image(f.raw, f.shape)
        self.tfp.set_image(f.tfp, f.shape)
        if f.tfi is not None:
            self.show_tfi(f.tick, f.tfi, f.shape)
        self._factor_timer.start()
        s = self.session
        w = f.b - f.a
        self.raw.set_title(f"Spikes at tick {f.tick}")
        self.tfp.set_title(f"TFP  Δτ = {w} ticks ({format_us(s.ticks_to_us(w))}), ticks [{f.a}, {f.b})")

    def show_tfi(self, tick: int, img: Any, shape: tuple[int, int]) -> None:
        """Show the TFI pane (computed on its own thread; during playback it may trail the others)."""
        self.tfi.set_image(img, shape)
        #: the tick the TFI pane shows (during playback it is refreshed a few times a second, so it trails)
        self.tfi_tick = int(tick)
        note = "  · refreshed 5×/s while playing" if self.session.playing else ""
        reach = self.session.tfi_search()
        dark = "" if reach == int(self.session.get("tfi_half_window")) else ", a dark capture's"
        self.tfi.set_title(f"TFI at tick {tick}  (±{reach} ticks{dark}){note}")

    # ------------------------------------------------------------------------------ ROI
    def _toggle_roi(self, on: bool) -> None:
        s = self.session
        if on and s.roi is None and s.source is not None:
            w, h = s.source.width, s.source.height
            s.set_roi((w // 4 - (w // 4) % 2, h // 4 - (h // 4) % 2, max(8, w // 2), max(8, h // 2)))
        elif not on:
            s.set_roi(None)

    def _on_roi(self, roi: tuple[int, int, int, int] | None) -> None:
        with QtCore.QSignalBlocker(self.roi_btn):
            self.roi_btn.setChecked(roi is not None)
        self.roi_rect.show(roi)

    @property
    def roi_item(self) -> Any:
        """The ROI's rectangle on the TFP pane (``None`` without an ROI)."""
        return self.roi_rect.item
