"""Live capture in the app: "Open camera…", a live indicator, Record/Stop, drop counters.

Install it on the main window with one call::

    from spikeview.gui.live_panel import install_live
    self.live_panel = install_live(self)      # at the end of MainWindow.__init__

:func:`install_live` adds *File ▸ Open camera…*, a "Live camera" dock (with its toggle in the View
menu) and a close hook: closing the window stops the camera and finalises a running recording
(every frame acquired is on disk, flushed, fsynced, with its sidecar).

The camera is a :class:`~spikeview.live.source.LiveSource`, so once it has buffered a few hundred
ticks it is opened in the session like any capture and every panel works on it; with *Follow
live* on, the session's tick tracks the newest window (the preview worker is asked for a new frame
only when it has shown the last one, so the display drops frames, never acquired data). The panel
polls the source from a Qt timer: the acquisition thread never touches Qt.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from spikeview.errors import SpikeviewError

#: the panel polls the source this often (ms); labels are refreshed every LABEL_MS
POLL_MS = 40
LABEL_MS = 200
#: ticks buffered before the camera is shown in the session (capped at half the ring)
ATTACH_TICKS = 1024

_COLOURS = {"live": "#3ec46d", "waiting": "#e0b030", "error": "#e05050", "off": "#808080"}


def format_bytes(n: float) -> str:
    """``1234567`` → ``"1.2 MB"`` (decimal units, as file browsers show)."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"  # pragma: no cover


def format_elapsed(seconds: float) -> str:
    """``75.3`` → ``"01:15.3"``; an hour or more → ``"1:01:15"``."""
    seconds = max(0.0, seconds)
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{int(h)}:{int(m):02d}:{int(s):02d}" if h >= 1 else f"{int(m):02d}:{s:04.1f}"


def indicator_state(status: Any) -> tuple[str, str]:
    """``(text, colour key)`` of the live indicator for a :class:`~spikeview.live.source.LiveStatus`."""
    value = getattr(status, "value", str(status))
    if value == "running":
        return "● LIVE", "live"
    if value in ("connecting", "waiting"):
        return "● WAITING" if value == "waiting" else "● CONNECTING", "waiting"
    if getattr(status, "failed", False):
        return "● ERROR", "error"
    return "● OFFLINE", "off"


# --------------------------------------------------------------------------------------- dialog


