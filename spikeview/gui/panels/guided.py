"""Guided reconstruction panel: sampler settings, scene plan, progress, live x̂₀, PSNR/SSIM curves."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.session.model import SPECS, Session
from spikeview.gui.widgets import (
    ImagePane,
    ParamCombo,
    ParamSlider,
    ParamSpin,
    form,
    hbox,
    job_controls,
    subscribe,
)
from spikeview.gui.panels.pooling import PoolingMap

#: the live preview is redrawn at most this often during a run (ms)
DRAW_INTERVAL_MS = 100
#: the PSNR/SSIM curves are redrawn at most this often during a run (ms): re-plotting (axes, text)
#: is the costliest update of the panel, and a busy machine stretches it
PLOT_INTERVAL_MS = 500
POOLING_TIP = ("Show the pooling map: Δτ_eff per photosite of this window (how many neighbouring windows each "
               "photosite borrowed spikes from) in place of x̂₀")
TILES_TIP = "Show the per-tile plan over x̂₀: tiles skipped (green), short (amber) or fully sampled (red)"
#: outline colour of a tile by the plan's decision (the fill is the same colour, faint)
TILE_COLOURS = {"skipped": (80, 200, 120), "short": (255, 200, 0), "full": (255, 80, 80)}
RUN_COLOURS = [(255, 170, 0), (0, 190, 255), (255, 90, 160), (120, 220, 90), (200, 140, 255), (255, 230, 80)]


class GuidedPanel(QtWidgets.QWidget):
    """Controls and live view of the guided sampler (the controller runs it in its worker)."""

    run_requested = QtCore.Signal()
    cancel_requested = QtCore.Signal()
    live_toggled = QtCore.Signal(bool)
    #: the pooling map is shown (True) or hidden: the controller keeps the window's plan current while shown
    pooling_toggled = QtCore.Signal(bool)

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.s = ParamSlider(session, "s", label="s")
        self.k = ParamSlider(session, "k", label="k")
        self.levels = ParamSlider(session, "levels", label="L")
        self.t_start = ParamSlider(session, "t_start", label="t_s")
        self.t_note = QtWidgets.QLabel()
        self.steps = ParamSpin(session, "steps")
        self.seed = ParamSpin(session, "seed")
        self.chroma = ParamSpin(session, "chroma")
        self.chroma.spin.setDecimals(1)
        self.temporal = ParamSpin(session, "temporal_radius")
        self.temporal.setToolTip(SPECS["temporal_radius"].help)
        self.pool_btn = QtWidgets.QToolButton(text="Map", objectName="pooling_map_toggle", checkable=True)
        self.pool_btn.setToolTip(POOLING_TIP)
        self.pool_btn.toggled.connect(self._toggle_pooling_map)
        self.prior = ParamCombo(session, "prior", {"ffdnet": "FFDNet (embedded)", "sd": "Stable Diffusion (folder)"})
        self.guidance = ParamCombo(session, "guidance", {"hqs": "HQS (DiffPIR, fast)", "dps": "DPS (backprop)"})
        self.quantise = ParamCombo(session, "quantise", {"auto": "auto (plan)", "on": "on", "off": "off"})
        self.precision = ParamCombo(session, "precision", {"auto": "auto (fastest, same quality)",
                                                           "float32": "float32 (reference)",
                                                           "float32-fast": "float32, NNPACK",
                                                           "bfloat16-mixed": "bfloat16 at high noise"})
        # the combo's longest text must not set the panel's width (with the Tiles button beside it the window no
        # longer fitted a 1366-pixel screen): the full text shows when the list opens
        self.precision.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.precision.setMinimumContentsLength(14)
        # the chroma σ shares Q's row (a row of its own pushed Run below a 768-pixel screen): Q's text may shorten
        self.quantise.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.quantise.setMinimumContentsLength(8)
        self.tiles_btn = QtWidgets.QToolButton(text="Tiles", objectName="tile_map_toggle", checkable=True)
        self.tiles_btn.toggled.connect(lambda _on: self._draw_tiles())
        self._tile_map: dict[str, Any] | None = None
        self._tile_items: list[Any] = []
        self.model_path = QtWidgets.QLineEdit()
        self.model_path.setObjectName("model_path")
        self.model_path.setPlaceholderText("packaged FFDNet weights")
        self.model_path.editingFinished.connect(lambda: session.set("model_path", self.model_path.text().strip()))
        browse = QtWidgets.QToolButton(text="…")
        browse.setToolTip("Choose a weights folder or .pth file")
        browse.clicked.connect(self._browse_model)
        mpw = hbox((self.model_path, 1), browse)
        chroma_label = QtWidgets.QLabel("chroma σ")
        chroma_label.setToolTip(SPECS["chroma"].help)
        smallw = hbox(QtWidgets.QLabel("steps"), self.steps, QtWidgets.QLabel("seed"), self.seed)
        tw = hbox((self.t_start, 1), self.t_note)
        settings = form([self.s, self.k, self.levels, tw, ("", smallw), ("Prior", self.prior), ("Weights", mpw),
                         ("Guidance", self.guidance), ("Q", hbox((self.quantise, 1), chroma_label, self.chroma)),
                         ("Precision", hbox((self.precision, 1), self.tiles_btn)),
                         ("Neighbours ±", hbox((self.temporal, 1), self.pool_btn))])
        #: recipe path → the control of that knob (disabled with the plan's reason when it cannot act)
        self.knob_controls = {"guided.s": self.s, "guided.k": self.k, "guided.levels": self.levels,
                              "guided.t_start": self.t_start, "guided.temporal_radius": self.temporal,
                              "guided.chroma": self.chroma}

        self.run_btn, self.cancel_btn, self.progress, self.status = job_controls(
            "guided", "Run", "Reconstruct the current window (the ROI when one is drawn)", self.run_requested,
            self.cancel_requested, "steps", idle="Idle.")
        self.live = QtWidgets.QCheckBox("Restart on change")
        self.live.setToolTip("Re-run automatically (after a short pause) whenever a setting changes")
        self.live.toggled.connect(self.live_toggled)
        # not the widths of their texts: the panel must fit beside the others on a 1366-pixel screen
        self.progress.setMinimumWidth(90)
        for b in (self.run_btn, self.cancel_btn):
            b.setMinimumWidth(56)
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(self.run_btn)
        buttons.addWidget(self.cancel_btn)
        buttons.addWidget(self.live)
        buttons.addWidget(self.progress, 1)

        self.plan = QtWidgets.QPlainTextEdit()
        self.plan.setObjectName("plan")
        self.plan.setReadOnly(True)
        self.plan.setPlaceholderText("The scene plan (which stages this window needs, and why) appears when a run starts.")
        self.plan.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.plan.setMaximumHeight(110)
        self.plan.setMinimumHeight(44)  # two lines and a scroll bar on a 768-pixel-high screen
        self.preview = ImagePane("x̂₀ (clean estimate)", min_size=120)
        self.pooling_map = PoolingMap()  # shown in place of x̂₀ by the "Map" button
        self.pooling_map.setVisible(False)
        self.psnr_plot = pg.PlotWidget()
        self.psnr_plot.setObjectName("psnr_plot")
        self.psnr_plot.setLabel("left", "PSNR (dB)")
        # the time axis is labelled once, under the SSIM plot (the two share it): a label between the plots ran into
        # the SSIM plot's title on a small screen
        self.psnr_plot.setMenuEnabled(False)
        self.ssim_plot = pg.PlotWidget()
        self.ssim_plot.setObjectName("ssim_plot")
        self.ssim_plot.setLabel("left", "SSIM")
        self.ssim_plot.setLabel("bottom", "elapsed (s)")
        self.ssim_plot.setMenuEnabled(False)
        self.ssim_plot.setXLink(self.psnr_plot)
        for plot in (self.psnr_plot, self.ssim_plot):
            plot.disableAutoRange()  # ranges grow in coarse steps (see _fit_ranges)
            plot.getAxis("left").enableAutoSIPrefix(False)
            plot.getAxis("left").setWidth(58)  # fixed: new tick labels do not re-layout the plot; room for "100.0" and the title
        self.psnr_plot.addLegend(offset=(-5, -5), labelTextSize="7pt")
        self.clear_btn = QtWidgets.QToolButton(text="Clear curves")
        self.clear_btn.clicked.connect(self.clear_curves)
        self.metrics_box = QtWidgets.QWidget()
        ml = QtWidgets.QVBoxLayout(self.metrics_box)
        ml.setContentsMargins(0, 0, 0, 0)
        ml.setSpacing(1)
        ml.addWidget(self.psnr_plot)
        ml.addWidget(self.ssim_plot)
        ml.addWidget(self.clear_btn, 0, QtCore.Qt.AlignmentFlag.AlignRight)
        live = QtWidgets.QHBoxLayout()
        live.addWidget(self.preview, 1)
        live.addWidget(self.pooling_map, 1)
        live.addWidget(self.metrics_box, 1)

        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.addWidget(settings)
        lay.addLayout(buttons)
        lay.addWidget(self.status)
        lay.addWidget(self.plan)
        lay.addLayout(live, 1)

        self.curves: dict[int, tuple[Any, Any, list[float], list[float], list[float]]] = {}
        self._pending: list[Any] = []
        self._draw_timer = QtCore.QTimer(self, singleShot=True, interval=DRAW_INTERVAL_MS)
        self._draw_timer.timeout.connect(self._flush)
        self._last_plot = 0.0
        self._ranges: dict[str, Any] = {}
        subscribe(self, session.events.param_changed, self._on_param)
        subscribe(self, session.events.source_changed, self._on_source)
        self._on_param("t_start", session.get("t_start"))
        self._on_param("model_path", session.get("model_path"))
        self._on_source()

    # ------------------------------------------------------------------------------ model → view
    def _on_param(self, name: str, value: Any) -> None:
        if name == "t_start":
            self.t_note.setText(f"σ = {255 * value:.0f}/255")
        elif name == "steps" and not self.cancel_btn.isEnabled():  # idle: a run sets its own range
            self._idle_progress()
        elif name == "model_path":
            self.model_path.setText(value)
        elif name == "temporal_radius" and not self.pool_btn.isEnabled():  # the next plan says whether it can act
            self.pool_btn.setEnabled(True)
            self.pool_btn.setToolTip(POOLING_TIP)
        elif name == "quantise" and getattr(self, "_knobs", None) is not None:
            # Q set on or off by hand: k follows at once (a 1000² window's plan takes seconds to come back, and
            # a k typed meanwhile into a greyed box was lost)
            self.show_knobs(self._knobs)
        elif name == "prior":
            self.model_path.setPlaceholderText("packaged FFDNet weights" if value == "ffdnet" else "folder with diffusers weights (required)")

    def show_knobs(self, knobs: dict[str, str | None]) -> None:
        """Enable each knob's control, or disable it with the plan's reason as its tooltip. Q set on or off by hand
        decides k's state before the plan of the new setting arrives (the plan follows the setting)."""
        self._knobs = dict(knobs)
        q = {"on": True, "off": False, True: True, False: False}.get(self.session.get("quantise"))  # auto: the plan's
        for path, control in self.knob_controls.items():
            why = knobs.get(path)
            if path == "guided.k" and q is not None and (why is None or why.startswith("soft quantisation Q is off")):
                why = None if q else "soft quantisation Q is off (as set); turn Q on to use k"
            control.setEnabled(why is None)
            control.setToolTip(SPECS[path.split(".")[1]].help if why is None else f"No effect on this window: {why}.")

    def show_pooling(self, pool: Any, knobs: dict[str, str | None] | None = None, tick: int | None = None,
                     image: np.ndarray | None = None) -> None:
        """Show the window's :class:`~spikeview.guided.temporal.Pooling` (the library's, from the observation
        the sampler uses) in the pooling map; without one (``temporal_radius = 0``, a capture too short)
        the "Map" button is disabled with the reason as its tooltip. ``image``: the map's image, made by the worker."""
        self.pooling_map.show_pooling(pool, knobs, tick, image)
        why = None if pool is None else self.pooling_map.why_not  # no plan yet: the button asks for one
        self.pool_btn.setEnabled(why is None)
        if pool is None:
            self.pool_btn.setToolTip(POOLING_TIP)
        elif why is None:
            self.pool_btn.setToolTip(f"Show the pooling map (Δτ_eff per photosite) in place of x̂₀: {pool.reason}")
        else:
            self.pool_btn.setToolTip(f"No pooling map for this window: {why}.")
            if self.pool_btn.isChecked():
                self.pool_btn.setChecked(False)

    def show_tiles(self, tile_map: dict[str, Any] | None, line: str = "") -> None:
        """The run's per-tile plan (:meth:`spikeview.guided.tiles.TileMap.as_dict`) for the "Tiles" overlay;
        without one the button is disabled with the plan's reason (tiles off, the frame fits in one tile…)."""
        self._tile_map = tile_map
        self.tiles_btn.setEnabled(tile_map is not None)
        if tile_map is not None:
            self.tiles_btn.setToolTip(f"{TILES_TIP}: {line}")
        elif line:
            self.tiles_btn.setToolTip(f"No tile map for this window: tiles {line}.")
        else:
            self.tiles_btn.setToolTip("No tile map yet: the plan of a guided run decides the tiles.")
        if tile_map is None and self.tiles_btn.isChecked():
            self.tiles_btn.setChecked(False)
        self._draw_tiles()

    def _draw_tiles(self) -> None:
        """Outline every tile over x̂₀, coloured by what the plan decided (skipped / short / full)."""
        for item in self._tile_items:
            self.preview.vb.removeItem(item)
        self._tile_items = []
        tm = self._tile_map
        if tm is None or not self.tiles_btn.isChecked():
            return
        th, tw = tm["shape"]
        h, w = self.preview._shape or (th, tw)  # a downsampled preview: scale the boxes to it
        sy, sx = h / th, w / tw
        for y0, y1, x0, x1, kind, steps in tm["tiles"]:
            item = QtWidgets.QGraphicsRectItem(x0 * sx, y0 * sy, (x1 - x0) * sx, (y1 - y0) * sy)
            colour = QtGui.QColor(*TILE_COLOURS[kind])
            pen = QtGui.QPen(colour)
            pen.setCosmetic(True)
            pen.setWidthF(1.5)
            item.setPen(pen)
            colour.setAlpha(28)
            item.setBrush(colour)
            item.setZValue(10)
            item.setToolTip(f"{kind}: {steps} step{'s' if steps != 1 else ''}")
            self.preview.vb.addItem(item)
            self._tile_items.append(item)

    def _toggle_pooling_map(self, on: bool) -> None:
        self.pooling_map.setVisible(on)
        self.preview.setVisible(not on)
        self.pooling_toggled.emit(bool(on))

    def _on_source(self) -> None:
        stream = self.session.stream
        sim = stream is not None and stream.is_simulated
        self.metrics_box.setVisible(sim)
        self.preview.set_image(None)
        self.plan.setPlainText("")
        self.show_pooling(None)
        self.show_tiles(None)
        # nothing of the previous capture's runs stays on screen (issue 10: its run and PSNR stayed)
        self.clear_curves()
        self.status.setText("Idle.")
        self.status.setStyleSheet("")
        self._idle_progress()

    def _idle_progress(self) -> None:
        """Idle, the bar reads 0 / (the steps set), not Qt's default 0 / 100."""
        self.progress.setRange(0, max(int(self.session.get("steps")), 1))
        self.progress.setValue(0)

    def _browse_model(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Prior weights", "", "Weights (*.pth *.safetensors *.bin *.json);;All files (*)")
        if path:
            self.session.set("model_path", path)

    # ------------------------------------------------------------------------------ results
    def set_state(self, state: str, message: str) -> None:
        running = state == "running"
        if not running:
            self._flush(final=True)
        self.cancel_btn.setEnabled(running)
        self.run_btn.setText("Restart" if running else "Run")
        self.status.setText(message)
        if state in ("failed",):
            self.status.setStyleSheet("color: #ff6060;")
        else:
            self.status.setStyleSheet("")
        if running:
            self.progress.setValue(0)

    def show_update(self, u: Any) -> None:
        """Show a :class:`~spikeview.session.jobs.GuidedUpdate` (plan text or a step).

        Steps are drawn at most every :data:`DRAW_INTERVAL_MS` (the latest preview, every metric
        point), so a fast sampler cannot keep the window busy redrawing.
        """
        if u.kind == "plan":
            self._flush()
            self.plan.setPlainText(u.text)
            self.show_knobs(u.knobs)
            if getattr(u, "pooling", None) is not None:
                self.show_pooling(u.pooling, u.knobs, image=getattr(u, "pooling_image", None))
            self.show_tiles(getattr(u, "tile_map", None), getattr(u, "tiles", ""))
            self.progress.setRange(0, max(u.total, 1))
            self.progress.setValue(0)
            return
        self._pending.append(u)
        if not self._draw_timer.isActive():
            self._draw_timer.start()

    def _flush(self, final: bool = False) -> None:
        pending, self._pending = self._pending, []
        if not pending:
            if final:
                self._redraw_curves()
            return
        u = pending[-1]
        self.progress.setRange(0, max(u.total, 1))
        self.progress.setValue(u.step)
        if u.preview is not None:
            self.preview.set_image(u.preview)
            self.preview.set_title(f"x̂₀ run {u.run}, step {u.step}/{u.total}")
        for p in pending:
            if p.psnr is not None:
                self._add_point(p.run, p.elapsed, p.psnr, p.ssim, redraw=False)
        now = time.perf_counter()
        if now - self._last_plot >= PLOT_INTERVAL_MS / 1000 or final:
            self._last_plot = now
            self._redraw_curves()

    def _redraw_curves(self) -> None:
        changed = False
        for pc, sc, ts, ps, ss in self.curves.values():
            if len(ts) != len(pc.xData if pc.xData is not None else ()):
                pc.setData(ts, ps)
                sc.setData(ts, ss)
                changed = True
        if changed:
            self._fit_ranges()

    def _fit_ranges(self) -> None:
        """Grow the axes in coarse steps (never per point): an unchanged axis is not redrawn."""
        ts = [t for c in self.curves.values() for t in c[2]]
        ps = [p for c in self.curves.values() for p in c[3] if np.isfinite(p)]
        ss = [x for c in self.curves.values() for x in c[4] if np.isfinite(x)]
        if not ts:
            return
        t_max = max(ts)
        x_hi = self._ranges.get("t", 0.0)
        if t_max > x_hi:
            x_hi = 2.0 ** np.ceil(np.log2(max(t_max, 0.5) * 1.05))  # 0.5, 1, 2, 4 … s
            self._ranges["t"] = x_hi
            self.psnr_plot.setXRange(0, x_hi, padding=0.02)
        for key, vals, plot, step in (("p", ps, self.psnr_plot, 1.0), ("s", ss, self.ssim_plot, 0.05)):
            if not vals:
                continue
            lo, hi = float(np.floor(min(vals) / step) * step), float(np.ceil(max(vals) / step) * step)
            old = self._ranges.get(key)
            if old is None or lo < old[0] or hi > old[1]:
                lo = min(lo, old[0]) if old else lo
                hi = max(hi, old[1]) if old else hi
                if hi - lo < step:
                    hi = lo + step
                self._ranges[key] = (lo, hi)
                plot.setYRange(lo, hi, padding=0.05)

    def show_result(self, r: Any) -> None:
        self._flush(final=True)
        self.preview.set_image(r.preview)
        self.preview.set_title(f"result of run {r.run} (tick {r.tick})")
        self.progress.setValue(self.progress.maximum())

    def _add_point(self, run: int, t: float, psnr: float, ssim: float | None, redraw: bool = True) -> None:
        entry = self.curves.get(run)
        if entry is None:
            for old_run, (pc, sc, *_rest) in self.curves.items():  # earlier runs fade
                c = QtGui.QColor(*RUN_COLOURS[old_run % len(RUN_COLOURS)])
                c.setAlpha(110)
                pc.setPen(pg.mkPen(c, width=1))
                sc.setPen(pg.mkPen(c, width=1))
            col = RUN_COLOURS[run % len(RUN_COLOURS)]
            # lines only: symbols are re-rendered on every update and cost the window time while a run goes on
            pc = self.psnr_plot.plot([], [], pen=pg.mkPen(col, width=2), name=f"run {run}")
            sc = self.ssim_plot.plot([], [], pen=pg.mkPen(col, width=2))
            entry = self.curves[run] = (pc, sc, [], [], [])
        pc, sc, ts, ps, ss = entry
        ts.append(t)
        ps.append(psnr)
        ss.append(ssim if ssim is not None else float("nan"))
        if redraw:
            pc.setData(ts, ps)
            sc.setData(ts, ss)

    def clear_curves(self) -> None:
        for pc, sc, *_ in self.curves.values():
            self.psnr_plot.removeItem(pc)
            self.ssim_plot.removeItem(sc)
        self.psnr_plot.plotItem.legend.clear()
        self.curves.clear()
        self._ranges.clear()
