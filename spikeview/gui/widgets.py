"""Small Qt widgets shared by the panels: image panes and parameter editors bound to the session.

Binding rule (napari style): a widget writes to the :class:`~spikeview.session.model.Session` with
``session.set(name, value)`` and reads back only through ``session.events.param_changed``; it
keeps no state of its own. A slider drag is one undo step (``begin_group`` on press,
``end_group`` on release).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.errors import ParameterError
from spikeview.session.model import SPECS, Session

# ------------------------------------------------------------------------------------ messages

#: command-line words in messages from the core, and what the app calls the same thing
_APP_WORDS = (
    ("check --layout, --width and --height", "check the array layout, width and height"),
    ("check --width and --height", "check the width and height (the sidecar FILE.toml beside the capture sets "
                                   "them; without one, File ▸ Open… asks)"),
    ("drop --width/--height or change --format", "change the width, height or format"),
    ("pass --format, --width and --height to be explicit", "choose the format, width and height in the Open dialog"),
    ("pass --width and --height (and --format if it is not plain)", "choose the width and height in the Open dialog"),
    ("check --format", "check the file format"),
    ("read as monochrome (--cfa none)", "read as monochrome (CFA none)"),
    ("as behind a colour filter: pass --cfa ", "as behind a colour filter: choose CFA "),
    (" (or --cfa ", " in File ▸ Stream settings (CFA, flip, camera profile)… (or "),
    ("--tag-check lenient (tag_check='lenient')", "lenient tag checking (tag_check = \"lenient\" in the sidecar)"),
)


def app_words(message: str) -> str:
    """``message`` with the command-line flags the core names replaced by what the app shows.

    The core (readers, writers) speaks the command line's language ("check --width and --height");
    in the app the same advice must name controls and menus that exist.
    """
    for cli, app in _APP_WORDS:
        message = message.replace(cli, app)
    if "--" not in message:
        return message
    import re

    controls = _flag_controls()

    def control(m: re.Match[str]) -> str:
        name = controls.get(m.group(0))
        return f"the {name} control" if name else m.group(0)

    # any other flag of a parameter: the control that sets it (a preset-only one keeps its flag: the README names it)
    return re.sub(r"--[a-z][a-z0-9-]*", control, message)


def _flag_controls() -> dict[str, str]:
    """Command-line flag → the app control's label, for every parameter that has a control (the recipe's help rows)."""
    from spikeview.recipe import help_rows

    return {row[1]: row[2] for row in help_rows() if row[2] and row[2] != "—"}


# ------------------------------------------------------------------------------------- images


class ElidedLabel(QtWidgets.QLabel):
    """A one-line label that shortens its text with "…" when it does not fit (never cut mid-word by the
    edge) and then shows the full text as its tooltip."""

    def __init__(self, text: str = "", parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self._full = ""
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Fixed)
        self.setText(text)

    def text(self) -> str:  # the full text (what is drawn may be shortened)
        return self._full

    def shown_text(self) -> str:
        """The text as drawn (shortened with "…" when it does not fit)."""
        return super().text()

    def setText(self, text: str) -> None:  # noqa: N802 - Qt's name
        self._full = str(text)
        self._elide()

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt's name
        super().resizeEvent(event)
        self._elide()

    def _elide(self) -> None:
        width = max(self.contentsRect().width(), 0)
        shown = self.fontMetrics().elidedText(self._full, QtCore.Qt.TextElideMode.ElideRight, width) if width else self._full
        super().setText(shown)
        self.setToolTip(self._full if shown != self._full else "")


class ImagePane(QtWidgets.QWidget):
    #: :meth:`reset_zoom` ran (Fit, double-click): a :class:`ZoomSync` fits the views of the same frame elsewhere
    zoom_reset = QtCore.Signal()

    """A titled pyqtgraph view of one uint8 image with fixed levels (0, 255), zoom and pan.

    Images are row-major ``(H, W)`` or ``(H, W, 3)`` uint8 and are shown as they are: levels are
    fixed, never recomputed per frame. Several panes can share zoom/pan with :meth:`link`.
    """

    def __init__(self, title: str, parent: QtWidgets.QWidget | None = None, *, min_size: int = 120):
        super().__init__(parent)
        self.title = ElidedLabel(title)
        self.title.setObjectName("paneTitle")
        self.title.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        # a new title (tick, step…) must not re-layout the panel: its size does not follow the text
        self.title.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Fixed)
        self.view = pg.GraphicsView()
        self.view.setBackground(pg.mkColor(24, 24, 24))
        self.vb = pg.ViewBox(lockAspect=True, invertY=True, enableMenu=False)
        self.view.setCentralItem(self.vb)
        # no pyqtgraph auto-downsampling (a numpy mean in the GUI thread, tens of ms per 1000×1000
        # frame): big images arrive downsampled from the worker, see ``display_factor``
        self.item = pg.ImageItem(axisOrder="row-major")
        self.vb.addItem(self.item)
        self.view.setMinimumSize(min_size, min_size * 3 // 4)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(1, 1, 1, 1)
        lay.setSpacing(1)
        lay.addWidget(self.title)
        lay.addWidget(self.view, 1)
        self._shape: tuple[int, ...] | None = None
        #: panes that zoom and pan together (see :meth:`link`); they share one fit state
        self._group: list[ImagePane] = [self]
        #: while True the view shows the whole image and follows size changes; a zoom or pan by the user
        #: ends it, :meth:`reset_zoom` (double-click) brings it back
        self.fit = True
        self.vb.sigRangeChangedManually.connect(self._user_zoomed)
        self.vb.sigResized.connect(self._resized)
        self.view.setToolTip("Wheel: zoom · drag: pan · double-click: fit the whole image")
        self.view.mouseDoubleClickEvent = self._double_click  # type: ignore[method-assign]

    def set_image(self, img: np.ndarray | None, extent: tuple[int, int] | None = None) -> None:
        """Show ``img`` (uint8) with levels (0, 255); ``None`` clears the pane.

        ``extent = (H, W)``: the image is a downsampled view of an ``H × W`` frame and is
        stretched over it, so coordinates (zoom, ROI) stay in frame pixels.
        """
        if img is None:
            self.item.clear()
            self._shape = None
            return
        img = np.asarray(img)
        if img.dtype != np.uint8:
            raise ParameterError(f"ImagePane shows uint8 images, got {img.dtype}; convert with to_display first.")
        h, w = extent if extent is not None else img.shape[:2]
        self.item.setImage(img, autoLevels=False, levels=(0, 255))
        self.item.setRect(QtCore.QRectF(0, 0, w, h))
        if self._shape != (h, w):
            self._shape = (h, w)
            if self.fit or not any(p is not self and p._shape == (h, w) for p in self._group):
                self.fit_view()  # a new frame size: the old zoom means nothing

    # --- zoom: fit unless the user zoomed --------------------------------------------------
    def fit_view(self) -> None:
        """Show the whole image (the panes linked to this one follow)."""
        if self._shape is None or not self.isVisible() or self.vb.width() < 2 or self.vb.height() < 2:
            return  # hidden or not laid out yet: done on the next resize
        h, w = self._shape
        self.vb.setRange(QtCore.QRectF(0, 0, w, h), padding=0.01)

    def reset_zoom(self) -> None:
        """Back to fitting the whole image, for this pane and the ones linked to it."""
        for p in self._group:
            p.fit = True
        for p in self._group:
            p.fit_view()
        self.zoom_reset.emit()

    def covers_image(self) -> bool:
        """Whether the view shows the whole image and the image fills at least half of it (tests, asserts)."""
        if self._shape is None:
            return True
        h, w = self._shape
        (x0, x1), (y0, y1) = self.vb.viewRange()
        whole = x0 <= 0.5 and y0 <= 0.5 and x1 >= w - 0.5 and y1 >= h - 0.5
        return whole and max(w / (x1 - x0), h / (y1 - y0)) >= 0.5

    def _user_zoomed(self, *_: Any) -> None:
        for p in self._group:
            p.fit = False

    def _resized(self, *_: Any) -> None:
        if self.fit:
            QtCore.QTimer.singleShot(0, self.fit_view)  # after the layout settles (linked views resize in turn)

    def showEvent(self, ev: QtGui.QShowEvent) -> None:  # noqa: N802 - Qt's name
        """A pane shown again (its tab brought to the front) fits the image it received while hidden."""
        super().showEvent(ev)
        if self.fit:
            QtCore.QTimer.singleShot(0, self.fit_view)

    def _double_click(self, ev: QtGui.QMouseEvent) -> None:
        self.reset_zoom()
        ev.accept()

    def display_factor(self) -> int:
        """How many frame pixels share one screen pixel now (1 when zoomed in)."""
        if self._shape is None or self.vb.width() <= 0:
            return 1
        try:
            px = self.vb.viewPixelSize()
        except (TypeError, RuntimeError, ZeroDivisionError):  # no view geometry yet (hidden): full resolution
            return 1
        return max(1, int(min(px[0], px[1])))

    def image(self) -> np.ndarray | None:
        return self.item.image

    def link(self, other: ImagePane) -> None:
        """Zoom and pan together with ``other`` (and everything linked to it)."""
        self.vb.setXLink(other.vb)
        self.vb.setYLink(other.vb)
        group = other._group
        for p in self._group:
            if p not in group:
                group.append(p)
            p._group = group

    def unlink(self) -> None:
        """Zoom and pan on its own again (the others of its group stay linked to each other)."""
        self.vb.setXLink(None)
        self.vb.setYLink(None)
        if self in self._group:
            self._group.remove(self)
        self._group = [self]

    def set_title(self, text: str) -> None:
        self.title.setText(text)


# --------------------------------------------------------------------------------- parameters


class RoiRect:
    """The session's region of interest drawn as a draggable rectangle on one view box: :meth:`show` follows the
    session's ROI (without echoing it back), a drag sets it (2-pixel snaps: one Bayer period)."""

    def __init__(self, session: Any, vb: Any, z: float | None = None):
        self.session, self.vb, self.z = session, vb, z
        self.item: Any = None

    def show(self, roi: tuple[int, int, int, int] | None) -> None:
        import pyqtgraph as pg

        if roi is None:
            if self.item is not None:
                self.vb.removeItem(self.item)
                self.item = None
            return
        x, y, w, h = roi
        if self.item is None:
            self.item = pg.RectROI((x, y), (w, h), pen=pg.mkPen((255, 200, 0), width=2), snapSize=2.0,
                                   translateSnap=True, scaleSnap=True)
            if self.z is not None:
                self.item.setZValue(self.z)
            self.item.sigRegionChangeFinished.connect(self._moved)
            self.vb.addItem(self.item)
        else:
            with QtCore.QSignalBlocker(self.item):
                self.item.setPos((x, y), update=False, finish=False)
                self.item.setSize((w, h), update=True, finish=False)

    def _moved(self, item: Any) -> None:
        pos, size = item.pos(), item.size()
        self.session.set_roi((pos.x(), pos.y(), size.x(), size.y()))