class OpenCameraDialog(QtWidgets.QDialog):
    """Pick a camera: the USB devices pyusb sees, or a simulated camera; settings for USB cameras.

    After ``accept``, :attr:`source` holds the (not yet started) live source.

    Args:
        backend: pyusb backend to list and open devices with (``None``: libusb; tests pass a mock).
        replay: the :class:`~spikeview.session.model.OpenedStream` open in the app, offered for replay, or ``None``.
        initial: last :class:`~spikeview.live.usb.CameraConfig` settings, as a dict.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None, *, backend: Any = None, replay: Any = None,
                 initial: dict[str, Any] | None = None):
        super().__init__(parent)
        self.setWindowTitle("Open camera")
        self.setObjectName("open_camera_dialog")
        self.backend = backend
        self.replay = replay
        self.source: Any = None
        self.initial = dict(initial or {})

        self.list = QtWidgets.QListWidget(objectName="camera_list")
        self.list.setMinimumWidth(460)
        self.refresh_btn = QtWidgets.QPushButton("Refresh")
        self.refresh_btn.clicked.connect(self.refresh)
        self.note = QtWidgets.QLabel(objectName="camera_note")
        self.note.setWordWrap(True)

        # USB settings (raw 1000×1000 tagged stream by default)
        self.vid = QtWidgets.QLineEdit(objectName="camera_vid", placeholderText="e.g. 1234")
        self.pid = QtWidgets.QLineEdit(objectName="camera_pid", placeholderText="e.g. 5678")
        self.endpoint = QtWidgets.QLineEdit("81", objectName="camera_endpoint")
        self.format = QtWidgets.QComboBox(objectName="camera_format")
        self.format.addItem("Tagged raw 1000×1000", "raw1m")
        self.format.addItem("Plain packed frames", "plain")
        self.width = QtWidgets.QSpinBox(objectName="camera_width", minimum=8, maximum=8192, value=1000)
        self.height = QtWidgets.QSpinBox(objectName="camera_height", minimum=1, maximum=8192, value=1000)
        self.cfa = QtWidgets.QComboBox(objectName="camera_cfa")
        for c in ("none", "RGGB", "BGGR", "GRBG", "GBRG"):
            self.cfa.addItem(c, c)
        self.flip = QtWidgets.QCheckBox("Flip vertically", objectName="camera_flip")
        self.roi = QtWidgets.QLineEdit(objectName="camera_roi", placeholderText="top, left, height, width (empty: all)")
        self.decimate = QtWidgets.QSpinBox(objectName="camera_decimate", minimum=1, maximum=64, value=1)
        self.frame_step = QtWidgets.QSpinBox(objectName="camera_frame_step", minimum=1, maximum=1000, value=1)
        self.format.currentIndexChanged.connect(self._format_changed)
        form = QtWidgets.QFormLayout()
        form.addRow("Vendor id (hex)", self.vid)
        form.addRow("Product id (hex)", self.pid)
        form.addRow("Bulk IN endpoint (hex)", self.endpoint)
        form.addRow("Stream format", self.format)
        size = QtWidgets.QHBoxLayout()
        size.addWidget(self.width)
        size.addWidget(QtWidgets.QLabel("×"))
        size.addWidget(self.height)
        form.addRow("Plain frame size", size)
        form.addRow("CFA (after flips)", self.cfa)
        form.addRow("", self.flip)
        form.addRow("ROI (sensor pixels)", self.roi)
        form.addRow("Decimate / frame step", self._pair(self.decimate, self.frame_step))
        self.usb_box = QtWidgets.QGroupBox("USB camera settings")
        self.usb_box.setLayout(form)
        hint = QtWidgets.QLabel("The host applies ROI and decimation after decoding: the full sensor (2.5 GB/s) is more "
                                "than USB 3 carries, and the camera's own ROI command is vendor-specific and not public.")
        hint.setWordWrap(True)
        hint.setStyleSheet("color: #a0a0a0;")
        self.error = QtWidgets.QLabel(objectName="camera_error")
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color: #ff7070;")
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.StandardButton.Open
                                             | QtWidgets.QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        self.buttons = buttons

        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Cameras found"), 1)
        top.addWidget(self.refresh_btn)
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(self.list, 1)
        lay.addWidget(self.note)
        lay.addWidget(self.usb_box)
        lay.addWidget(hint)
        lay.addWidget(self.error)
        lay.addWidget(buttons)
        self.list.currentItemChanged.connect(self._selected)
        self.list.itemDoubleClicked.connect(lambda *_: self.accept())
        self._apply_initial()
        self.refresh()

    @staticmethod
    def _pair(a: QtWidgets.QWidget, b: QtWidgets.QWidget) -> QtWidgets.QWidget:
        w = QtWidgets.QWidget()
        h = QtWidgets.QHBoxLayout(w)
        h.setContentsMargins(0, 0, 0, 0)
        h.addWidget(a)
        h.addWidget(b)
        return w

    def _apply_initial(self) -> None:
        c = self.initial
        if c.get("vid") is not None:
            self.vid.setText(f"{int(c['vid']):04x}")
        if c.get("pid") is not None:
            self.pid.setText(f"{int(c['pid']):04x}")
        if c.get("endpoint") is not None:
            self.endpoint.setText(f"{int(c['endpoint']):02x}")
        i = self.format.findData(c.get("format", "raw1m"))
        self.format.setCurrentIndex(max(i, 0))
        self.width.setValue(int(c.get("width") or 1000))
        self.height.setValue(int(c.get("height") or 1000))
        self.cfa.setCurrentIndex(max(self.cfa.findData(c.get("cfa", "none")), 0))
        self.flip.setChecked(bool(c.get("flip_vertical") or False))
        if c.get("roi"):
            self.roi.setText(", ".join(str(v) for v in c["roi"]))
        self.decimate.setValue(int(c.get("decimate", 1)))
        self.frame_step.setValue(int(c.get("frame_step", 1)))
        self._format_changed()

    def _format_changed(self) -> None:
        plain = self.format.currentData() == "plain"
        self.width.setEnabled(plain)
        self.height.setEnabled(plain)

    # ------------------------------------------------------------------------------ list
    def refresh(self) -> None:
        """List the simulated cameras and the USB devices pyusb sees."""
        self.list.clear()
        self._add("Simulated camera: demo scene (128×128, RGGB)", ("sim-demo", None))
        if self.replay is not None:
            src = self.replay.source
            self._add(f"Simulated camera: replay {self.replay.label} ({src.width}×{src.height}, {src.n_frames} ticks, "
                      f"looped)", ("sim-replay", None))
        self._add("Simulated camera: replay a spike file…", ("sim-file", None))
        self._add("USB camera with the settings below", ("usb", None))
        note = ""
        try:
            from spikeview.live.usb import list_usb_devices

            devices = list_usb_devices(self.backend)
        except SpikeviewError as e:
            devices, note = [], str(e)
        except Exception as e:  # a broken USB stack must not break the dialog
            devices, note = [], f"Listing USB devices failed ({e}); enter the camera's ids below."
        for d in devices:
            self._add(f"USB: {d.label}", ("usb-device", d))
        if not devices and not note:
            note = "No USB devices found: plug the camera in and press Refresh, or pick a simulated camera."
        self.note.setText(note)
        self.note.setVisible(bool(note))
        first_usb = self.list.count() - len(devices)
        self.list.setCurrentRow(first_usb if devices else 0)

    def _add(self, text: str, data: tuple[str, Any]) -> None:
        item = QtWidgets.QListWidgetItem(text)
        item.setData(QtCore.Qt.ItemDataRole.UserRole, data)
        self.list.addItem(item)

    def _selected(self, item: QtWidgets.QListWidgetItem | None, _prev: Any = None) -> None:
        if item is None:
            return
        kind, dev = item.data(QtCore.Qt.ItemDataRole.UserRole)
        self.usb_box.setEnabled(kind in ("usb", "usb-device"))
        if kind == "usb-device":
            self.vid.setText(f"{dev.vid:04x}")
            self.pid.setText(f"{dev.pid:04x}")

    def select(self, text_contains: str) -> bool:
        """Select the first entry whose text contains ``text_contains`` (for tests and scripts)."""
        for i in range(self.list.count()):
            if text_contains in self.list.item(i).text():
                self.list.setCurrentRow(i)
                return True
        return False

    def entries(self) -> list[str]:
        return [self.list.item(i).text() for i in range(self.list.count())]

    # ------------------------------------------------------------------------------ result
    def camera_settings(self) -> dict[str, Any]:
        """The USB settings as :class:`~spikeview.live.usb.CameraConfig` keyword arguments (may raise ParameterError;
        the text fields are read by :func:`spikeview.live.usb.parse_hex_id` and :func:`~spikeview.live.usb.parse_roi`,
        an empty endpoint leaves ``CameraConfig``'s default)."""
        from spikeview.live.usb import parse_hex_id, parse_roi

        kw: dict[str, Any] = {"vid": parse_hex_id(self.vid.text(), "Vendor id"), "pid": parse_hex_id(self.pid.text(), "Product id"),
                              "format": self.format.currentData(), "cfa": self.cfa.currentData(),
                              "flip_vertical": self.flip.isChecked(), "roi": parse_roi(self.roi.text()),
                              "decimate": self.decimate.value(), "frame_step": self.frame_step.value()}
        endpoint = parse_hex_id(self.endpoint.text(), "Endpoint")
        if endpoint is not None:
            kw["endpoint"] = endpoint
        if kw["format"] == "plain":
            kw.update(width=self.width.value(), height=self.height.value())
        for item in (self.list.currentItem(),):
            if item is not None:
                kind, dev = item.data(QtCore.Qt.ItemDataRole.UserRole)
                if kind == "usb-device":
                    kw.update(bus=dev.bus, address=dev.address)
        return kw

    def build_source(self) -> Any:
        """The live source for the selected entry (not started); raises SpikeviewError with a fix."""
        item = self.list.currentItem()
        if item is None:
            from spikeview.errors import ParameterError

            raise ParameterError("Pick a camera in the list first.")
        kind, _dev = item.data(QtCore.Qt.ItemDataRole.UserRole)
        from spikeview.live.simcam import SimCamera

        if kind == "sim-demo":
            return SimCamera.demo(size=128)
        if kind == "sim-replay":
            st = self.replay
            label = f"simulated camera (replay of {st.label})"
            if st.path is None:  # in memory: the viewer never closes it
                return SimCamera(st.source, label=label)
            from spikeview.io import open_source

            # a file: open it again, as the viewer closes its own copy when it shows the camera
            kwargs = {k: v for k, v in st.open_kwargs.items() if v is not None}
            return SimCamera(open_source(st.path, **kwargs), label=label, close_producer=True)
        if kind == "sim-file":
            path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Replay a spike file as a camera", "",
                                                            "Spike captures (*.dat *.bin *.raw *.npy *.npz);;All files (*)")
            if not path:
                return None
            from spikeview.io import open_source

            src = open_source(path)
            return SimCamera(src, label=f"simulated camera (replay of {Path(path).name})", close_producer=True)
        from spikeview.live.usb import CameraConfig, UsbCamera

        return UsbCamera(CameraConfig(**self.camera_settings()), backend=self.backend)

    def accept(self) -> None:
        """Build the camera; on bad settings stay open and say why (Qt override)."""
        try:
            source = self.build_source()
        except SpikeviewError as e:
            self.error.setText(str(e))
            return
        if source is None:
            return
        self.source = source
        super().accept()


