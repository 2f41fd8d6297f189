"""Render the app's window to a PNG after an action and exit: ``spikeview app [FILE] --screenshot OUT.png``.

Options (:func:`render`): the window size (``--size WxH``, the screen it stands for), a guided run or the TFP
(``--run guided|tfp``), what the canvas shows (``--view A`` or ``--view A:MODE:B``, e.g. ``guided:wipe:tfp``),
a ground-truth image (``--truth``), an ROI, a tick, the pixel whose readout is shown (``--pixel X,Y``), an
export of the current frame (``--export FILE``) and View ▸ Reset layout (``--reset-layout``). The window
renders off-screen (no display needed); settings go to a temporary file, the user's own are not touched.
Prints the window's and the canvas's sizes and pixel statistics of the image, so a blank grab is noticed;
the layout tests read the same numbers from :func:`render`.

The README's screenshot::

    spikeview app --screenshot docs/screenshot.png --size 1366x768 --run guided --view guided:wipe:tfp
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: seconds to wait for one step (opening, frames, a guided run, an export) before giving up
STEP_TIMEOUT_S = 600.0


@dataclass
class Rendered:
    """What :func:`render` saw: the window's and the canvas image view's sizes (px), the share of the window's
    area the canvas's image view takes, the readout shown, the image's statistics."""

    window: tuple[int, int]
    canvas: tuple[int, int]
    canvas_fraction: float
    readout: str
    stats: dict[str, float]
    #: the window's size after each action (``"open"``, ``"run"``, ``"export"``, ``"reset layout"``, ``"view"``)
    steps: list[tuple[str, tuple[int, int]]] = field(default_factory=list)


def _wait(app: Any, cond: Any, what: str, errors: list[str] | None = None, timeout: float = STEP_TIMEOUT_S) -> None:
    end = time.perf_counter() + timeout
    n = len(errors) if errors is not None else 0
    while not cond():
        if errors is not None and len(errors) > n:
            raise RuntimeError(f"screenshot: {what} failed: {errors[-1]}")
        if time.perf_counter() > end:
            raise TimeoutError(f"screenshot: timed out waiting for {what}")
        app.processEvents()
        time.sleep(0.005)


def _spin(app: Any, seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.005)


def image_stats(path: Path) -> dict[str, float]:
    """Mean, standard deviation and share of distinct colours of a PNG (a blank grab has std ≈ 0)."""
    from PySide6 import QtGui

    img = QtGui.QImage(str(path)).convertToFormat(QtGui.QImage.Format.Format_RGB888)
    w, h = img.width(), img.height()
    arr = np.frombuffer(img.constBits(), np.uint8, count=img.sizeInBytes()).reshape(h, img.bytesPerLine())[:, : 3 * w]
    arr = arr.reshape(h, w, 3)
    colours = np.unique(arr[::4, ::4].reshape(-1, 3), axis=0).shape[0]
    return {"width": w, "height": h, "mean": float(arr.mean()), "std": float(arr.std()), "colours": colours}


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size {text!r}: give the window size as WIDTHxHEIGHT, e.g. 1366x768") from None
    if w < 320 or h < 240:
        raise ValueError(f"--size {text!r}: the window needs at least 320x240")
    return w, h


def parse_view(text: str) -> tuple[str, str | None, str | None]:
    """``A`` or ``A:MODE:B`` (keys of :data:`spikeview.gui.canvas.SOURCES` and :data:`~spikeview.gui.canvas.MODES`)."""
    from spikeview.gui.canvas import MODES, SOURCES

    parts = text.split(":")
    if text.startswith("deg:"):  # a degradation stage's key has a colon of its own
        parts = [":".join(parts[:2]), *parts[2:]]
    if len(parts) > 3 and parts[2] == "deg":
        parts = [parts[0], parts[1], ":".join(parts[2:])]
    a, mode, b = (parts + [None, None])[:3]
    for key, table, what in ((a, SOURCES, "image"), (mode, MODES, "mode"), (b, SOURCES, "image")):
        if key is not None and key not in table:
            raise ValueError(f"--view {text!r}: {key!r} is no {what}; choose one of {', '.join(table)}")
    if mode is not None and mode != "single" and b is None:
        raise ValueError(f"--view {text!r}: the mode {mode} compares two images: give A:{mode}:B")
    return a, mode, b


def render(out: str | Path, path: str | Path | None = None, *, size: tuple[int, int] = (1366, 768),
           run: str | None = None, view: str | None = None, truth: str | Path | None = None,
           roi: tuple[int, int, int, int] | None = None, tick: int | None = None, pixel: tuple[int, int] | None = None,
           export: str | Path | None = None, reset_layout: bool = False, demo_size: int | None = None,
           panel: str | None = None) -> Rendered:
    """Open ``path`` (or the demo capture) in a window of ``size``, do the actions in order (ground truth, tick,
    ROI, run, export, reset layout, view, the panel in front, pixel), wait until every preview is idle, save the window
    to ``out``. ``panel`` names the dock whose tab is brought to the front (``compare``, ``guided``, ``export``, …)."""
    from PySide6 import QtCore

    from spikeview.gui.app import make_application
    from spikeview.gui.main_window import MainWindow

    if run not in (None, "guided", "tfp"):
        raise ValueError(f"--run {run!r}: choose guided or tfp")
    parsed_view = parse_view(view) if view else None
    app = make_application()
    out = Path(out)
    with tempfile.TemporaryDirectory() as tmp:
        settings = QtCore.QSettings(str(Path(tmp) / "settings.ini"), QtCore.QSettings.Format.IniFormat)
        w = MainWindow(settings=settings)
        w.resize(*size)
        w.show()
        steps: list[tuple[str, tuple[int, int]]] = []
        try:
            if panel is not None and panel not in w.docks:
                raise ValueError(f"--panel {panel!r}: choose one of {', '.join(w.docks)}")
            _act(app, w, path, run, parsed_view, truth, roi, tick, pixel, export, reset_layout, demo_size, steps, panel)
            out.parent.mkdir(parents=True, exist_ok=True)
            if not w.grab().save(str(out)):
                raise OSError(f"could not write {out}")
            v = w.canvas.a.view
            result = Rendered((w.width(), w.height()), (v.width(), v.height()),
                              v.width() * v.height() / max(w.width() * w.height(), 1), w.canvas.last_readout,
                              image_stats(out), steps)
        finally:
            w.close()
            app.processEvents()
            w.deleteLater()
            QtCore.QCoreApplication.sendPostedEvents(None, QtCore.QEvent.Type.DeferredDelete)
    return result


def _act(app: Any, w: Any, path: Any, run: str | None, view: tuple[str, str | None, str | None] | None, truth: Any,
         roi: Any, tick: int | None, pixel: tuple[int, int] | None, export: Any, reset_layout: bool,
         demo_size: int | None, steps: list[tuple[str, tuple[int, int]]], panel: str | None = None) -> None:
    c, s = w.controller, w.session

    def step(what: str) -> None:
        _spin(app, 0.3)  # the layout settles
        steps.append((what, (w.width(), w.height())))

    if path is None:
        w.open_demo(*(() if demo_size is None else (demo_size,)))
    else:
        w.open_path(path)
    _wait(app, lambda: s.stream is not None or (w.settings_dialog is not None), "the capture", w.errors_shown)
    if s.stream is None:  # a file without a sidecar: the dialog's first guess, as the user would accept it
        dlg = w.settings_dialog
        _wait(app, lambda: dlg.stream is not None or bool(dlg.error.text().strip()), "the capture's preview",
              w.errors_shown)
        if dlg.stream is None:  # the dialog's first guess does not fit: a user would see why and choose; no one here
            raise RuntimeError(f"screenshot: {Path(str(path)).name}: {dlg.error.text().strip()}")
        geo = dlg.settings or {}
        print(f"spikeview: note: {Path(str(path)).name} has no sidecar: opened with the settings dialog's first guess "
              f"({geo.get('width', '?')}x{geo.get('height', '?')}, CFA {geo.get('cfa') or 'none'}, "
              f"{'flipped' if geo.get('flip_vertical') else 'not flipped'} vertically); `spikeview info` lists the "
              "other geometries that fit, and the app's dialog lets you choose one.", file=sys.stderr)
        dlg.accept()
        _wait(app, lambda: s.stream is not None, "the capture", w.errors_shown)
    # the first frames and the capture's exposure (the white point the CLI would use; α too for a colour capture)
    _wait(app, lambda: c.last_frames is not None and getattr(c, "capture_white", None) is not None
          and (c.alpha is not None or s.source.cfa is None), "the first frames", c.errors)
    step("open")
    if truth is not None and not w.load_truth(truth):
        raise RuntimeError(f"screenshot: the ground truth was refused: {w.notice.text()}")
    n, h, wd = s.source.n_frames, s.source.height, s.source.width
    if tick is not None:
        if not 0 <= int(tick) < n:
            raise ValueError(f"--tick {tick} is outside the capture, which holds ticks 0 to {n - 1}; choose one inside it.")
        s.set_tick(int(tick))
    if roi is not None:
        x, y, rw, rh = (int(v) for v in roi)
        if x < 0 or y < 0 or rw < 1 or rh < 1 or x + rw > wd or y + rh > h:
            raise ValueError(f"--roi {x},{y},{rw},{rh} does not lie inside the {wd}x{h} frame; give X,Y,W,H with "
                             f"X+W <= {wd} and Y+H <= {h}.")
        s.set_roi((x, y, rw, rh))
    if pixel is not None and not (0 <= pixel[0] < wd and 0 <= pixel[1] < h):
        raise ValueError(f"--pixel {pixel[0]},{pixel[1]} is outside the {wd}x{h} frame; give X,Y with X < {wd} and "
                         f"Y < {h}.")
    _wait(app, lambda: c.last_frames is not None and c.last_frames.tick == s.tick, f"frames at tick {s.tick}", c.errors)
    if run == "guided":
        n = c.run_guided()
        _wait(app, lambda: c.guided_result is not None and c.guided_result.run == n, f"guided run {n}", c.errors)
        if view is None:
            w.canvas.set_view("guided", "wipe", "tfp")
    elif run == "tfp" and view is None:
        w.canvas.set_view("tfp", "single")
    if run is not None:
        step("run")
    if export is not None:
        from spikeview.export.base import existing_frame_files

        if existing_frame_files(str(export)):  # the app would ask before replacing them; no one is there to answer
            raise ValueError(f"--export {export}: the file already exists; choose another name or delete it first "
                             "(the app asks before replacing files, and a screenshot run has no one to answer).")
        fmt = Path(str(export)).suffix.lower().lstrip(".")
        if fmt in ("png", "exr", "mp4"):
            s.set("export_format", fmt)
        w.export_panel.path.setText(str(export))
        w.export_now()
        _wait(app, lambda: w.notice.kind in ("success", "error") and not c.exporter.is_active(), "the export", c.errors)
        if w.notice.kind == "error":
            raise RuntimeError(f"screenshot: the export failed: {w.notice.text()}")
        step("export")
    if reset_layout:
        w.default_layout()
        step("reset layout")
    if view is not None:
        w.canvas.set_view(*view)
    if panel is not None:
        w.docks[panel].show()
        w.docks[panel].raise_()
    if s.stream is not None and s.stream.ground_truth is not None and c.enabled.get("compare"):
        done = w.canvas.compares
        c.compare_timer.stop()
        c.submit_compare()  # at once: no debounce to wait for
        _wait(app, lambda: w.canvas.compares > done, "the scores against the ground truth", c.errors)
    _wait(app, lambda: not c.preview.is_active() and not c.tfi.is_active() and not c.scorer.is_active(), "idle previews",
          c.errors)
    _spin(app, 0.6)  # the dock layout and the throttled panels settle
    w.canvas.fit()
    _spin(app, 0.3)
    if pixel is not None:
        w.canvas.point_at(*pixel)
        _spin(app, 0.1)
    step("view")


def make_screenshot(out: Path, size: tuple[int, int] = (1366, 768)) -> dict[str, float]:
    """The README's screenshot: the demo after a guided run, its x̂₀ split against the TFP."""
    return render(out, size=size, run="guided", view="guided:wipe:tfp").stats