def subscribe(widget: QtCore.QObject, event: Any, callback: Any) -> None:
    """Connect ``callback`` to a session ``event`` for as long as ``widget`` lives."""
    event.connect(callback)
    widget.destroyed.connect(lambda *_, e=event, cb=callback: e.disconnect(cb))


#: tooltip of a control that acts only through a colour filter, on a monochrome capture
MONO_TIP = ("No effect on a monochrome capture (CFA none): without a colour filter there is nothing to demosaic and "
            "no colour cast to correct.")


def set_colour_only(controls: dict[QtWidgets.QWidget, str], source: Any) -> bool:
    """Enable ``controls`` (control → its tooltip for a colour capture) for a capture with a colour filter (or
    none open); disable them, saying why, for a monochrome one. Returns whether the capture has colour."""
    colour = source is None or getattr(source, "cfa", None) is not None
    for control, tip in controls.items():
        control.setEnabled(colour)
        control.setToolTip(tip if colour else MONO_TIP)
    return colour


class ParamSlider(QtWidgets.QWidget):
    """Label, slider and spin box for a numeric parameter; one drag = one undo step."""

    RESOLUTION = 1000

    def __init__(self, session: Session, name: str, parent: QtWidgets.QWidget | None = None, *, label: str | None = None):
        super().__init__(parent)
        self.session, self.name = session, name
        spec = self.spec = SPECS[name]
        self.is_int = spec.kind is int
        lo, hi = float(spec.minimum), float(spec.maximum)
        self.label = QtWidgets.QLabel(label or spec.label)
        self.label.setToolTip(spec.help)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.slider.setObjectName(f"slider_{name}")
        self.slider.setToolTip(spec.help)
        if self.is_int:
            self.slider.setRange(int(lo), int(min(hi, lo + 10 * self.RESOLUTION)))
            self.spin: QtWidgets.QAbstractSpinBox = QtWidgets.QSpinBox()
            self.spin.setRange(int(lo), int(hi))
        else:
            self.slider.setRange(0, self.RESOLUTION)
            self.spin = QtWidgets.QDoubleSpinBox()
            self.spin.setRange(lo, hi)
            step = spec.step or (hi - lo) / 100
            self.spin.setSingleStep(step)
            self.spin.setDecimals(max(0, min(4, int(np.ceil(-np.log10(step))) + 1)) if step < 1 else 1)
        self.spin.setObjectName(f"spin_{name}")
        self.spin.setKeyboardTracking(False)
        if spec.unit:
            self.spin.setSuffix(f" {spec.unit}")
        self.spin.setMinimumWidth(72)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.label)
        lay.addWidget(self.slider, 1)
        lay.addWidget(self.spin)
        self.slider.sliderPressed.connect(lambda: session.begin_group(spec.label))
        self.slider.sliderReleased.connect(session.end_group)
        self.slider.valueChanged.connect(self._from_slider)
        self.spin.valueChanged.connect(self._from_spin)
        subscribe(self, session.events.param_changed, self._on_param)
        self._show(session.get(name))

    # slider positions ↔ values
    def _to_pos(self, v: float) -> int:
        if self.is_int:
            return int(min(max(v, self.slider.minimum()), self.slider.maximum()))
        lo, hi = float(self.spec.minimum), float(self.spec.maximum)
        return round((v - lo) / (hi - lo) * self.RESOLUTION)

    def _from_pos(self, p: int) -> float:
        if self.is_int:
            return int(p)
        lo, hi = float(self.spec.minimum), float(self.spec.maximum)
        v = lo + (hi - lo) * p / self.RESOLUTION
        step = self.spec.step
        return float(min(max(round(v / step) * step, lo), hi)) if step else v

    def _from_slider(self, p: int) -> None:
        self._write(self._from_pos(p))

    def _from_spin(self, v: float) -> None:
        self._write(int(v) if self.is_int else float(v))

    def _write(self, v: Any) -> None:
        try:
            self.session.set(self.name, v)
        except ParameterError as e:
            self.session.events.message.emit(str(e))
            self._show(self.session.get(self.name))

    def _on_param(self, name: str, value: Any) -> None:
        if name == self.name:
            self._show(value)

    def _show(self, value: Any) -> None:
        with QtCore.QSignalBlocker(self.slider), QtCore.QSignalBlocker(self.spin):
            self.slider.setValue(self._to_pos(value))
            self.spin.setValue(value)

    def set_value(self, value: Any) -> None:
        """Set as a user would by dragging the slider to ``value`` (one undo step)."""
        self.session.begin_group(self.spec.label)
        try:
            self._write(value)
        finally:
            self.session.end_group()