# --------------------------------------------------------------------------------------- panel


class LivePanel(QtWidgets.QWidget):
    """The "Live camera" dock: indicator, status, Record/Stop, elapsed time, file size, drop counters.

    Args:
        window: the :class:`~spikeview.gui.main_window.MainWindow` (its session, controller,
            ``set_stream``, ``show_error`` and settings are used).
        backend: pyusb backend for listing/opening USB cameras (``None``: libusb).
    """

    def __init__(self, window: Any, backend: Any = None):
        super().__init__()
        self.setObjectName("live_panel")
        self.window = window
        self.backend = backend
        self.source: Any = None
        self.dialog: OpenCameraDialog | None = None
        #: returns the path to record to, or None to cancel (tests replace it; default: a save dialog)
        self.ask_record_path = self._ask_record_path
        self._attached = False
        self._reported: tuple[Any, str] | None = None
        self._shown_summary: Any = None
        self._last_labels = 0.0
        self._shut = False

        self.indicator = QtWidgets.QLabel(objectName="live_indicator")
        font = self.indicator.font()
        font.setBold(True)
        self.indicator.setFont(font)
        self.device = QtWidgets.QLabel("No camera open.", objectName="live_device")
        self.status = QtWidgets.QLabel(objectName="live_status")
        self.status.setWordWrap(True)
        self.status.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.open_btn = QtWidgets.QPushButton("Open camera…", objectName="live_open")
        self.open_btn.clicked.connect(self.open_dialog)
        self.show_btn = QtWidgets.QPushButton("Show live", objectName="live_show")
        self.show_btn.setToolTip("Show the camera in the viewer again (after opening a file)")
        self.show_btn.clicked.connect(self.show_in_session)
        self.close_btn = QtWidgets.QPushButton("Disconnect", objectName="live_disconnect")
        self.close_btn.clicked.connect(self.close_camera)
        self.record_btn = QtWidgets.QPushButton("● Record", objectName="live_record")
        self.record_btn.clicked.connect(self.toggle_recording)
        self.follow = QtWidgets.QCheckBox("Follow live", objectName="live_follow")
        self.follow.setChecked(True)
        self.follow.setToolTip("Keep the viewer on the newest window of the camera")
        mono = QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont)
        self.elapsed = QtWidgets.QLabel(objectName="live_elapsed")
        self.size = QtWidgets.QLabel(objectName="live_size")
        self.counters = QtWidgets.QLabel(objectName="live_counters")
        self.dropped = QtWidgets.QLabel(objectName="live_dropped")
        for w in (self.elapsed, self.size, self.counters, self.dropped):
            w.setFont(mono)

        head = QtWidgets.QHBoxLayout()
        head.addWidget(self.indicator)
        head.addWidget(self.device, 1)
        head.addWidget(self.open_btn)
        head.addWidget(self.show_btn)
        head.addWidget(self.close_btn)
        rec = QtWidgets.QHBoxLayout()
        rec.addWidget(self.record_btn)
        rec.addWidget(self.elapsed)
        rec.addWidget(self.size)
        rec.addStretch(1)
        rec.addWidget(self.follow)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(6, 4, 6, 4)
        lay.addLayout(head)
        lay.addWidget(self.status)
        lay.addLayout(rec)
        lay.addWidget(self.counters)
        lay.addWidget(self.dropped)
        lay.addStretch(1)

        self.timer = QtCore.QTimer(self, interval=POLL_MS)
        self.timer.timeout.connect(self.poll)
        self.refresh_labels()

    # ------------------------------------------------------------------------------ opening
    def open_dialog(self) -> OpenCameraDialog:
        """Show the (non-modal) Open camera dialog; the chosen camera is attached when accepted."""
        st = self.window.session.stream
        replay = st if st is not None and not _is_live(st.source) else None
        dlg = OpenCameraDialog(self.window, backend=self.backend, replay=replay, initial=self._saved_config())
        dlg.accepted.connect(lambda: self._dialog_accepted(dlg))
        dlg.finished.connect(lambda *_: setattr(self, "dialog", None))
        self.dialog = dlg
        dlg.open()
        return dlg

    def _dialog_accepted(self, dlg: OpenCameraDialog) -> None:
        if dlg.source is None:
            return
        if getattr(dlg.source, "config", None) is not None:
            self._save_config(dlg.source.config)
        self.attach(dlg.source)

    def attach(self, source: Any) -> None:
        """Make ``source`` (a :class:`~spikeview.live.source.LiveSource`) the panel's camera and start it."""
        self.close_camera()
        # The preview workers import spikeview.classical on first use from several threads at once, which
        # can deadlock on its circular imports; importing it once here, on the GUI thread, avoids that.
        import spikeview.classical.reconstruct  # noqa: F401
        import spikeview.classical.tfi  # noqa: F401

        self.source = source
        self._attached = False
        self._reported = None
        self.device.setText(source.label)
        source.start()
        self.timer.start()
        self.poll()

    def close_camera(self) -> None:
        """Stop the camera (finalising a recording); the viewer keeps what the buffer holds."""
        src, self.source = self.source, None
        if src is None:
            return
        self.timer.stop()
        was_recording = src.recording
        src.close()
        if was_recording:
            self._report_recording(src)
        self.device.setText(f"{src.label} (closed)")
        self.refresh_labels(src)

    def show_in_session(self) -> bool:
        """Open the camera's stream in the viewer (done automatically once it has buffered enough)."""
        src = self.source
        if src is None or src.n_frames == 0:
            return False
        from spikeview.session.model import OpenedStream

        if self.window.session.source is not src:
            self.window.set_stream(OpenedStream(source=src, label=src.label))
        self._attached = True
        self._follow_now(src)
        return True

    # ------------------------------------------------------------------------------ recording
    def _ask_record_path(self) -> str | None:
        settings = self.window.settings
        start = settings.value("live/record_dir", str(Path.home()), str)
        name = time.strftime("capture-%Y%m%d-%H%M%S.dat")
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Record to", str(Path(start) / name), "Plain spike files (*.dat)")
        return path or None

    def toggle_recording(self) -> None:
        if self.source is not None and self.source.recording:
            self.stop_recording()
        else:
            self.start_recording()

    def start_recording(self, path: str | Path | None = None) -> bool:
        """Record the camera to ``path`` (asked for when ``None``); errors go to the notification strip."""
        src = self.source
        if src is None:
            self.window.show_error("Open a camera first (File ▸ Open camera…), then record.")
            return False
        if path is None:
            path = self.ask_record_path()
            if not path:
                return False
        path = Path(path)
        if path.suffix == "":
            path = path.with_suffix(".dat")
        try:
            src.start_recording(path, overwrite=True)  # the save dialog already asked about overwriting
        except SpikeviewError as e:
            self.window.show_error(str(e), dialog_title="Cannot record")
            return False
        self.window.settings.setValue("live/record_dir", str(path.parent))
        self.refresh_labels()
        return True

    def stop_recording(self) -> Any:
        """Stop recording (the queue is written, flushed and fsynced); returns the summary."""
        src = self.source
        if src is None or not src.recording:
            return None
        self.record_btn.setEnabled(False)
        summary = src.stop_recording()
        self.record_btn.setEnabled(True)
        self._report_recording(src)
        self.refresh_labels()
        return summary

    def _report_recording(self, src: Any) -> None:
        s = src.last_recording
        if s is None or s is self._shown_summary:
            return
        self._shown_summary = s
        kind = "success" if s.state == "done" and not s.buffer_dropped_frames else "warning"
        if s.state == "failed":
            kind = "error"
        elif getattr(src.status, "failed", False):
            kind = "warning"  # complete file, but the camera ended on a problem (the message says which)
        self.window.notice.show_message(f"{s.message} ({format_bytes(s.bytes)}, {format_elapsed(s.duration_s)}).", kind)

    # ------------------------------------------------------------------------------ polling
    def poll(self) -> None:
        """Timer tick: show the camera in the viewer once it has data, follow it, refresh labels, report problems."""
        src = self.source
        if src is None:
            return
        n = src.n_frames
        if not self._attached and n > 0:
            ready = n >= min(ATTACH_TICKS, src.ring.capacity // 2) or not src.running
            if ready:
                self.show_in_session()
        elif self._attached and self.follow.isChecked():
            self._follow_now(src)
        status, message = src.status, src.status_message
        if getattr(status, "failed", False) and self._reported != (status, message):
            self._reported = (status, message)
            self.window.show_error(message, dialog_title="Camera")
        elif src.last_recording is not None and not src.recording:
            self._report_recording(src)  # a recording the acquisition ended (end of stream …)
        now = time.monotonic()
        if now - self._last_labels >= LABEL_MS / 1000:
            self._last_labels = now
            self.refresh_labels()
        if not src.running and not src.recording:
            self.refresh_labels()
            self.timer.stop()

    def _follow_now(self, src: Any) -> None:
        w = self.window
        s = w.session
        if s.source is not src or s.playing or w.controller.preview.is_active("frames"):
            return  # back-pressure: the last frame is not shown yet, skip this one
        n = src.n_frames
        if n == 0:
            return
        scrub = getattr(getattr(w, "stream_panel", None), "scrub", None)
        if scrub is not None and scrub.maximum() != n - 1:
            with QtCore.QSignalBlocker(scrub):
                scrub.setRange(0, n - 1)
        s.set_tick(n - 1)

    def refresh_labels(self, src: Any = None) -> None:
        src = src if src is not None else self.source
        if src is None:
            text, key = "● OFFLINE", "off"
            self.status.setText("Open a camera (USB or simulated) to see it live and record it.")
        else:
            text, key = indicator_state(src.status)
            self.status.setText(src.status_message)
        self.indicator.setText(text)
        self.indicator.setStyleSheet(f"color: {_COLOURS[key]};")
        live = src is not None and self.source is src
        running = live and src.running
        recording = live and src.recording
        self.record_btn.setText("■ Stop" if recording else "● Record")
        self.record_btn.setEnabled(bool(running or recording))
        self.show_btn.setEnabled(live and src.n_frames > 0)
        self.close_btn.setEnabled(live)
        if src is None:
            for w in (self.elapsed, self.size, self.counters, self.dropped):
                w.setText("")
            return
        st = src.stats()
        if recording:
            self.elapsed.setText(f"REC {format_elapsed(st['record_elapsed_s'])}")
            self.size.setText(f"{format_bytes(st['record_bytes'])} · {st['record_frames']:,} frames")
            self.elapsed.setStyleSheet(f"color: {_COLOURS['error']};")
        else:
            last = src.last_recording
            self.elapsed.setText("" if last is None else f"last: {format_elapsed(last.duration_s)}")
            self.size.setText("" if last is None else f"{format_bytes(last.bytes)} · {last.frames:,} frames")
            self.elapsed.setStyleSheet("")
        self.counters.setText(f"{st['frames']:,} frames · {format_bytes(st['bytes_per_s'])}/s in · "
                              f"{st['frames_per_s']:,.0f} frames/s")
        rec_drop = st.get("record_buffer_dropped", src.last_recording.buffer_dropped_frames if src.last_recording else 0)
        self.dropped.setText(f"Dropped: device {st.get('device_dropped_frames', 0):,} · recorder {rec_drop:,} · "
                             f"buffer overruns {st['ring_overruns']:,}")
        bad = st.get("device_dropped_frames", 0) or rec_drop
        self.dropped.setStyleSheet(f"color: {_COLOURS['waiting']};" if bad else "")

    # ------------------------------------------------------------------------------ settings, shutdown
    def _saved_config(self) -> dict[str, Any]:
        import json

        raw = self.window.settings.value("live/camera", "", str)
        try:
            data = json.loads(raw) if raw else {}
        except ValueError:
            data = {}
        return data if isinstance(data, dict) else {}

    def _save_config(self, config: Any) -> None:
        import json

        self.window.settings.setValue("live/camera", json.dumps(config.to_dict()))

    def shutdown(self) -> None:
        """Stop the camera and finalise a running recording (called when the window closes)."""
        if self._shut:
            return
        self._shut = True
        self.timer.stop()
        src, self.source = self.source, None
        if src is not None:
            src.close()


def _is_live(source: Any) -> bool:
    from spikeview.live.source import LiveSource

    return isinstance(getattr(source, "inner", source), LiveSource)


class _CloseFilter(QtCore.QObject):
    """Finalises the camera when the main window closes (before its own closeEvent runs)."""

    def __init__(self, panel: LivePanel):
        super().__init__(panel)
        self.panel = panel

    def eventFilter(self, obj: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        if event.type() == QtCore.QEvent.Type.Close:
            self.panel.shutdown()
        return False


def install_live(window: Any, backend: Any = None) -> LivePanel:
    """Add live capture to the main window: *File ▸ Open camera…*, the "Live camera" dock, the close hook.

    Args:
        window: the :class:`~spikeview.gui.main_window.MainWindow`.
        backend: pyusb backend (``None``: libusb); tests pass :class:`~spikeview.live.mockusb.MockBackend`.

    Returns:
        The :class:`LivePanel` (also at ``window.live_panel``).
    """
    panel = LivePanel(window, backend=backend)
    dock = window.add_panel("live", "Live camera", panel, beside="degradation")
    panel.dock = dock

    act = QtGui.QAction("Open &camera…", window)
    act.setObjectName("act_open_camera")
    act.setStatusTip("Open a USB spike camera or a simulated camera, live")
    act.triggered.connect(lambda: (dock.show(), dock.raise_(), panel.open_dialog()))
    window.add_file_action(act)
    panel.action = act

    window.installEventFilter(_CloseFilter(panel))
    app = QtWidgets.QApplication.instance()
    if app is not None:
        app.aboutToQuit.connect(panel.shutdown)
    window.live_panel = panel
    return panel
