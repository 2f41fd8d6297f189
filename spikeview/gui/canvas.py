"""The central image canvas: one large view of any image of the window, A/B comparison, the pixel readout.

The canvas is the window's central widget. It shows one of the images the app has for the current window
(:data:`SOURCES`: the spikes, TFP, TFI, the guided estimate x̂₀ live as it refines, the previous guided run,
a degradation stage, the ground truth) as **A**, and optionally a second one as **B** (:data:`MODES`): a
split with a draggable wipe line, side by side (zoom and pan shared), or the difference A − B. Every image
is placed in frame pixels (an ROI result sits over its ROI), so zoom, pan and the ROI rectangle mean the
same pixels in every view. Moving the mouse over the image reports the pixel: its firing rate, the displayed
values of A and B and the ground truth's where there is one (:attr:`ImageCanvas.readout`).

The canvas computes nothing of the physics: it shows what the workers sent (uint8 display images) and keeps
each image's scores (:func:`spikeview.session.jobs.score_frame`) for the Compare panel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from spikeview.session import core
from spikeview.session.model import Session
from spikeview.gui.widgets import ElidedLabel, ImagePane, RoiRect, subscribe, tool_button

#: what the canvas can show (key → menu text)
SOURCES = {
    "spikes": "Spikes",
    "tfp": "TFP",
    "tfi": "TFI",
    "guided": "Guided x̂₀",
    "guided_prev": "Guided, previous run",
    "truth": "Ground truth",
    "deg:mx": "Stage M X (mosaic)",
    "deg:cmx": "Stage C M X (colour cast)",
    "deg:qcmx": "Stage Q(C M X)",
    "deg:y": "Stage Y (observed TFP)",
    "deg:residual": "Stage residual √w̃ (Y − A X)",
}
#: how A and B are shown (key → menu text)
MODES = {"single": "A only", "wipe": "Split A | B (wipe)", "side": "Side by side", "diff": "Difference A − B"}
#: the difference image's display range: ± this share of the display range maps to black / white
DIFF_RANGE = 0.25
#: opacity of the context layer under a wipe (where neither A nor B covers the frame)
CONTEXT_OPACITY = 0.35
#: parameters whose change redraws the canvas's own float images (the stream images come back from the worker)
DISPLAY_PARAMS = frozenset({"black", "white", "transfer", "gamma"})
#: what the canvas shows when the app starts (and after View ▸ Reset layout)
DEFAULT_VIEW = ("tfp", "single", "guided")


@dataclass
class Shown:
    """One image the canvas can show: ``image`` uint8 ``(h, w)`` or ``(h, w, 3)`` covering ``rect = (x, y, w, h)``
    frame pixels (a downsampled stream image covers the whole frame with fewer pixels), its title, and its
    scores against the ground truth (empty without one)."""

    image: np.ndarray
    rect: tuple[int, int, int, int]
    title: str
    scores: dict[str, float] = field(default_factory=dict)
    #: the linear float frame the image shows (a guided result), redrawn when the display levels change
    data: np.ndarray | None = None
    #: the tick it is of, where it can differ from the stream's (a guided run, the truth); None: follows the stream
    tick: int | None = None

    def value_at(self, x: int, y: int) -> np.ndarray | None:
        """The displayed value at frame pixel ``(x, y)`` (one value per channel), ``None`` outside the image."""
        rx, ry, rw, rh = self.rect
        if not (rx <= x < rx + rw and ry <= y < ry + rh):
            return None
        ih, iw = self.image.shape[:2]
        return np.atleast_1d(self.image[(y - ry) * ih // rh, (x - rx) * iw // rw])

    def on_grid(self, box: tuple[int, int, int, int]) -> np.ndarray:
        """The image resampled (nearest) to the frame pixels of ``box = (x, y, w, h)``, float32 ``(h, w, 3)`` 0–255."""
        x, y, w, h = box
        rx, ry, rw, rh = self.rect
        ih, iw = self.image.shape[:2]
        rows = (np.arange(y, y + h) - ry) * ih // rh
        cols = (np.arange(x, x + w) - rx) * iw // rw
        img = self.image[rows[:, None], cols[None, :]].astype(np.float32)
        return np.repeat(img[..., None], 3, axis=-1) if img.ndim == 2 else img


def overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
    """The intersection of two ``(x, y, w, h)`` boxes, ``None`` when they do not meet."""
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    return (x0, y0, x1 - x0, y1 - y0) if x1 > x0 and y1 > y0 else None


def difference(a: Shown, b: Shown) -> Shown | None:
    """A − B of two displayed images where they overlap (mid-grey = equal, ± :data:`DIFF_RANGE` of the display
    range at black / white), ``None`` when they do not overlap."""
    box = overlap(a.rect, b.rect)
    if box is None:
        return None
    d = (a.on_grid(box) - b.on_grid(box)) / np.float32(255.0)
    return Shown(core.signed_display(d, DIFF_RANGE), box, f"{a.title} − {b.title}  (mid-grey = equal, ±{DIFF_RANGE:.0%})")


class ImageCanvas(QtWidgets.QWidget):
    """The central view (see module docstring)."""

    #: the text of the pixel under the cursor ("" when the cursor leaves the image)
    readout = QtCore.Signal(str)
    #: frame pixels per screen pixel changed (zoom or resize): the stream images should be this coarse
    display_factor_changed = QtCore.Signal(int)
    #: the shown images changed (the Compare panel's histogram and scores follow)
    changed = QtCore.Signal()
    #: a click on the image: frame pixel (x, y) (the white-balance picker)
    clicked = QtCore.Signal(int, int)

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.setObjectName("canvas")
        self.session = session
        self.images: dict[str, Shown] = {}
        #: the frame's firing rates (spikes per photosite per tick, full resolution) for the readout
        self.mosaic: np.ndarray | None = None
        self.last_readout = ""
        self._guided_origin = (0, 0)
        self._guided_run = 0
        #: the tick the classical methods' scores are of (they are kept while the tick stays)
        self._scores_tick: int | None = None
        #: comparisons received (tests and the screenshot wait on it)
        self.compares = 0
        #: the display parameters as the jobs get them (``Controller.display_params``); set by the window
        self.display_params: Any = None
        self._redisplay_timer = QtCore.QTimer(self, singleShot=True, interval=60)
        self._redisplay_timer.timeout.connect(self._redisplay)

        self.combo_a = self._source_combo("canvas_a", "A: the image the canvas shows")
        self.combo_b = self._source_combo("canvas_b", "B: the image A is compared with (split, side by side, difference)")
        self.mode = QtWidgets.QComboBox(objectName="canvas_mode")
        for key, text in MODES.items():
            self.mode.addItem(text, key)
        self.mode.setToolTip("How A and B are shown: A alone, split by a draggable line, side by side, or A − B")
        self.swap_btn = tool_button("⇄", "Swap A and B", self.swap, name="canvas_swap")
        self.fit_btn = tool_button("Fit", "Show the whole frame (Ctrl+0, or double-click the image)", self.fit,
                                   name="canvas_fit")
        self.one_btn = tool_button("1:1", "One frame pixel per screen pixel, around the centre of the view", self.one_to_one,
                                   name="canvas_1to1")
        header = QtWidgets.QHBoxLayout()
        header.setContentsMargins(2, 0, 2, 0)
        header.addWidget(QtWidgets.QLabel("A"))
        header.addWidget(self.combo_a)
        header.addWidget(self.mode)
        self.b_label = QtWidgets.QLabel("B")
        header.addWidget(self.b_label)
        header.addWidget(self.combo_b)
        header.addWidget(self.swap_btn)
        self.note = ElidedLabel()
        self.note.setObjectName("canvas_note")
        header.addWidget(self.note, 1)
        header.addWidget(self.one_btn)
        header.addWidget(self.fit_btn)

        self.a = ImagePane("A", min_size=160)
        self.b = ImagePane("B", min_size=160)
        self.b.link(self.a)
        for pane in (self.a, self.b):
            pane.title.setVisible(False)  # the header and the note say what is shown
            pane.view.scene().sigMouseMoved.connect(lambda pos, p=pane: self._hover(p, pos))
            pane.view.scene().sigMouseClicked.connect(lambda ev, p=pane: self._click(p, ev))
        # the wipe: A left of a draggable line, B right of it, each clipped to its side; under both, dimmed, the one
        # of them that covers more of the frame (the context around an ROI result)
        self.clip_left, self.wipe_left = self._clipped_layer()
        self.clip, self.wipe_item = self._clipped_layer()
        self.line = pg.InfiniteLine(angle=90, movable=True, pen=pg.mkPen((255, 200, 0), width=2),
                                    hoverPen=pg.mkPen((255, 230, 120), width=3))
        self.line.setZValue(20)
        self.line.sigPositionChanged.connect(lambda *_: self._update_clip())
        self.a.vb.addItem(self.line)
        self._line_placed = False
        self.roi_rect = RoiRect(session, self.a.vb, z=30)
        #: the pixel :meth:`point_at` reads out (a screenshot has no cursor to show it)
        self.marker = pg.ScatterPlotItem(size=18, symbol="+", pen=pg.mkPen((255, 230, 0), width=2), brush=None)
        self.marker.setZValue(40)
        self.marker.setVisible(False)
        self.a.vb.addItem(self.marker)
        panes = QtWidgets.QHBoxLayout()
        panes.setSpacing(2)
        panes.addWidget(self.a, 1)
        panes.addWidget(self.b, 1)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(1)
        lay.addLayout(header)
        lay.addLayout(panes, 1)

        self._factor = 1
        self._factor_timer = QtCore.QTimer(self, singleShot=True, interval=150)
        self._factor_timer.timeout.connect(self._check_factor)
        self.a.vb.sigRangeChanged.connect(lambda *_: self._factor_timer.start())
        self.a.vb.sigResized.connect(lambda *_: self._factor_timer.start())
        self.combo_a.currentIndexChanged.connect(lambda _i: self._refresh())
        self.combo_b.currentIndexChanged.connect(lambda _i: self._refresh())
        self.mode.currentIndexChanged.connect(lambda _i: self._refresh())
        subscribe(self, session.events.source_changed, self._on_source)
        subscribe(self, session.events.roi_changed, self._on_roi)
        subscribe(self, session.events.param_changed, self._on_param)
        subscribe(self, session.events.tick_changed, lambda _t: self._refresh_if_shown("guided", "guided_prev", "truth"))
        self.set_view(*DEFAULT_VIEW)

    def _clipped_layer(self) -> tuple[QtWidgets.QGraphicsRectItem, pg.ImageItem]:
        clip = QtWidgets.QGraphicsRectItem()
        clip.setFlag(QtWidgets.QGraphicsItem.GraphicsItemFlag.ItemClipsChildrenToShape, True)
        clip.setPen(pg.mkPen(None))
        clip.setZValue(5)
        item = pg.ImageItem(axisOrder="row-major")
        item.setParentItem(clip)
        self.a.vb.addItem(clip)
        return clip, item

    def _source_combo(self, name: str, tip: str) -> QtWidgets.QComboBox:
        c = QtWidgets.QComboBox(objectName=name)
        for key, text in SOURCES.items():
            c.addItem(text, key)
        c.setToolTip(tip)
        c.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        c.setMinimumContentsLength(12)
        return c

    # ------------------------------------------------------------------------------ what is shown
    def view(self) -> tuple[str, str, str]:
        """``(A, mode, B)`` keys of what the canvas shows."""
        return self.combo_a.currentData(), self.mode.currentData(), self.combo_b.currentData()

    def set_view(self, a: str | None = None, mode: str | None = None, b: str | None = None) -> None:
        """Show source ``a`` (:data:`SOURCES`), compared with ``b`` as ``mode`` (:data:`MODES`); ``None`` keeps one."""
        for combo, key, table in ((self.combo_a, a, SOURCES), (self.mode, mode, MODES), (self.combo_b, b, SOURCES)):
            if key is None:
                continue
            if key not in table:
                raise ValueError(f"unknown canvas view {key!r}; choose one of {', '.join(table)}")
            with QtCore.QSignalBlocker(combo):
                combo.setCurrentIndex(combo.findData(key))
        self._refresh()

    def swap(self) -> None:
        a, mode, b = self.view()
        self.set_view(b, mode, a)

    def shown(self) -> tuple[Shown | None, Shown | None]:
        """The images A and B as they stand (B ``None`` when the mode shows A alone)."""
        a, mode, b = self.view()
        return self.images.get(a), (self.images.get(b) if mode != "single" else None)

    def fit(self) -> None:
        self.a.reset_zoom()

    def one_to_one(self) -> None:
        """One frame pixel per screen pixel (the B view follows), centred where the view is centred now."""
        vb = self.a.vb
        (x0, x1), (y0, y1) = vb.viewRange()
        w, h = max(vb.width(), 1.0), max(vb.height(), 1.0)
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        self.a._user_zoomed()  # the view stays at this zoom when frames arrive, until Fit
        vb.setRange(QtCore.QRectF(cx - w / 2, cy - h / 2, w, h), padding=0)

    def _frame_shape(self) -> tuple[int, int] | None:
        src = self.session.source
        return None if src is None else (src.height, src.width)

    def _place(self, pane: ImagePane, item: pg.ImageItem, shown: Shown | None) -> None:
        if shown is None:
            item.clear()
            return
        item.setImage(shown.image, autoLevels=False, levels=(0, 255))
        item.setRect(QtCore.QRectF(*shown.rect))
        frame = self._frame_shape() or (shown.rect[1] + shown.rect[3], shown.rect[0] + shown.rect[2])
        if pane._shape != frame:
            pane._shape = frame
            pane.fit_view()

    def _refresh(self) -> None:
        a_key, mode, b_key = self.view()
        A, B = self.images.get(a_key), self.images.get(b_key)
        two = mode != "single"
        self.b_label.setEnabled(two)
        self.combo_b.setEnabled(two)
        self.swap_btn.setEnabled(two)
        self.b.setVisible(mode == "side")
        wipe = mode == "wipe"
        self.clip.setVisible(wipe)
        self.clip_left.setVisible(wipe)
        self.line.setVisible(wipe)
        self.a.item.setOpacity(CONTEXT_OPACITY if wipe else 1.0)
        missing = [SOURCES[k] for k, img in ((a_key, A), (b_key, B)) if img is None and (k == a_key or two)]
        note = ""
        if mode == "diff":
            d = difference(A, B) if A is not None and B is not None else None
            self._place(self.a, self.a.item, d)
            note = d.title if d is not None else ""
            if A is not None and B is not None and d is None:
                note = "A and B do not overlap"
        elif wipe:
            shown = [img for img in (A, B) if img is not None]
            context = max(shown, key=lambda img: img.rect[2] * img.rect[3]) if shown else None
            self._place(self.a, self.a.item, context)
            self._place(self.a, self.wipe_left, A)
            self._place(self.a, self.wipe_item, B)
            note = A.title if A is not None else ""
            self._place_line(A, B)
        else:
            self._place(self.a, self.a.item, A)
            note = A.title if A is not None else ""
            if mode == "side":
                self._place(self.b, self.b.item, B)
        if mode != "diff":
            if two and B is not None:
                note += f"   │   B: {B.title}"
        stale = sorted({img.tick for img in ((A, B) if two else (A,)) if img is not None and img.tick is not None
                        and img.tick != self.session.tick})
        if stale:
            note += f"   · of tick {', '.join(map(str, stale))}; the stream is at tick {self.session.tick}"
        if missing:
            note = (note + "   · " if note else "") + "not available yet: " + ", ".join(missing) + _hint(a_key, b_key, missing)
        self.note.setText(note)
        self.changed.emit()

    def _place_line(self, A: Shown | None, B: Shown | None) -> None:
        """The wipe line at the middle of where A and B overlap when it is first shown, or when it lies outside that
        overlap (a new ROI): a line beside an ROI result would show only one of the two."""
        if self._frame_shape() is None:
            return
        h, w = self._frame_shape()
        box = overlap(A.rect, B.rect) if A is not None and B is not None else None
        if box is None:
            box = A.rect if A is not None else B.rect if B is not None else (0, 0, w, h)
        x = float(self.line.value())
        if not self._line_placed or not box[0] < x < box[0] + box[2]:
            self._line_placed = True
            with QtCore.QSignalBlocker(self.line):
                self.line.setValue(box[0] + box[2] / 2)
        self._update_clip()

    def _update_clip(self) -> None:
        x = float(self.line.value())
        self.clip.setRect(QtCore.QRectF(x, -1e6, 2e6, 2e6 + 1e6))
        self.clip_left.setRect(QtCore.QRectF(x - 2e6, -1e6, 2e6, 2e6 + 1e6))

    # ------------------------------------------------------------------------------ images in
    def _put(self, key: str, shown: Shown | None) -> None:
        if shown is None:
            self.images.pop(key, None)
        else:
            self.images[key] = shown
        a, mode, b = self.view()
        if key == a or (mode != "single" and key == b):
            self._refresh()

    def show_frames(self, f: Any) -> None:
        """A :class:`~spikeview.session.core.StreamFrames`: the spikes and TFP (and TFI when it came with them)."""
        h, w = f.shape
        self.mosaic = f.mosaic
        full = (0, 0, w, h)
        self.images["spikes"] = Shown(f.raw, full, f"spikes at tick {f.tick}")
        old = self.images.get("tfp")
        scores = old.scores if old is not None and self._scores_tick == f.tick else {}
        self.images["tfp"] = Shown(f.tfp, full, f"TFP ticks [{f.a}, {f.b})", scores)
        if f.tfi is not None:
            self.show_tfi(f.tick, f.tfi, f.shape)
        else:
            self._refresh_if_shown("spikes", "tfp")
        self._factor_timer.start()

    def show_tfi(self, tick: int, img: Any, shape: tuple[int, int]) -> None:
        h, w = shape
        old = self.images.get("tfi")
        scores = old.scores if old is not None and self._scores_tick == tick else {}
        self.images["tfi"] = Shown(img, (0, 0, w, h), f"TFI at tick {tick}", scores)
        self._refresh_if_shown("spikes", "tfp", "tfi")

    def _refresh_if_shown(self, *keys: str) -> None:
        a, mode, b = self.view()
        if a in keys or (mode != "single" and b in keys):
            self._refresh()

    def guided_started(self, run: int, roi: tuple[int, int, int, int] | None) -> None:
        """A guided run started on ``roi``: its live previews go there."""
        shape = self._frame_shape()
        self._guided_origin = core.roi_origin(roi, shape) if shape is not None else (0, 0)

    def show_guided_update(self, u: Any) -> None:
        """A step of a guided run (:class:`~spikeview.session.jobs.GuidedUpdate`): x̂₀ as it refines."""
        if u.kind != "step" or u.preview is None:
            return
        h, w = u.preview.shape[:2]
        if u.run != self._guided_run:  # a new run: the latest result becomes the previous one
            self._new_run(u.run)
        x, y = self._guided_origin
        self._put("guided", Shown(u.preview, (x, y, w, h), f"guided run {u.run}, step {u.step}/{u.total}"))

    def _new_run(self, run: int) -> None:
        done = self.images.get("guided")
        if done is not None and done.title.startswith("guided run") and "step" not in done.title:
            self.images["guided_prev"] = Shown(done.image, done.rect, done.title, done.scores, done.data, done.tick)
        self._guided_run = run

    def show_guided_result(self, r: Any) -> None:
        """A finished run (:class:`~spikeview.session.jobs.GuidedResult`)."""
        if r.run != self._guided_run:
            self._new_run(r.run)
        x, y = int(r.origin[1]), int(r.origin[0])  # GuidedResult.origin is (y, x)
        h, w = r.preview.shape[:2]
        self._guided_origin = (x, y)
        self.images["guided"] = Shown(r.preview, (x, y, w, h), f"guided run {r.run} (tick {r.tick})", dict(r.scores),
                                      np.asarray(r.image), int(r.tick))
        if getattr(r, "truth_preview", None) is not None:
            self.images["truth"] = Shown(r.truth_preview, (x, y, w, h), f"ground truth (tick {r.tick})", tick=int(r.tick))
        self._refresh()

    def show_degradation(self, view: Any) -> None:
        """The degradation preview's stages (:class:`~spikeview.session.jobs.DegradationView`)."""
        imgs = view.result.images
        shape = self._frame_shape()
        roi = self.session.roi
        for key in ("mx", "cmx", "qcmx", "y", "residual"):
            img = imgs.get(key)
            if img is None:
                self.images.pop(f"deg:{key}", None)
                continue
            h, w = img.shape[:2]
            x, y = core.roi_origin(roi, shape) if roi is not None and shape is not None and (h, w) != shape else (0, 0)
            self.images[f"deg:{key}"] = Shown(img, (x, y, w, h), f"{SOURCES['deg:' + key][6:]} of {view.x_label}, tick {view.tick}")
        self._refresh_if_shown(*(f"deg:{k}" for k in ("mx", "cmx", "qcmx", "y", "residual")))

    def show_compare(self, v: Any) -> None:
        """Scores of the classical methods and the aligned ground truth (:class:`~spikeview.session.jobs.CompareView`)."""
        self._scores_tick = v.tick
        self.compares += 1
        for m, scores in v.scores.items():
            if m in self.images:
                self.images[m].scores = dict(scores)
        if v.truth is not None:
            h, w = v.truth.shape[:2]
            x, y = v.origin
            self.images["truth"] = Shown(v.truth, (x, y, w, h), f"ground truth (tick {v.tick})", tick=int(v.tick))
        self._refresh()

    def _on_param(self, name: str, value: Any) -> None:
        if name in DISPLAY_PARAMS:
            self._redisplay_timer.start()

    def _redisplay(self) -> None:
        """The guided results again with the display levels as they are now (as the stream images are): converted by
        ``redisplay_request(items, params)`` in a worker when the window wires one (the result comes back through
        :meth:`apply_redisplay`; a 1000² conversion is tens of ms the event loop must not wait), else here."""
        if self.display_params is None:
            return
        items = {k: img.data for k, img in self.images.items() if img.data is not None}
        if not items:
            return
        params = self.display_params()
        request = getattr(self, "redisplay_request", None)
        if request is not None:
            request(items, params)
            return
        self.apply_redisplay({k: (data, core.show(data, params)) for k, data in items.items()})

    def apply_redisplay(self, result: dict[str, Any]) -> None:
        """``{key: (data, uint8 image)}`` converted for the current levels; an image whose data changed meanwhile (a
        newer result) keeps its own."""
        changed = False
        for k, (data, image) in result.items():
            img = self.images.get(k)
            if img is not None and img.data is data:
                img.image = image
                changed = True
        if changed:
            self._refresh()

    def forget(self, *keys: str) -> None:
        for k in keys:
            self.images.pop(k, None)
        self._refresh()

    def _on_source(self) -> None:
        self.images.clear()
        self.mosaic = None
        self._scores_tick = None
        self._line_placed = False
        self._guided_run = 0
        self.a._shape = None
        self.b._shape = None
        self.a.item.clear()
        self.b.item.clear()
        self.wipe_item.clear()
        self.wipe_left.clear()
        self._on_roi(self.session.roi)
        self._refresh()
        self.a.reset_zoom()

    # ------------------------------------------------------------------------------ ROI
    def _on_roi(self, roi: tuple[int, int, int, int] | None) -> None:
        self.roi_rect.show(roi)

    @property
    def roi_item(self) -> Any:
        """The ROI's rectangle on pane A (``None`` without an ROI)."""
        return self.roi_rect.item

    # ------------------------------------------------------------------------------ readout
    def _check_factor(self) -> None:
        f = self.a.display_factor()
        if f != self._factor:
            self._factor = f
            self.display_factor_changed.emit(f)

    def point_at(self, x: int, y: int) -> str:
        """Read out frame pixel ``(x, y)`` as if the cursor were on it, and mark it; returns the text."""
        self.marker.setData([x + 0.5], [y + 0.5])
        self.marker.setVisible(True)
        text = self.pixel_text(int(x), int(y))
        self._emit_readout(text)
        return text

    def _hover(self, pane: ImagePane, pos: Any) -> None:
        self.marker.setVisible(False)
        if not pane.vb.sceneBoundingRect().contains(pos):
            self._emit_readout("")
            return
        p = pane.vb.mapSceneToView(pos)
        self._emit_readout(self.pixel_text(int(np.floor(p.x())), int(np.floor(p.y()))))

    def _click(self, pane: ImagePane, ev: Any) -> None:
        pos = ev.scenePos()
        if not pane.vb.sceneBoundingRect().contains(pos):
            return
        p = pane.vb.mapSceneToView(pos)
        self.clicked.emit(int(np.floor(p.x())), int(np.floor(p.y())))

    def _emit_readout(self, text: str) -> None:
        if text != self.last_readout:
            self.last_readout = text
            self.readout.emit(text)

    def pixel_text(self, x: int, y: int) -> str:
        """The readout of frame pixel ``(x, y)``: position, firing rate, the displayed values of A and B, the truth's."""
        shape = self._frame_shape()
        if shape is None or not (0 <= x < shape[1] and 0 <= y < shape[0]):
            return ""
        parts = [f"x {x}  y {y}"]
        if self.mosaic is not None and self.mosaic.shape == shape:
            rate = float(self.mosaic[y, x])
            site = core.site_at(getattr(self.session.source, "cfa", None), x, y)
            parts.append(f"{site + ' ' if site else ''}rate {rate:.4f} spikes/tick ({rate * self.session.tick_rate / 1000:.2f} kHz)")
        a_key, mode, b_key = self.view()
        keys = [("A", a_key)] + ([("B", b_key)] if mode != "single" else [])
        if "truth" not in (a_key, b_key if mode != "single" else None):
            keys.append(("truth", "truth"))
        for name, key in keys:
            img = self.images.get(key)
            v = None if img is None else img.value_at(x, y)
            if v is None:
                continue
            label = name if name == "truth" else f"{name} {SOURCES[key].split(' (')[0]}"
            parts.append(f"{label} {_values(v, getattr(self.session.source, 'cfa', None) is None)}")
        return "   ".join(parts)


def _values(v: np.ndarray, gray: bool = False) -> str:
    """One value for a one-channel image or any image of a monochrome capture (``gray``: its RGB images are gray, and
    the readout mixed 75 with (69, 69, 69)), else (R, G, B)."""
    flat = np.asarray(v).ravel()
    if flat.size == 1 or gray:
        return str(int(flat[0]))
    return "(" + ", ".join(str(int(c)) for c in flat[:3]) + ")"


def _hint(a: str, b: str, missing: list[str]) -> str:
    names = {SOURCES[k] for k in (a, b)}
    if any(m.startswith("Guided") for m in missing if m in names):
        return " (Guided ▸ Run, Ctrl+R)"
    if SOURCES["truth"] in missing:
        return " (File ▸ Load ground truth…)"
    return ""