def report(out: Path, r: Rendered, screen: tuple[int, int]) -> int:
    """Print what :func:`render` saw; 1 when the image looks blank or the window outgrew the screen."""
    s = r.stats
    print(f"{out}: {s['width']}x{s['height']}, mean {s['mean']:.1f}, std {s['std']:.1f}, {s['colours']} colours; "
          f"window {r.window[0]}x{r.window[1]} on a {screen[0]}x{screen[1]} screen, canvas {r.canvas[0]}x{r.canvas[1]} "
          f"({r.canvas_fraction:.0%} of the window)")
    if r.readout:
        print(f"pixel: {r.readout}")
    status = 0
    if s["std"] < 5 or s["colours"] < 50:
        print("spikeview: the image looks blank", file=sys.stderr)
        status = 1
    for what, (ww, wh) in r.steps:
        if ww > screen[0] or wh > screen[1]:
            print(f"spikeview: after {what} the window ({ww}x{wh}) outgrew the screen", file=sys.stderr)
            status = 1
    return status


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Save a screenshot of the spikeview window after a guided run.")
    ap.add_argument("out", type=Path, help="PNG file to write (e.g. docs/screenshot.png)")
    ap.add_argument("--size", default="1366x768", help="window size WxH (default 1366x768)")
    args = ap.parse_args(argv)
    size = parse_size(args.size)
    return report(args.out, render(args.out, size=size, run="guided", view="guided:wipe:tfp"), size)


if __name__ == "__main__":
    raise SystemExit(main())
