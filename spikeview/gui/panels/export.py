"""Export panel: EXR/MP4/PNG of the current frame or the marked range, in the background."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from spikeview.errors import SpikeviewError
from spikeview.export.base import strip_frame_field
from spikeview.session import jobs
from spikeview.session.model import Session
from spikeview.gui.widgets import ParamCombo, ParamSpin, form, hbox, job_controls, subscribe

FORMAT_TEXT = {"png": "PNG (8-bit, display)", "exr": "EXR (half float, linear)", "mp4": "MP4 (H.264)"}
RANGE_TEXT = {"frame": "Current frame", "marked": "Marked range (one frame per Δτ)"}
METHOD_TEXT = {"tfp": "TFP (classical)", "tfi": "TFI (classical)", "guided": "Guided (ROI if drawn; slow)"}


def suggested_name(stem: str, fmt: str, n_frames: int) -> str:
    """File name for an export: sequences of images get a visible ``_%04d`` frame field."""
    if fmt == "mp4":
        return f"{stem}.mp4"
    return f"{stem}_%04d.{fmt}" if n_frames > 1 else f"{stem}.{fmt}"


def matching_name(path: str, fmt: str, n_frames: int) -> str:
    """A typed file name adapted (visibly, in the field) to the chosen format and frame count.

    The suffix follows the format; an image sequence gets a ``_%04d`` field if it has none; an
    MP4 loses the field. Other names are left alone.
    """
    if not path:
        return path
    p = Path(path)
    if p.suffix.lower() not in (".png", ".exr", ".mp4"):
        if p.suffix or path.endswith(("/", "\\")):  # another suffix (.zarr, .npy…) or a folder: left alone
            return path
        p = p.with_name(p.name + ".png")  # no suffix yet: the format's is added below
    stem = p.stem
    field = strip_frame_field(stem) != stem
    if fmt == "mp4" and field:
        stem = strip_frame_field(stem)
    elif fmt != "mp4" and n_frames > 1 and not field:
        stem += "_%04d"
    return str(p.with_name(f"{stem}.{fmt}"))


class ExportPanel(QtWidgets.QWidget):
    export_requested = QtCore.Signal(str)
    cancel_requested = QtCore.Signal()

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.folder = Path.home()
        self._chosen_folder: Path | None = None  # the last export folder (settings) or one picked in Browse
        self._suggested = ""  # the last name the panel generated: the field follows the settings while it shows it
        self.fmt = ParamCombo(session, "export_format", FORMAT_TEXT)
        self.range = ParamCombo(session, "export_range", RANGE_TEXT)
        self.method = ParamCombo(session, "export_method", METHOD_TEXT)
        self.fps = ParamSpin(session, "export_fps")
        self.slowmo = QtWidgets.QLabel()
        self.slowmo.setObjectName("slowmo_note")
        self.slowmo.setWordWrap(True)
        # room for two lines: at its narrowest (a 1366-pixel screen) the note wraps, and must not overlap
        self.slowmo.setMinimumHeight(2 * self.slowmo.fontMetrics().lineSpacing() + 2)
        self.count = QtWidgets.QLabel()
        self.count.setObjectName("export_count")
        # the count line can say that Export writes TFP, not the guided result shown: it wraps rather than widen the
        # panel past a laptop's screen (cut off there, behind a horizontal scroll bar)
        self.count.setWordWrap(True)
        self.cluster = QtWidgets.QLineEdit()
        self.cluster.setObjectName("export_cluster")
        self.cluster.setPlaceholderText("optional: local:2 or tcp://HOST:8786")
        self.cluster.setToolTip("Reconstruct in chunks on Dask workers (local:N worker processes, or a running "
                                "scheduler's address) into a Zarr store (.zarr); the workers read the capture "
                                "from its file. spikeview export turns the store into MP4/EXR/npy.")
        self.cluster.textChanged.connect(lambda _text: self.refresh())
        self.path = QtWidgets.QLineEdit()
        self.path.setObjectName("export_path")
        self.path.setToolTip("Output file; image sequences need a frame field such as %04d")
        browse = QtWidgets.QToolButton(text="…")
        browse.setToolTip("Choose where to write")
        browse.clicked.connect(self._browse)
        pw = hbox((self.path, 1), browse)
        self.export_btn, self.cancel_btn, self.progress, self.status = job_controls(
            "export", "Export", "Write the files in the background (Ctrl+E)",
            lambda: self.export_requested.emit(self.path.text().strip()), self.cancel_requested, "frames")
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(self.export_btn)
        buttons.addWidget(self.cancel_btn)
        buttons.addWidget(self.progress, 1)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(3, 3, 3, 3)
        lay.addWidget(form([("Format", self.fmt), ("Frames", self.range), ("Method", self.method), ("Output fps", self.fps),
                            ("", self.slowmo), ("", self.count), ("Dask", self.cluster), ("File", pw)]))
        lay.addLayout(buttons)
        lay.addWidget(self.status)
        lay.addStretch(1)
        ev = session.events
        subscribe(self, ev.param_changed, lambda *_: self.refresh())
        subscribe(self, ev.marks_changed, lambda *_: self.refresh())
        subscribe(self, ev.source_changed, self._on_source)
        subscribe(self, ev.tick_changed, self._on_tick)
        subscribe(self, ev.playback_changed, lambda playing: None if playing else self.refresh())
        self._auto_name = True
        self.path.textEdited.connect(self._edited)
        self.guided_seen = False  # a guided result of this capture is on screen (the count line then says what Export writes)
        self._on_source()

    def _edited(self, _text: str) -> None:
        self._auto_name = False

    def _typed(self) -> bool:
        """Whether the field holds a path the user gave (typed, pasted or set), not the panel's suggestion."""
        text = self.path.text().strip()
        return not self._auto_name or (bool(text) and bool(self._suggested) and text != self._suggested)

    def _set_suggestion(self, text: str) -> None:
        self._suggested = text
        self.path.setText(text)

    def note_guided_result(self, _result: object = None) -> None:
        """A guided run finished: while the method is a classical one, the count line says that Export does not
        write the guided result shown (the method is this panel's own parameter; it does not change by itself)."""
        self.guided_seen = True
        self.refresh()

    def _on_source(self) -> None:
        import os

        self.guided_seen = False

        stream = self.session.stream
        if self._chosen_folder is not None:  # the last export folder wins: it was writable
            self.folder = self._chosen_folder
        elif stream is not None and stream.path is not None and os.access(stream.path.parent, os.W_OK):
            self.folder = stream.path.parent
        else:  # no folder of its own, or a read-only one (a mounted card, a shared data set): the home folder
            self.folder = Path.home()
        self._auto_name = True
        self._suggested = ""
        if not self.cancel_btn.isEnabled():  # a finished or failed export of the previous capture: forget it
            self.status.setText("")
            self.status.setStyleSheet("")
        self.refresh()

    def _on_tick(self, _tick: int) -> None:
        # the suggested name follows the tick; not at the display rate during playback (on pause)
        if self.session.get("export_range") == "frame" and not self.session.playing:
            self.refresh()

    def ticks(self) -> tuple[int, ...]:
        s = self.session
        if s.source is None:
            return ()
        from spikeview.session.presets import session_recipe

        try:
            return jobs.export_ticks(session_recipe(s), s.n_frames)
        except SpikeviewError:  # a value the recipe refuses: the export reports it when started
            return (int(s.tick),)

    def stem(self) -> str:
        from spikeview.export import output_stem

        s = self.session
        path = s.stream.path if s.stream is not None else None
        if s.get("export_range") == "frame":
            return output_stem(path, s.get("export_method"), tick=s.tick)
        return output_stem(path, s.get("export_method"), span=s.marked_range())

    def refresh(self) -> None:
        """Update the derived texts: frame count, slow-motion factor, the suggested file name."""
        s = self.session
        ticks = self.ticks()
        n = len(ticks)
        fmt = s.get("export_format")
        self.fps.setEnabled(fmt == "mp4")
        if s.source is None:
            self.count.setText("No capture open.")
            self.slowmo.setText("")
            return
        self.count.setText(f"{n} frame(s), centre ticks {ticks[0]}…{ticks[-1]}" if n > 1 else f"1 frame at tick {ticks[0]}")
        if self.guided_seen and s.get("export_method") != "guided":
            self.count.setText(self.count.text() + f" by {s.get('export_method').upper()}, not the guided result: "
                               "Method Guided exports it")
        if not self.cancel_btn.isEnabled() and getattr(self, "_done_ticks", None) != tuple(ticks):
            # idle: the bar reads 0 / the frames this export would write (a finished export of these frames stays full
            # until they change: a refresh right after it had emptied the bar)
            self.progress.setRange(0, max(n, 1))
            self.progress.setValue(0)
        try:
            from spikeview.export import describe_slow_motion, slow_motion_factor

            factor = slow_motion_factor(s.tick_rate, max(1, int(s.get("window"))), float(s.get("export_fps")))
            self.slowmo.setText(describe_slow_motion(factor) + (" — for MP4" if fmt != "mp4" else ""))
        except SpikeviewError as e:  # a note only; the export itself reports real errors
            self.slowmo.setText(str(e))
        if self.cluster_address():  # a batch export writes a Zarr store
            self.count.setText(self.count.text() + f" → a Zarr store, on {self.cluster_address()}")
            current = Path(self.path.text().strip() or self.stem())
            if not self._typed():
                self._set_suggestion(str(self.folder / f"{self.stem()}.zarr"))
            elif current.suffix.lower() != ".zarr":
                stem = strip_frame_field(current.stem)
                self.path.setText(str(current.with_name(f"{stem}.zarr")))
        elif not self._typed():
            self._set_suggestion(str(self.folder / suggested_name(self.stem(), fmt, n)))
        else:  # the user's path: keep it, change only the suffix (and the frame field) to the format's
            adapted = matching_name(self.path.text().strip(), fmt, n)
            if adapted != self.path.text().strip():
                self.path.setText(adapted)

    def cluster_address(self) -> str | None:
        """The Dask target typed in the panel (``local:N`` or a scheduler address), ``None`` when empty."""
        text = self.cluster.text().strip()
        return text or None

    def _browse(self) -> None:
        fmt = self.session.get("export_format")
        start = self.path.text() or str(self.folder)
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Export to", start.replace("%04d", "0000"),
                                                        f"{fmt.upper()} (*.{fmt});;All files (*)")
        if path:
            p = Path(path)
            if len(self.ticks()) > 1 and fmt != "mp4" and "%" not in p.name:
                p = p.with_name(suggested_name(p.stem, fmt, 2))
            self.folder = self._chosen_folder = p.parent
            self._auto_name = False
            self.path.setText(str(p))

    def set_state(self, state: str, message: str) -> None:
        running = state == "running"
        self.export_btn.setEnabled(not running)
        self.cancel_btn.setEnabled(running)
        self.status.setText(message)
        self.status.setStyleSheet("color: #ff6060;" if state == "failed" else "")
        if running:
            self.progress.setValue(0)
            self._done_ticks = None
            self._started = time.monotonic()

    def set_progress(self, done: int, total: int) -> None:
        """Frames done of ``total``, with the time taken, the time left and the ETA (as the CLI's progress bar)."""
        self.progress.setRange(0, max(total, 1))
        self.progress.setValue(done)
        self._done_ticks = tuple(self.ticks()) if done >= total else None
        started = getattr(self, "_started", None)
        if started is not None and self.cancel_btn.isEnabled():
            self.status.setText(progress_text(done, total, time.monotonic() - started, time.time()))


    def remember_folder(self, folder: Path) -> None:
        """The folder of a started export: the default for the next capture's exports (not the capture's own)."""
        self._chosen_folder = Path(folder)

    def set_folder(self, folder: Any) -> None:
        if folder:
            self.folder = self._chosen_folder = Path(folder)
            self.refresh()


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def progress_text(done: int, total: int, elapsed: float, now: float) -> str:
    """``"12 / 40 frames · 0:24 elapsed · 0:56 left · ETA 10:42 (2.0 s/frame)"``: what the CLI's progress bar says,
    in words; before the first frame the time left is not known yet. ``now`` is the wall clock (s since the epoch)."""
    text = f"{done} / {total} frames · {_clock(elapsed)} elapsed"
    if done <= 0 or elapsed <= 0:
        return text + " · time left after the first frame"
    per = elapsed / done
    left = per * max(total - done, 0)
    eta = time.strftime("%H:%M:%S", time.localtime(now + left))
    rate = f"{per:.1f} s/frame" if per >= 1 else f"{1 / per:.1f} frames/s"
    return text + f" · {_clock(left)} left · ETA {eta} ({rate})"
