"""Make the README screenshot: the main window with every panel populated.

Usage (on a display, or under Xvfb)::

    xvfb-run -a -s "-screen 0 1920x1200x24" python -m spikeview.gui.screenshot docs/screenshot.png

It opens the demo capture with every parameter at its default, plays a little (so the colour-cast
history has points), draws an ROI over the fan, runs a guided reconstruction of the ROI (its PSNR/SSIM
curves), exports the current frame (the notification), then grabs the window. Settings go to a temporary file: the user's own
settings are not touched. Prints pixel statistics of the image so a blank grab is noticed.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _wait(app, cond, timeout: float = 300.0, what: str = "", errors: list[str] | None = None) -> None:
    end = time.perf_counter() + timeout
    while not cond():
        if errors:
            raise RuntimeError(f"screenshot: {what} failed: {errors[-1]}")
        if time.perf_counter() > end:
            raise TimeoutError(f"screenshot: timed out waiting for {what}")
        app.processEvents()
        time.sleep(0.005)


def _spin(app, seconds: float) -> None:
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


def make_screenshot(out: Path, size: tuple[int, int] = (1800, 1080)) -> dict[str, float]:
    from PySide6 import QtCore

    from spikeview.gui.app import make_application
    from spikeview.gui.main_window import MainWindow

    app = make_application()
    with tempfile.TemporaryDirectory() as tmp:
        settings = QtCore.QSettings(str(Path(tmp) / "settings.ini"), QtCore.QSettings.Format.IniFormat)
        w = MainWindow(settings=settings)
        w.resize(*size)
        w.show()
        try:
            _populate(app, w, Path(tmp), out)
        finally:
            w.close()
            app.processEvents()
    return image_stats(out)


def _populate(app, w, tmp: Path, out: Path) -> None:
    from spikeview.session.model import SPECS

    w.open_demo()
    _wait(app, lambda: w.session.stream is not None, what="the demo capture")
    s, c = w.session, w.controller
    _wait(app, lambda: c.last_frames is not None and c.alpha is not None, what="the first frames")
    # every parameter at its default (the README shows what a new user sees); only playback's speed is
    # changed for the short play below, and set back
    s.update_params({"speed": "window"}, record=False)
    # a little playback: the colour-cast history gets points
    s.set_tick(200)
    s.set_mark_in()
    s.set_tick(800)
    s.set_mark_out()
    s.set_tick(200)
    s.set_playing(True)
    _spin(app, 4.0)
    s.set_playing(False)
    s.update_params({"speed": SPECS["speed"].default}, record=False)
    s.set_tick(640)
    s.set_roi((150, 144, 96, 96))  # the fan (lower right of the demo scene)
    _wait(app, lambda: c.last_frames is not None and c.last_frames.tick == 640, what="frames at tick 640")
    run = c.run_guided()  # the default recipe
    _wait(app, lambda r=run: c.guided_result is not None and c.guided_result.run == r, what=f"guided run {run}",
          errors=c.errors)
    _wait(app, lambda: w.degradation_panel.last is not None and "guided" in w.degradation_panel.panes["x"].title.text(),
          what="the degradation preview of the guided result")
    s.set("export_format", "png")
    w.export_panel.path.setText(str(tmp / "demo_tfp_t640.png"))
    w.export_now()
    _wait(app, lambda: w.notice.kind == "success", what="the export")
    _wait(app, lambda: not c.preview.is_active() and not c.tfi.is_active(), what="idle previews")
    _spin(app, 1.0)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not w.grab().save(str(out)):
        raise OSError(f"could not write {out}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Save a screenshot of the spikeview window with every panel populated.")
    ap.add_argument("out", type=Path, help="PNG file to write (e.g. docs/screenshot.png)")
    ap.add_argument("--size", default="1800x1080", help="window size WxH (default 1800x1080)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    stats = make_screenshot(args.out, (w, h))
    print(f"{args.out}: {stats['width']}x{stats['height']}, mean {stats['mean']:.1f}, std {stats['std']:.1f}, "
          f"{stats['colours']} colours")
    if stats["std"] < 5 or stats["colours"] < 50:
        print("the image looks blank", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
