"""The main window: dockable panels over one session, menus, shortcuts, status bar, settings.

Ownership: the window owns a :class:`~spikeview.session.model.Session` (the state), a
:class:`~spikeview.gui.controller.Controller` (jobs and playback) and the five panels (views).
Opening files goes through a loader worker so a slow file or the demo simulation never blocks
the window. Everything the user sets is remembered in :class:`QtCore.QSettings` (layout, last
folder, recent files, last parameters), written as soon as it changes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.errors import SpikeviewError
from spikeview.session import core
from spikeview.gui.canvas import ImageCanvas
from spikeview.gui.controller import Controller
from spikeview.gui.dialogs import ShortcutsDialog, StreamSettingsDialog, app_icon
from spikeview.session.model import OpenedStream, Session, format_us
from spikeview.gui.panels.compare import ComparePanel
from spikeview.gui.panels.degradation import DegradationPanel
from spikeview.gui.panels.export import ExportPanel
from spikeview.gui.panels.guided import GuidedPanel
from spikeview.gui.panels.rates import RatesPanel
from spikeview.gui.panels.stream import StreamPanel
from spikeview.gui.widgets import app_words
from spikeview.gui.workers import Worker, configure_runtime

#: captures whose loaded ground truth is remembered (the most recent ones)
MAX_TRUTHS = 50
MAX_RECENT = 10
#: bump when the dock layout changes incompatibly (older saved states are ignored)
LAYOUT_VERSION = 2
#: the dock column beside the central canvas: this share of the window's width, within these bounds (px)
SIDE_SHARE, SIDE_MIN, SIDE_MAX = 0.285, 320, 480
#: file suffixes offered by File ▸ Open
CAPTURE_FILTER = "Spike captures (*.dat *.bin *.raw *.npy *.npz);;All files (*)"


class NotificationBar(QtWidgets.QFrame):
    """A slim, non-modal message strip with optional action buttons (errors, finished exports).

    The strip keeps one line's height whether or not it shows a message, so a message arriving or
    going never re-lays out the window: showing it in a bar that appeared and vanished resized every
    dock and repainted every view, ~30 ms of the GUI thread at 1000×1000 (50–111 ms stalls at the end
    of an export on a loaded machine; issue 15). A text longer than the strip is elided; the whole
    text is in the tooltip and in :meth:`text`."""

    def __init__(self, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.setObjectName("notification")
        self.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        self.label = QtWidgets.QLabel()
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.label.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Fixed)
        self.label.setMinimumWidth(50)
        self.buttons = QtWidgets.QHBoxLayout()
        self.close_button = close = QtWidgets.QToolButton(text="✕")
        close.setAutoRaise(True)
        close.setToolTip("Dismiss")
        close.clicked.connect(self.dismiss)
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Fixed)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(8, 1, 4, 1)
        lay.addWidget(self.label, 1)
        lay.addLayout(self.buttons)
        lay.addWidget(close)
        # one line, the height of a push button (the tallest thing the strip holds)
        self.setFixedHeight(max(QtWidgets.QPushButton("Open").sizeHint().height(), self.label.fontMetrics().lineSpacing()) + 2)
        self.kind = ""
        self._text = ""
        self._paint("")

    def _paint(self, kind: str) -> None:
        colour = {"error": "#5a1f1f", "warning": "#574515", "info": "#1f3a57", "success": "#1f4a2a"}.get(kind, "#333")
        bg = f"background: {colour}; border-radius: 3px;" if kind else "background: transparent;"
        self.setStyleSheet(f"#notification {{ {bg} }} QLabel {{ color: #f0f0f0; }}")
        self.close_button.setVisible(bool(kind))

    def _clear_buttons(self) -> None:
        while self.buttons.count():
            w = self.buttons.takeAt(0).widget()
            if w is not None:
                w.deleteLater()

    def show_message(self, text: str, kind: str = "info", actions: list[tuple[str, Any]] | None = None) -> None:
        self._clear_buttons()
        for text_, slot in actions or []:
            b = QtWidgets.QPushButton(text_)
            b.clicked.connect(slot)
            self.buttons.addWidget(b)
        self.kind = kind or "info"
        self._text = text
        self._paint(self.kind)
        self.label.setToolTip(text)
        self._elide()

    def dismiss(self) -> None:
        self.kind = ""
        self._text = ""
        self._clear_buttons()
        self._paint("")
        self.label.setToolTip("")
        self.label.setText("")

    def _elide(self) -> None:
        fm = self.label.fontMetrics()
        self.label.setText(fm.elidedText(" ".join(self._text.split()), QtCore.Qt.TextElideMode.ElideRight, max(50, self.label.width())))

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt's name
        super().resizeEvent(event)
        self._elide()

    def is_shown(self) -> bool:
        return bool(self.kind) and self.isVisible()

    def text(self) -> str:
        return self._text if self.kind else ""



class MainWindow(QtWidgets.QMainWindow):
    """The spikeview desktop window (see module docstring)."""

    stream_opened = QtCore.Signal(object)

    def __init__(self, settings: QtCore.QSettings | None = None, session: Session | None = None):
        super().__init__()
        #: every error the notification strip has shown (:meth:`show_error`), in order
        self.errors_shown: list[str] = []
        configure_runtime()
        core.preload()  # before any worker thread starts (see core.preload)
        self.setObjectName("spikeview_main")
        self.setWindowTitle("spikeview")
        self.setWindowIcon(app_icon())
        self.setAcceptDrops(True)
        self.settings = settings if settings is not None else QtCore.QSettings("spikeview", "spikeview")
        self.session = session if session is not None else Session()
        self._restore_params()
        self.controller = Controller(self.session, self)
        self.loader = Worker("spikeview-loader", parent=self, nice=5)  # below the GUI thread (see controller.WORKER_NICE)
        self.loader.finished.connect(self._on_loaded)
        self.loader.failed.connect(self._on_load_failed)
        self.settings_dialog: StreamSettingsDialog | None = None
        self._closing = False

        # --- panels in docks
        s = self.session
        self.stream_panel = StreamPanel(s)
        self.rates_panel = RatesPanel(s)
        self.degradation_panel = DegradationPanel(s)
        self.guided_panel = GuidedPanel(s)
        self.export_panel = ExportPanel(s)
        # the image, large: the window's central widget; the panels are docks around it
        self.canvas = ImageCanvas(s)
        self.setCentralWidget(self.canvas)
        self.compare_panel = ComparePanel(s, self.canvas)
        self.stream_panel.set_images_visible(False)  # the canvas shows the spikes, TFP and TFI
        # every view of the capture's frame zooms and pans with the others (ZoomSync; within a panel, its link)
        from spikeview.gui.widgets import ZoomSync

        self.zoom_sync = ZoomSync([self.canvas.a, self.stream_panel.raw, *self.degradation_panel.panes.values()], self)
        self.docks: dict[str, QtWidgets.QDockWidget] = {}  # the panels default_layout places
        self.file_menu: QtWidgets.QMenu | None = None
        self.view_menu: QtWidgets.QMenu | None = None
        # short titles: the tabs of one column show them whole
        for key, title, panel in (("stream", "Stream", self.stream_panel), ("guided", "Guided", self.guided_panel),
                                  ("compare", "Compare", self.compare_panel), ("export", "Export", self.export_panel),
                                  ("rates", "Rates", self.rates_panel), ("degradation", "Degradation", self.degradation_panel)):
            self.add_panel(key, title, panel)
        self.setDockNestingEnabled(True)
        self.default_layout()
        self.notice = NotificationBar()
        bar = QtWidgets.QToolBar("Notifications")
        bar.setObjectName("notification_bar")
        bar.setMovable(False)
        bar.setFloatable(False)
        bar.addWidget(self.notice)  # always shown: the strip keeps its height (NotificationBar)
        bar.toggleViewAction().setVisible(False)
        self.addToolBar(QtCore.Qt.ToolBarArea.BottomToolBarArea, bar)

        # --- status bar
        sb = self.statusBar()
        self.time_status = QtWidgets.QLabel(objectName="status_time")
        self.rate_status = QtWidgets.QLabel(objectName="status_rate")
        self.fps_status = QtWidgets.QLabel(objectName="status_fps")
        for w in (self.time_status, self.rate_status, self.fps_status):
            w.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
            sb.addPermanentWidget(w)
        self.fps_timer = QtCore.QTimer(self, interval=500)
        self.fps_timer.timeout.connect(self._update_fps)
        self.fps_timer.start()

        self._make_actions()
        self._connect()
        self._restore_layout()
        self.export_panel.set_folder(self.settings.value("last_export_dir", "", str) or None)
        self._params_timer = QtCore.QTimer(self, singleShot=True, interval=500)
        self._params_timer.timeout.connect(self._save_params)
        # everything loaded so far (torch, numba, pyqtgraph, the widgets) out of the collector's reach now,
        # before the window shows: the first collection after opening a file otherwise walked all of it on
        # the GUI thread (a 270 ms freeze at the first 1000×1000 open; issue 15)
        Controller.settle_heap()

    # ------------------------------------------------------------------------------ layout
    def add_panel(self, key: str, title: str, widget: QtWidgets.QWidget, *, beside: str | None = None) -> QtWidgets.QDockWidget:
        """Put ``widget`` in a dockable panel named ``dock_<key>``; how every panel joins the window.

        Without ``beside`` the panel is one of :attr:`docks`, placed by :meth:`default_layout`. With it
        (a panel added after the window is built, such as live capture) the panel goes where the
        saved layout had it, else in a tab beside the panel ``beside``, and its toggle heads the
        View menu.
        """
        dock = QtWidgets.QDockWidget(title, self)
        dock.setObjectName(f"dock_{key}")
        dock.setWidget(scrolled(widget))
        dock.setFeatures(QtWidgets.QDockWidget.DockWidgetFeature.DockWidgetMovable
                         | QtWidgets.QDockWidget.DockWidgetFeature.DockWidgetFloatable
                         | QtWidgets.QDockWidget.DockWidgetFeature.DockWidgetClosable)
        if beside is None:
            self.docks[key] = dock
            return dock
        if not self.restoreDockWidget(dock):
            below = self.docks.get(beside)
            if below is not None:  # a tab beside it: the window still fits 1366×768
                self.tabifyDockWidget(below, dock)
                below.raise_()
            else:
                self.addDockWidget(QtCore.Qt.DockWidgetArea.LeftDockWidgetArea, dock)
        if self.view_menu is not None:
            first = self.view_menu.actions()[0] if self.view_menu.actions() else None
            self.view_menu.insertAction(first, dock.toggleViewAction())
        return dock

    def add_file_action(self, action: QtGui.QAction) -> None:
        """An *Open …* entry of the File menu (above *Open recent*), with its shortcut window-wide."""
        self.addAction(action)
        self.file_menu.insertAction(self.recent_menu.menuAction(), action)

    def default_layout(self) -> None:
        """The start-up layout (View ▸ Reset layout): the canvas in the centre showing the TFP; one column of docks on
        the right, the Stream panel (transport, window, display) on top and the other panels as tabs below it, the
        Guided panel in front. The column takes 28.5 % of the window's width (320–480 px), so the canvas keeps
        about two thirds of a 1366×768 window whatever the panels hold (each panel scrolls rather than grows)."""
        from spikeview.gui.canvas import DEFAULT_VIEW

        d = self.docks
        right = QtCore.Qt.DockWidgetArea.RightDockWidgetArea
        for dock in self.findChildren(QtWidgets.QDockWidget):
            if dock not in d.values():  # a panel added later (live capture): back beside the others
                continue
            dock.setFloating(False)
            self.removeDockWidget(dock)
        self.addDockWidget(right, d["stream"])
        d["stream"].show()
        self.addDockWidget(right, d["guided"])
        self.splitDockWidget(d["stream"], d["guided"], QtCore.Qt.Orientation.Vertical)
        d["guided"].show()
        for key in ("compare", "export", "rates", "degradation"):
            self.tabifyDockWidget(d["guided"], d[key])
            d[key].show()
        for dock in self.findChildren(QtWidgets.QDockWidget):
            if dock not in d.values() and not dock.isFloating() and self.dockWidgetArea(dock) != QtCore.Qt.DockWidgetArea.NoDockWidgetArea:
                self.tabifyDockWidget(d["degradation"], dock)
        d["guided"].raise_()
        self._size_docks()
        if hasattr(self, "canvas"):
            self.canvas.set_view(*DEFAULT_VIEW)
            self.canvas.fit()
        QtCore.QTimer.singleShot(0, self._size_docks)  # again once the window has its size (first start, Reset layout)

    def tile_panels(self) -> None:
        """View ▸ Panels side by side: every panel in sight at once (no tabs), in two columns right of the canvas —
        for a large screen; on a small one the panels scroll."""
        d = self.docks
        right = QtCore.Qt.DockWidgetArea.RightDockWidgetArea
        for dock in d.values():
            dock.setFloating(False)
            self.removeDockWidget(dock)
        self.addDockWidget(right, d["stream"])
        self.splitDockWidget(d["stream"], d["compare"], QtCore.Qt.Orientation.Horizontal)
        self.splitDockWidget(d["stream"], d["guided"], QtCore.Qt.Orientation.Vertical)
        self.splitDockWidget(d["guided"], d["export"], QtCore.Qt.Orientation.Vertical)
        self.splitDockWidget(d["compare"], d["rates"], QtCore.Qt.Orientation.Vertical)
        self.splitDockWidget(d["rates"], d["degradation"], QtCore.Qt.Orientation.Vertical)
        for dock in d.values():
            dock.show()
        self._size_tiles()
        QtCore.QTimer.singleShot(0, self._size_tiles)  # again once the window has its size

    def _size_tiles(self) -> None:
        d = self.docks
        side = int(min(SIDE_MAX, max(SIDE_MIN, SIDE_SHARE * self.width())))
        self.resizeDocks([d["stream"], d["compare"]], [side, side], QtCore.Qt.Orientation.Horizontal)
        h = self.height()
        self.resizeDocks([d["compare"], d["rates"], d["degradation"]], [int(0.28 * h), int(0.24 * h), int(0.48 * h)],
                         QtCore.Qt.Orientation.Vertical)  # the degradation's six images get the most

    def _size_docks(self) -> None:
        """The default sizes of :meth:`default_layout`: the column's width from the window's, the Stream panel its
        natural height, the tabs the rest."""
        d = self.docks
        side = int(min(SIDE_MAX, max(SIDE_MIN, SIDE_SHARE * self.width())))
        self.resizeDocks([d["stream"]], [side], QtCore.Qt.Orientation.Horizontal)
        stream_h = self.stream_panel.sizeHint().height() + 40  # the title bar and the frame
        self.resizeDocks([d["stream"], d["guided"]], [stream_h, max(200, self.height() - stream_h)], QtCore.Qt.Orientation.Vertical)

    def _restore_layout(self) -> None:
        geo = self.settings.value("window/geometry")
        state = self.settings.value("window/state")
        if int(self.settings.value("window/layout_version", 0, int)) != LAYOUT_VERSION:
            state = None
        screen = QtGui.QGuiApplication.primaryScreen()
        avail = screen.availableGeometry() if screen is not None else QtCore.QRect(0, 0, 1700, 1000)
        if isinstance(geo, QtCore.QByteArray):
            self.restoreGeometry(geo)
            if self.width() > avail.width() or self.height() > avail.height():  # saved on a larger screen
                self.resize(min(self.width(), avail.width()), min(self.height(), avail.height() - 30))
        else:  # first start: large, but never larger than the screen (a 1366×768 laptop)
            self.resize(min(1700, avail.width()), min(1000, avail.height() - 30))
        if isinstance(state, QtCore.QByteArray):
            self.restoreState(state)
        else:
            QtCore.QTimer.singleShot(0, self._size_docks)

    # ------------------------------------------------------------------------------ actions
    def _action(self, menu: QtWidgets.QMenu, text: str, slot: Any, shortcut: Any = None, tip: str = "",
                checkable: bool = False, name: str | None = None) -> QtGui.QAction:
        act = QtGui.QAction(text, self)
        if shortcut is not None:
            if isinstance(shortcut, (list, tuple)):
                act.setShortcuts([QtGui.QKeySequence(k) for k in shortcut])
            else:
                act.setShortcut(QtGui.QKeySequence(shortcut))
        act.setStatusTip(tip)
        act.setCheckable(checkable)
        if name:
            act.setObjectName(name)
        (act.toggled if checkable else act.triggered).connect(slot)
        menu.addAction(act)
        self.addAction(act)  # shortcuts work even when the menu bar is hidden
        return act

    def _make_actions(self) -> None:
        mb = self.menuBar()
        K = QtGui.QKeySequence.StandardKey
        s = self.session
        f = self.file_menu = mb.addMenu("&File")
        self.act_open = self._action(f, "&Open…", self.open_dialog, K.Open, "Open a spike capture", name="act_open")
        self._action(f, "Open the &demo capture", lambda: self.open_demo(), tip="The built-in simulated capture")
        self.recent_menu = f.addMenu("Open &recent")
        self._action(f, "Stream &settings (CFA, flip, camera profile)…", self.stream_settings, "Ctrl+Shift+G", "Re-interpret the open capture")
        self._action(f, "Load &ground truth…", self.load_truth_dialog, tip="An image of the scene to score against "
                     "(a capture without .gt.npz, e.g. a Spike-Zoo clip's PNG)", name="act_load_truth")
        f.addSeparator()
        self._action(f, "&Load preset…", self.load_preset_dialog, "Ctrl+L", "Load parameters from a TOML preset")
        self._action(f, "&Save preset…", self.save_preset_dialog, K.Save, "Save the parameters as a TOML preset")
        f.addSeparator()
        self.act_export = self._action(f, "&Export", self.export_now, "Ctrl+E", "Export with the Export panel's settings", name="act_export")
        f.addSeparator()
        self._action(f, "&Quit", self.close, K.Quit)

        e = mb.addMenu("&Edit")
        self.act_undo = self._action(e, "&Undo", lambda: s.undo(), K.Undo, name="act_undo")
        self.act_redo = self._action(e, "&Redo", lambda: s.redo(), ["Ctrl+Shift+Z", "Ctrl+Y"], name="act_redo")
        self.act_undo.setEnabled(False)
        self.act_redo.setEnabled(False)
        e.addSeparator()
        self._action(e, "Reset parameters to defaults", self.reset_params)

        p = mb.addMenu("&Playback")
        self.act_play = self._action(p, "&Play / pause", lambda: s.toggle_playing(), "Space", name="act_play")
        self._action(p, "Step &back one tick", lambda: s.step(-1), "Left", name="act_back")
        self._action(p, "Step &forward one tick", lambda: s.step(1), "Right", name="act_fwd")
        self._action(p, "Back one window", lambda: s.step(-int(s.get("window"))), "Shift+Left")
        self._action(p, "Forward one window", lambda: s.step(int(s.get("window"))), "Shift+Right")
        self._action(p, "First tick of the range", lambda: s.go_start(), "Home", name="act_home")
        self._action(p, "Last tick of the range", lambda: s.go_end(), "End", name="act_end")
        p.addSeparator()
        self._action(p, "Mark &in", lambda: s.set_mark_in(), "I")
        self._action(p, "Mark &out", lambda: s.set_mark_out(), "O")
        self._action(p, "Clear marks", lambda: s.clear_marks())
        self._action(p, "&Loop", lambda: s.set("loop", not s.get("loop")), "L")

        g = mb.addMenu("&Guided")
        self._action(g, "&Run", self.controller.run_guided, "Ctrl+R", name="act_run")
        self._action(g, "&Cancel", self.controller.cancel_guided, "Escape", name="act_cancel")

        v = self.view_menu = mb.addMenu("&View")
        for dock in self.docks.values():
            v.addAction(dock.toggleViewAction())
        v.addSeparator()
        self._action(v, "&Fit images (reset zoom)", self.fit_images, "Ctrl+0",
                     "Show the whole image in every pane again (double-click a pane for one group)", name="act_fit")
        self._action(v, "Reset layout", self.default_layout, name="act_reset_layout")
        self._action(v, "Panels side by side (no tabs)", self.tile_panels, tip="Every panel in sight at once (a large screen)",
                     name="act_tile")
        v.addSeparator()
        self._action(v, "Canvas: split A | B", lambda: self.canvas.set_view(mode="wipe"), "Ctrl+\\", name="act_split")
        self._action(v, "Canvas: swap A and B", self.canvas.swap, "Ctrl+Shift+S", name="act_swap")

        h = mb.addMenu("&Help")
        self._action(h, "&Keyboard shortcuts", self.show_help, "F1", name="act_help")
        self._action(h, "&About spikeview", self.about)
        self._rebuild_recent()

    def _connect(self) -> None:
        c, s = self.controller, self.session
        c.frames_ready.connect(self._on_frames)
        c.tfi_ready.connect(self.stream_panel.show_tfi)
        c.rates_ready.connect(self.rates_panel.show_rates)
        c.alpha_history.connect(self.rates_panel.show_alpha_history)
        c.alpha_ready.connect(self.rates_panel.show_sequence_alpha)
        c.white_balance_said.connect(self.stream_panel.show_white_balance)
        c.degradation_ready.connect(self.degradation_panel.show_result)
        c.degradation_ready.connect(self.canvas.show_degradation)
        c.tfi_ready.connect(self.canvas.show_tfi)
        c.guided_started.connect(self.canvas.guided_started)
        c.guided_update.connect(self.canvas.show_guided_update)
        c.guided_done.connect(self.canvas.show_guided_result)
        c.compare_ready.connect(self.canvas.show_compare)
        self.canvas.readout.connect(self._on_readout)
        self.canvas.clicked.connect(self._on_canvas_click)
        self.stream_panel.error.connect(self.show_error)
        self.canvas.display_params = c.display_params
        self.canvas.redisplay_request = c.request_redisplay  # converted off the GUI thread
        c.redisplayed.connect(self.canvas.apply_redisplay)
        self.canvas.display_factor_changed.connect(c.set_display_factor)
        self.canvas.changed.connect(self._update_compare_wanted)
        self.docks["compare"].visibilityChanged.connect(lambda _v: self._update_compare_wanted())
        self.compare_panel.load_truth_requested.connect(self.load_truth_dialog)
        c.degradation_ready.connect(lambda view: self.guided_panel.show_knobs(view.knobs))
        c.degradation_ready.connect(lambda view: self.guided_panel.show_pooling(view.pooling, view.knobs, view.tick,
                                                                               getattr(view, "pooling_image", None)))
        self.guided_panel.pooling_toggled.connect(lambda v: c.set_enabled("pooling", v) if not self._closing else None)
        c.guided_update.connect(self.guided_panel.show_update)
        c.guided_done.connect(self.guided_panel.show_result)
        c.guided_done.connect(self.export_panel.note_guided_result)
        c.guided_state.connect(self.guided_panel.set_state)
        c.guided_state.connect(self._on_guided_state)
        c.export_progress.connect(self.export_panel.set_progress)
        c.export_state.connect(self.export_panel.set_state)
        c.export_done.connect(self._on_export_done)
        c.error.connect(self.show_error)
        self.guided_panel.run_requested.connect(c.run_guided)
        self.guided_panel.cancel_requested.connect(c.cancel_guided)
        self.guided_panel.live_toggled.connect(lambda v: setattr(c, "guided_live", bool(v)))
        self.export_panel.export_requested.connect(self.export_to)
        self.export_panel.cancel_requested.connect(c.cancel_export)
        self.stream_panel.tfi_check.toggled.connect(lambda v: c.set_enabled("tfi", v))
        for key in ("rates", "degradation"):
            self.docks[key].visibilityChanged.connect(lambda _v: self._update_compare_wanted())
        ev = s.events
        self._session_links = [(ev.tick_changed, self._on_tick), (ev.undo_changed, self._on_undo_changed),
                               (ev.param_changed, self._on_param), (ev.message, self._on_message),
                               (ev.source_changed, self._on_source)]
        for event, cb in self._session_links:
            event.connect(cb)

    # ------------------------------------------------------------------------------ opening
    def open_demo(self, size: int = core.DEMO_SIZE, n_ticks: int = core.DEMO_TICKS) -> None:
        """Simulate and open the built-in demo capture (in the background)."""
        self.statusBar().showMessage("Simulating the demo capture…")
        self.loader.submit("open", lambda ctx: ("ok", core.demo_stream(size, n_ticks), None))

    def open_path(self, path: str | os.PathLike[str], **kwargs: Any) -> None:
        """Open a capture (in the background).

        With a sidecar, or with explicit settings (a recent file), the file opens directly;
        otherwise the settings dialog asks for the geometry, CFA and flip with a live preview,
        starting from what detection found. A ``.toml`` file is loaded as a preset.
        """
        path = Path(path)
        from spikeview.io.sidecar import is_sidecar

        if path.suffix.lower() == ".toml" and not is_sidecar(path):  # a preset (a sidecar opens its spike file)
            self.load_preset(path)
            return
        self.statusBar().showMessage(f"Opening {path.name}…")

        def job(ctx: Any) -> tuple[str, Any, Any]:
            if kwargs or core.has_sidecar(path):
                return ("ok", core.open_file(path, **kwargs), None)
            return ("ask", path, core.probe_file(path))

        self.loader.submit("open", job)

    def _on_loaded(self, channel: str, job_id: int, result: Any) -> None:
        if not self.loader.is_current(channel, job_id) or self._closing:
            if isinstance(result, tuple) and result[0] == "ok" and result[1].path is not None:
                result[1].source.close()
            return
        kind, payload, extra = result
        if kind == "ask":
            initial, candidates, note = extra
            self.ask_stream_settings(payload, initial, candidates, note)
            return
        self.set_stream(payload)

    def _on_load_failed(self, channel: str, job_id: int, message: str) -> None:
        self.statusBar().clearMessage()
        self.show_error(message, dialog_title="Cannot open the capture")

    def set_stream(self, stream: OpenedStream) -> None:
        """Make ``stream`` the session's stream (closing the previous file)."""
        old = self.session.stream
        if self.notice.kind != "" and not self.controller.exporter.is_active():
            self.notice.dismiss()  # messages about the previous capture (an export error…) no longer apply
        if old is not None and old is not stream:
            # a capture's settings belong to it: nothing of the previous capture's (exposure, η, range, knobs) carries
            # over; every recipe parameter starts where the CLI starts, the white point at this capture's own
            self._reset_recipe_params("New capture: parameters at their defaults")
        self.session.open_stream(stream)
        if old is not None and old is not stream and old.path is not None and old.path != stream.path:
            old.source.close()
        if stream.path is not None:
            self._add_recent(stream.path, stream.open_kwargs)
            self.settings.setValue("last_dir", str(stream.path.parent))
        warnings = list(getattr(stream.source.info, "warnings", []) or [])
        msg = f"Opened {stream.label}: {stream.source.width}×{stream.source.height}, {stream.source.n_frames} ticks, CFA {stream.source.cfa or 'none'}."
        self.statusBar().showMessage(msg, 8000)
        if warnings:  # each reader warning already starts with the file name: say it once
            label = f"{stream.label}: "
            text = " ".join(w[len(label):] if w.startswith(label) else w for w in warnings)
            self.notice.show_message(app_words(label + text), "warning", self._geometry_actions(stream))
        self._restore_truth(stream)  # after the "Opened" line: its own line says which truth came back
        self.stream_opened.emit(stream)

    def _geometry_actions(self, stream: OpenedStream) -> list[tuple[str, Any]]:
        """The warning's button for a capture whose rows the spikes show sheared at its width
        (``info.likely_size``, the size the CLI names when it refuses to write): reopen it at the size they point to
        (the CLI's ``--width W --height H``); none for a capture in memory or one that lines up."""
        likely = getattr(stream.source.info, "likely_size", None)
        if likely is None or stream.path is None:
            return []
        path, kwargs = stream.path, {**stream.open_kwargs, "width": int(likely[0]), "height": int(likely[1])}
        return [(f"Reopen as {likely[0]}×{likely[1]}", lambda *_: self.open_path(path, **kwargs))]

    def ask_stream_settings(self, path: Path, initial: dict[str, Any] | None = None,
                            candidates: list[tuple[int, int]] | None = None, note: str = "") -> StreamSettingsDialog:
        """Show the settings dialog for a file without a sidecar (non-blocking, live preview)."""
        initial = dict(initial or {"cfa": "RGGB", "flip_vertical": True})
        msg = (f"{path.name} has no sidecar saying how to read it. Check the size, the colour filter and the flip: "
               "the preview updates as you go (a wrong width shears the rows, a wrong flip turns the picture upside down, "
               "a wrong colour filter gives wrong colours).")
        if note:
            msg += f"\n{note}"
        dlg = StreamSettingsDialog(f"Open {path.name}", lambda **kw: core.open_file(path, **kw), initial, candidates or [], msg,
                                   remember=True, parent=self)
        dlg.accepted.connect(lambda: self._accept_settings(dlg))
        dlg.finished.connect(lambda *_: setattr(self, "settings_dialog", None))
        self.settings_dialog = dlg
        self.statusBar().clearMessage()
        dlg.open()
        return dlg

    def _accept_settings(self, dlg: StreamSettingsDialog) -> None:
        if dlg.stream is None:
            return
        if dlg.remember.isChecked():
            try:
                side = core.write_stream_sidecar(dlg.stream)
                self.statusBar().showMessage(f"Saved the settings in {side.name}.", 8000)
            except (SpikeviewError, OSError) as e:
                self.show_error(f"Could not write the sidecar: {e}")
        self.set_stream(dlg.stream)

    def stream_settings(self) -> StreamSettingsDialog | None:
        """Re-interpret the open stream (CFA, flip) with a live preview."""
        st = self.session.stream
        if st is None or st.reopen is None:
            self.show_error("Open a capture first; its CFA and flip can then be changed here.")
            return None
        initial = dict(st.open_kwargs)
        initial.setdefault("cfa", st.source.cfa or "none")
        initial.setdefault("flip_vertical", st.source.info.flip_vertical)
        dlg = StreamSettingsDialog(f"Stream settings — {st.label}", lambda **kw: st.reopen(**_only(kw, "cfa", "flip_vertical", "camera")),
                                   initial, message="Change how the capture is interpreted (colour filter, flip, camera profile); the preview shows the result.",
                                   geometry=False, parent=self)
        dlg.accepted.connect(lambda: dlg.stream is not None and (self.session.open_stream(dlg.stream, keep_position=True),
                                                                  self._restore_truth(dlg.stream)))
        dlg.finished.connect(lambda *_: setattr(self, "settings_dialog", None))
        self.settings_dialog = dlg
        dlg.open()
        return dlg

    def open_dialog(self) -> None:
        start = self.settings.value("last_dir", str(Path.home()), str)
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open a spike capture", start, CAPTURE_FILTER)
        if path:
            self.open_path(path)

    # ------------------------------------------------------------------------------ recent files
    def recent_files(self) -> list[dict[str, Any]]:
        raw = self.settings.value("recent", "[]", str)
        try:
            items = json.loads(raw)
        except (TypeError, ValueError):
            return []
        return [i for i in items if isinstance(i, dict) and "path" in i][:MAX_RECENT]

    def _add_recent(self, path: Path, kwargs: dict[str, Any]) -> None:
        path = Path(path).resolve()  # absolute: a recent file opens from any working folder
        items = [i for i in self.recent_files() if i["path"] != str(path)]
        clean = {k: v for k, v in kwargs.items() if isinstance(v, (str, int, float, bool))}
        items.insert(0, {"path": str(path), "kwargs": clean})
        self.settings.setValue("recent", json.dumps(items[:MAX_RECENT]))
        self._rebuild_recent()

    def _rebuild_recent(self) -> None:
        self.recent_menu.clear()
        items = self.recent_files()
        for item in items:
            act = self.recent_menu.addAction(item["path"])
            act.triggered.connect(lambda _=False, it=item: self._open_recent(it))
        self.recent_menu.setEnabled(bool(items))

    def _open_recent(self, item: dict[str, Any]) -> None:
        p = Path(item["path"])
        if not p.exists():
            self.show_error(f"{p} no longer exists; it was removed from the recent files.")
            self.settings.setValue("recent", json.dumps([i for i in self.recent_files() if i["path"] != item["path"]]))
            self._rebuild_recent()
            return
        self.open_path(p, **item.get("kwargs", {}))

    # ------------------------------------------------------------------------------ drag and drop
    def dragEnterEvent(self, ev: QtGui.QDragEnterEvent) -> None:
        if ev.mimeData().hasUrls() and any(u.isLocalFile() for u in ev.mimeData().urls()):
            ev.acceptProposedAction()
        else:
            ev.ignore()

    def dropEvent(self, ev: QtGui.QDropEvent) -> None:
        files = [u.toLocalFile() for u in ev.mimeData().urls() if u.isLocalFile()]
        if files:
            ev.acceptProposedAction()
            self.open_path(files[0])

    # ------------------------------------------------------------------------------ presets
    def load_preset(self, path: str | os.PathLike[str]) -> bool:
        from spikeview.session.presets import load_preset

        return self._preset_file(load_preset, path, "load", f"Loaded preset {Path(path).name} (Ctrl+Z undoes it).")

    def save_preset(self, path: str | os.PathLike[str]) -> bool:
        from spikeview.session.presets import save_preset

        return self._preset_file(save_preset, path, "save", f"Saved preset {path}.")

    def _preset_file(self, action: Any, path: str | os.PathLike[str], verb: str, done: str) -> bool:
        """Load or save a preset: an error is shown (nothing changes), success remembers the folder."""
        try:
            action(self.session, path)
        except SpikeviewError as e:
            self.show_error(str(e), dialog_title=f"Cannot {verb} the preset")
            return False
        self.settings.setValue("last_preset_dir", str(Path(path).parent))
        self.statusBar().showMessage(done, 8000)
        return True

    def load_preset_dialog(self) -> None:
        start = self.settings.value("last_preset_dir", str(Path.home()), str)
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Load a parameter preset", start, "Presets (*.toml);;All files (*)")
        if path:
            self.load_preset(path)

    def save_preset_dialog(self) -> None:
        start = self.settings.value("last_preset_dir", str(Path.home()), str)
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save the parameters", str(Path(start) / "spikeview.toml"),
                                                        "Presets (*.toml)")
        if path:
            self.save_preset(path if path.endswith(".toml") else path + ".toml")

    def reset_params(self) -> None:
        """Every parameter back to its default, the white point to the one the CLI would use with them: the
        capture's exposure is estimated again for the default η and window (it depends on both)."""
        from spikeview.session.model import default_params

        values = default_params()
        white = getattr(self.controller, "capture_white", None)
        if white is not None:
            values["white"] = white  # shown until the new estimate arrives
        self.session.update_params(values, label="Reset parameters")
        self.controller.follow_capture_white()

    def _reset_recipe_params(self, label: str) -> None:
        """The recipe's parameters (and the export's range) at their defaults, as one undo step; the app's own
        preferences (playback, the export format, the display panels) stay."""
        from spikeview.session.model import default_params
        from spikeview.recipe import BY_KEY

        defaults = default_params()
        values = {k: v for k, v in defaults.items() if k in BY_KEY or k == "export_range"}
        changed = {k: v for k, v in values.items() if self.session.params.get(k) != v}
        if changed:
            self.session.update_params(changed, label=label)
        self.controller.follow_capture_white()

    # ------------------------------------------------------------------------------ export
    def export_now(self) -> None:
        self.docks["export"].show()
        self.docks["export"].raise_()
        self.export_to(self.export_panel.path.text().strip())

    def export_to(self, out: str) -> None:
        if not out:
            self.show_error("Choose an output file in the Export panel first.")
            return
        from spikeview.export.base import existing_frame_files

        existing = existing_frame_files(out)
        if existing and not self.ask_overwrite(Path(out), existing):
            self.statusBar().showMessage("Export not started: the existing files are kept.", 8000)
            return
        if self.controller.start_export(out, overwrite=bool(existing), cluster=self.export_panel.cluster_address()):
            self.settings.setValue("last_export_dir", str(Path(out).parent))
            self.export_panel.remember_folder(Path(out).parent)

    def ask_overwrite(self, out: Path, existing: list[Path]) -> bool:
        """Ask before replacing files (tests replace this method)."""
        what = existing[0].name if len(existing) == 1 else f"{len(existing)} files named like {existing[0].name}"
        answer = QtWidgets.QMessageBox.question(
            self, "Replace existing files?", f"{what} already exist{'s' if len(existing) == 1 else ''} in {out.parent}. "
            "Replace them with this export?",
            QtWidgets.QMessageBox.StandardButton.Yes | QtWidgets.QMessageBox.StandardButton.Cancel,
            QtWidgets.QMessageBox.StandardButton.Cancel)
        return answer == QtWidgets.QMessageBox.StandardButton.Yes

    def _on_export_done(self, paths: list[Path]) -> None:
        if not paths:
            return
        first = Path(paths[0])
        what = first.name if len(paths) == 1 else f"{len(paths)} files ({first.name} …)"
        self.notice.show_message(
            f"Export finished: {what} in {first.parent}.", "success",
            [("Open", lambda: QtGui.QDesktopServices.openUrl(QtCore.QUrl.fromLocalFile(str(first)))),
             ("Show folder", lambda: QtGui.QDesktopServices.openUrl(QtCore.QUrl.fromLocalFile(str(first.parent))))])

    def _on_canvas_click(self, x: int, y: int) -> None:
        """A click on the image: the white-balance picker takes it when its Pick button is down."""
        if not self.stream_panel.wb_pick.isChecked():
            return
        refused = self.stream_panel.pick_white(x, y)
        if refused:
            self.show_error(refused)
        else:
            self.statusBar().showMessage(f"White balance from the patch at ({x}, {y}): gains "
                                         f"{self.session.get('white_balance')} (R, G, B).", 8000)

    # ------------------------------------------------------------------------------ messages
    def show_error(self, message: str, dialog_title: str | None = None) -> None:
        """Show an error in the notification strip (never modal, never a crash) and the status bar."""
        message = app_words(message)
        self.errors_shown.append(message)  # what --screenshot (no one to read the strip) stops on
        self.notice.show_message(message, "error")
        self.statusBar().showMessage(message.splitlines()[0], 10000)

    def _on_message(self, message: str) -> None:
        self.statusBar().showMessage(app_words(message), 8000)

    def _on_guided_state(self, state: str, message: str) -> None:
        self.statusBar().showMessage(app_words(message), 6000)

    def show_help(self) -> ShortcutsDialog:
        dlg = ShortcutsDialog(self)
        dlg.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        dlg.open()
        self._help = dlg
        return dlg

    def about(self) -> None:
        from spikeview import __version__

        self.notice.show_message(
            f"spikeview {__version__} — viewer, simulator and zero-shot guided reconstruction for chromatic spike cameras. "
            "GPL-3.0-or-later (FFDNet weights GPL-3.0).", "info")

    def fit_images(self) -> None:
        """View ▸ Fit images (reset zoom): every image pane shows its whole image again."""
        from spikeview.gui.widgets import ImagePane

        for pane in self.findChildren(ImagePane):
            pane.reset_zoom()

    # ------------------------------------------------------------------------------ canvas and ground truth
    def _on_readout(self, text: str) -> None:
        """The pixel under the cursor, in the status bar (while the cursor is over the image)."""
        if text:
            self.statusBar().showMessage(text)
        elif self.statusBar().currentMessage() and self.statusBar().currentMessage().startswith("x "):
            self.statusBar().clearMessage()

    def _update_compare_wanted(self) -> None:
        """Compute what is in sight only: the rates while their panel is, the degradation stages while their panel or
        the canvas shows them, the classical methods' scores while the Compare panel is in front or the canvas
        compares two images or shows the truth."""
        if self._closing:
            return
        a, mode, b = self.canvas.view()
        shown = {a} | ({b} if mode != "single" else set())
        c = self.controller
        c.set_enabled("rates", self.docks["rates"].isVisible())
        c.set_enabled("degradation", self.docks["degradation"].isVisible() or any(k.startswith("deg:") for k in shown))
        c.set_enabled("compare", self.docks["compare"].isVisible() or mode != "single" or a == "truth")

    def load_truth(self, path: str | os.PathLike[str], remember: bool = True) -> bool:
        """Use an image file as the open capture's ground truth (every tick): the canvas shows it, and the Compare
        panel and the guided runs score against it. Refused in one sentence (nothing changes) for an unreadable
        file or one of another size. It belongs to the capture: remembered (QSettings ``truth_for``) and loaded again
        when the same file is opened again in the same orientation (:meth:`_restore_truth`)."""
        st = self.session.stream
        if st is None:
            self.show_error("Open a capture first, then load its ground truth.")
            return False
        try:
            img = core.load_ground_truth(path, (st.source.height, st.source.width), st.source.cfa is not None)
        except SpikeviewError as e:
            self.show_error(str(e))
            return False
        st.ground_truth = lambda tick, _img=img: _img
        self.settings.setValue("last_truth_dir", str(Path(path).parent))
        if remember and st.path is not None:  # the capture's own setting: loaded again when it is opened again
            self._remember_truth(st, str(Path(path).resolve()))
        self.statusBar().showMessage(f"Ground truth: {Path(path).name} (for every tick of {st.label}"
                                     f"{'; remembered for this capture' if st.path is not None else ''}).", 8000)
        self.canvas.forget("truth")
        self._update_compare_wanted()
        self.controller.request_compare()
        self.compare_panel.redraw()
        return True

    def _truths(self) -> dict[str, dict[str, Any]]:
        try:
            items = json.loads(self.settings.value("truth_for", "{}", str))
        except (TypeError, ValueError):
            return {}
        return items if isinstance(items, dict) else {}

    def _remember_truth(self, st: OpenedStream, truth: str | None) -> None:
        items = self._truths()
        key = str(Path(st.path).resolve())
        items.pop(key, None)
        if truth is not None:
            items[key] = {"truth": truth, "flip_vertical": bool(st.source.info.flip_vertical),
                          "flip_horizontal": bool(st.source.info.flip_horizontal)}
        self.settings.setValue("truth_for", json.dumps(dict(list(items.items())[-MAX_TRUTHS:])))

    def _restore_truth(self, st: OpenedStream) -> None:
        """The ground truth loaded earlier for this capture file (same orientation), when it has none of its own."""
        if st.path is None or st.ground_truth is not None:
            return
        item = self._truths().get(str(Path(st.path).resolve()))
        if not isinstance(item, dict) or "truth" not in item:
            return
        info = st.source.info
        if (item.get("flip_vertical"), item.get("flip_horizontal")) != (bool(info.flip_vertical), bool(info.flip_horizontal)):
            return  # read the other way up: the image no longer lies on its pixels
        if not Path(item["truth"]).is_file():
            self._remember_truth(st, None)
            self.notice.show_message(f"The ground truth remembered for {st.label} ({item['truth']}) no longer exists; "
                                     "load it again with File ▸ Load ground truth….", "warning")
            return
        self.load_truth(item["truth"], remember=False)

    def load_truth_dialog(self) -> None:
        st = self.session.stream
        start = self.settings.value("last_truth_dir", "", str) or (str(st.path.parent) if st is not None and st.path else str(Path.home()))
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Load the ground truth of this capture", start,
                                                        "Images (*.png *.jpg *.jpeg *.tif *.tiff *.npy);;All files (*)")
        if path:
            self.load_truth(path)

    # ------------------------------------------------------------------------------ session → window
    def _on_source(self) -> None:
        st = self.session.stream
        self.setWindowTitle("spikeview" if st is None else f"{st.label} — spikeview")
        self._on_tick(self.session.tick)

    def _on_frames(self, f: Any) -> None:
        self.stream_panel.show_frames(f)
        self.canvas.show_frames(f)
        rate_hz = f.spike_rate * self.session.tick_rate
        self.rate_status.setText(f"  rate {f.spike_rate:.3f} spikes/px/tick ({rate_hz / 1000:.1f} kHz)  ")

    def _on_tick(self, tick: int) -> None:
        s = self.session
        self.time_status.setText(f"  tick {tick} · {format_us(s.ticks_to_us(tick))}  ")

    def _update_fps(self) -> None:
        fps = self.controller.display_fps()
        self.fps_status.setText(f"  {fps:4.1f} fps  " if self.session.playing else "  paused  ")

    def _on_undo_changed(self, can_undo: bool, can_redo: bool) -> None:
        u, r = self.session.undo_text()
        self.act_undo.setEnabled(can_undo)
        self.act_redo.setEnabled(can_redo)
        self.act_undo.setText(f"&Undo {u}" if u else "&Undo")
        self.act_redo.setText(f"&Redo {r}" if r else "&Redo")

    def _on_param(self, name: str, value: Any) -> None:
        self._params_timer.start()

    # ------------------------------------------------------------------------------ settings
    def _restore_params(self) -> None:
        raw = self.settings.value("params", "", str)
        if not raw:
            return
        try:
            values = json.loads(raw)
        except (TypeError, ValueError):
            return
        if isinstance(values, dict):
            # a launch keeps the user's preferences only: every recipe parameter (what a result depends on) and the
            # export's range start at the CLI's defaults, so nothing remembered changes a result silently
            from spikeview.recipe import BY_KEY

            values = {k: v for k, v in values.items() if k not in BY_KEY and k != "export_range"}
            skipped = self.session.update_params(values, record=False, strict=False)
            if skipped:
                self.session.events.message.emit(f"Ignored saved settings that no longer apply: {', '.join(skipped)}.")

    def _save_params(self) -> None:
        self.settings.setValue("params", json.dumps(self.session.params))

    def save_settings(self) -> None:
        self._save_params()
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.setValue("window/state", self.saveState())
        self.settings.setValue("window/layout_version", LAYOUT_VERSION)
        self.settings.sync()

    def closeEvent(self, ev: QtGui.QCloseEvent) -> None:
        self._closing = True
        self.save_settings()
        self.fps_timer.stop()
        self._params_timer.stop()
        self.controller.shutdown()
        self.loader.stop()
        for event, cb in self._session_links:
            event.disconnect(cb)
        st = self.session.stream
        if st is not None and st.path is not None:
            st.source.close()
        super().closeEvent(ev)