class ParamCombo(QtWidgets.QComboBox):
    """A combo box over a parameter's choices (``texts`` maps choice → shown text)."""

    def __init__(self, session: Session, name: str, texts: dict[str, str] | None = None,
                 parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session, self.name = session, name
        self.setObjectName(f"combo_{name}")
        spec = SPECS[name]
        self.setToolTip(spec.help)
        for c in spec.choices:
            self.addItem((texts or {}).get(c, c), c)
        self.currentIndexChanged.connect(self._changed)
        subscribe(self, session.events.param_changed, self._on_param)
        self._on_param(name, session.get(name))

    def _changed(self, idx: int) -> None:
        if idx >= 0:
            self.session.set(self.name, self.itemData(idx))

    def _on_param(self, name: str, value: Any) -> None:
        if name == self.name:
            with QtCore.QSignalBlocker(self):
                self.setCurrentIndex(max(self.findData(value), 0))


class ParamCheck(QtWidgets.QCheckBox):
    """A check box for a boolean parameter."""

    def __init__(self, session: Session, name: str, text: str | None = None, parent: QtWidgets.QWidget | None = None):
        super().__init__(text or SPECS[name].label, parent)
        self.session, self.name = session, name
        self.setObjectName(f"check_{name}")
        self.setToolTip(SPECS[name].help)
        self.toggled.connect(lambda v: self.session.set(self.name, bool(v)))
        subscribe(self, session.events.param_changed, self._on_param)
        self._on_param(name, session.get(name))

    def _on_param(self, name: str, value: Any) -> None:
        if name == self.name:
            with QtCore.QSignalBlocker(self):
                self.setChecked(bool(value))


class ParamSpin(QtWidgets.QWidget):
    """A spin box for a numeric parameter (no slider), with an optional live note beside it."""

    def __init__(self, session: Session, name: str, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session, self.name = session, name
        spec = SPECS[name]
        if spec.kind is int:
            self.spin: QtWidgets.QAbstractSpinBox = QtWidgets.QSpinBox()
            self.spin.setRange(int(spec.minimum), int(spec.maximum))
        else:
            self.spin = QtWidgets.QDoubleSpinBox()
            self.spin.setRange(float(spec.minimum), float(spec.maximum))
            self.spin.setSingleStep(spec.step or 1.0)
        self.spin.setObjectName(f"spin_{name}")
        self.spin.setKeyboardTracking(False)
        self.spin.setToolTip(spec.help)
        if spec.unit:
            self.spin.setSuffix(f" {spec.unit}")
        self.note = QtWidgets.QLabel()
        self.note.setObjectName(f"note_{name}")
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.spin)
        lay.addWidget(self.note, 1)
        self.spin.valueChanged.connect(self._changed)
        subscribe(self, session.events.param_changed, self._on_param)
        self._on_param(name, session.get(name))

    def _changed(self, v: float) -> None:
        try:
            self.session.set(self.name, int(v) if SPECS[self.name].kind is int else float(v))
        except ParameterError as e:
            self.session.events.message.emit(str(e))

    def _on_param(self, name: str, value: Any) -> None:
        if name == self.name:
            with QtCore.QSignalBlocker(self.spin):
                self.spin.setValue(value)


def form(rows: list[tuple[str, QtWidgets.QWidget] | QtWidgets.QWidget]) -> QtWidgets.QWidget:
    """A compact form: ``(label, widget)`` pairs or full-width widgets."""
    w = QtWidgets.QWidget()
    lay = QtWidgets.QFormLayout(w)
    lay.setContentsMargins(4, 2, 4, 2)
    lay.setVerticalSpacing(3)
    lay.setFieldGrowthPolicy(QtWidgets.QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
    for r in rows:
        if isinstance(r, tuple):
            lay.addRow(r[0], r[1])
        else:
            lay.addRow(r)
    return w


def hbox(*items: QtWidgets.QWidget | tuple[QtWidgets.QWidget, int]) -> QtWidgets.QWidget:
    """A widget holding ``items`` in one row without margins; ``(widget, stretch)`` gives one a stretch factor."""
    w = QtWidgets.QWidget()
    lay = QtWidgets.QHBoxLayout(w)
    lay.setContentsMargins(0, 0, 0, 0)
    for item in items:
        widget, stretch = item if isinstance(item, tuple) else (item, 0)
        lay.addWidget(widget, stretch)
    return w


def job_controls(name: str, run_text: str, run_tip: str, on_run: Any, on_cancel: Any, unit: str,
                 idle: str = "") -> tuple[QtWidgets.QPushButton, QtWidgets.QPushButton, QtWidgets.QProgressBar, QtWidgets.QLabel]:
    """The controls of a panel's background job: run and cancel buttons, a progress bar counting ``unit``, a status line.

    Their object names are ``{name}_run``, ``{name}_cancel``, ``{name}_progress`` and ``{name}_status``;
    cancel starts disabled and the status line shows ``idle``.
    """
    run = QtWidgets.QPushButton(run_text)
    run.setObjectName(f"{name}_run")
    run.setToolTip(run_tip)
    run.clicked.connect(on_run)
    cancel = QtWidgets.QPushButton("Cancel")
    cancel.setObjectName(f"{name}_cancel")
    cancel.setEnabled(False)
    cancel.clicked.connect(on_cancel)
    progress = QtWidgets.QProgressBar()
    progress.setObjectName(f"{name}_progress")
    progress.setFormat(f"%v / %m {unit}")
    progress.setValue(0)
    status = QtWidgets.QLabel(idle)
    status.setObjectName(f"{name}_status")
    status.setWordWrap(True)
    return run, cancel, progress, status


def tool_button(text: str, tip: str, slot: Any, *, icon: QtGui.QIcon | None = None, checkable: bool = False,
                name: str | None = None) -> QtWidgets.QToolButton:
    b = QtWidgets.QToolButton()
    b.setText(text)
    b.setToolTip(tip)
    b.setAutoRaise(False)
    if icon is not None:
        b.setIcon(icon)
    b.setCheckable(checkable)
    if name:
        b.setObjectName(name)
    if slot is not None:
        (b.toggled if checkable else b.clicked).connect(slot)
    return b


class ZoomSync(QtCore.QObject):
    """Zoom and pan shared by the views of one frame in different widgets (the canvas, the Stream panel's panes, the
    degradation panes): a zoom or pan by the user in one shows the same rectangle of frame pixels in the others that
    show an image of the same size (an ROI-sized degradation stage does not follow the whole frame), and Fit in one
    fits them all. Not pyqtgraph's view link, which lines views up by their place on the screen: fine for the panes
    of one grid (:meth:`ImagePane.link`), wrong for views in different docks."""

    def __init__(self, panes: Any, parent: QtCore.QObject | None = None):
        super().__init__(parent)
        self.panes: list[ImagePane] = list(panes)
        self._busy = False
        for p in self.panes:
            p.vb.sigRangeChangedManually.connect(lambda *_, p=p: self._follow(p))
            p.zoom_reset.connect(lambda p=p: self._fit(p))

    def _others(self, src: ImagePane) -> list[ImagePane]:
        """One shown pane per zoom group other than ``src``'s, with an image of ``src``'s size."""
        out, groups = [], [src._group]
        for p in self.panes:
            if any(p._group is g for g in groups) or p._shape is None or p._shape != src._shape or not p.isVisible():
                continue
            groups.append(p._group)
            out.append(p)
        return out

    def _follow(self, src: ImagePane) -> None:
        if self._busy:
            return
        self._busy = True
        try:
            rect = src.vb.viewRect()
            for p in self._others(src):
                for q in p._group:
                    q.fit = False
                p.vb.setRange(rect, padding=0)
        finally:
            self._busy = False

    def _fit(self, src: ImagePane) -> None:
        if self._busy:
            return
        self._busy = True
        try:
            for p in self.panes:
                if p._group is not src._group and not all(q.fit for q in p._group):
                    p.reset_zoom()
        finally:
            self._busy = False