class _Fill(QtWidgets.QWidget):
    """Holds a panel in a scroll area: the panel gets the whole visible area, or its minimum size and scroll bars
    when the area is smaller. (A panel with word-wrapped labels put straight into a resizable scroll area was
    sized by its height-for-width at its preferred width: 1200 px wide and ~1000 px tall in a 400-pixel column,
    its images scrolled out of sight.)"""

    def __init__(self, inner: QtWidgets.QWidget):
        super().__init__()
        self.inner = inner
        inner.setParent(self)
        inner.installEventFilter(self)

    def sizeHint(self) -> QtCore.QSize:  # noqa: N802 - Qt's name
        return self.inner.minimumSizeHint()

    def minimumSizeHint(self) -> QtCore.QSize:  # noqa: N802 - Qt's name
        return self.inner.minimumSizeHint()

    def resizeEvent(self, ev: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt's name
        self.inner.setGeometry(0, 0, ev.size().width(), ev.size().height())

    def eventFilter(self, obj: QtCore.QObject, ev: QtCore.QEvent) -> bool:  # noqa: N802 - Qt's name
        if obj is self.inner and ev.type() == QtCore.QEvent.Type.LayoutRequest:
            self.updateGeometry()  # the panel's minimum may have changed: the scroll area asks again
        return False


def scrolled(widget: QtWidgets.QWidget) -> QtWidgets.QScrollArea:
    """``widget`` in a frameless scroll area: a panel whose contents need more room than its dock has scrolls
    instead of widening or heightening the window (after a run, an export or a long message)."""
    area = QtWidgets.QScrollArea()
    area.setObjectName(f"scroll_{widget.objectName() or type(widget).__name__}")
    area.setWidgetResizable(True)
    area.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
    area.setWidget(_Fill(widget))
    return area


def _only(d: dict[str, Any], *keys: str) -> dict[str, Any]:
    return {k: v for k, v in d.items() if k in keys}
