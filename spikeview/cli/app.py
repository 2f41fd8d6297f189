"""``spikeview app`` (also ``spikeview`` alone or ``spikeview FILE``): the desktop app.

With ``--screenshot OUT.png`` the window renders off-screen after the given actions, is saved, and the command
exits (:func:`spikeview.gui.screenshot.render`): the README's screenshot and the layout tests are made this way.
"""

from __future__ import annotations

import argparse

from spikeview.errors import ParameterError


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="FILE", help="capture to open (default: the built-in demo capture)")
    g = p.add_argument_group("screenshot (render the window off-screen after the actions below, save it and exit)")
    g.add_argument("--screenshot", metavar="OUT.png", help="save the window to this PNG and exit")
    g.add_argument("--size", default="1366x768", metavar="WxH", help="window size, the screen it stands for (default 1366x768)")
    g.add_argument("--run", choices=("guided", "tfp"), help="run a guided reconstruction of the window first (guided), or "
                   "show the TFP (tfp)")
    g.add_argument("--view", metavar="A[:MODE:B]", help="what the central canvas shows: an image (spikes, tfp, tfi, guided, "
                   "guided_prev, truth, deg:mx, deg:cmx, deg:qcmx, deg:y, deg:residual), or A:MODE:B with MODE one of "
                   "single, wipe, side, diff (e.g. guided:wipe:tfp)")
    g.add_argument("--truth", metavar="IMAGE", help="load this image as the capture's ground truth (File ▸ Load ground truth…)")
    g.add_argument("--tick", type=int, help="go to this tick first")
    g.add_argument("--roi", metavar="X,Y,W,H", help="set this region of interest first")
    g.add_argument("--pixel", metavar="X,Y", help="show the readout of this frame pixel in the status bar")
    g.add_argument("--export", metavar="FILE", help="export with the Export panel's settings to FILE after the run")
    g.add_argument("--reset-layout", action="store_true", help="View ▸ Reset layout before the screenshot")
    g.add_argument("--panel", metavar="NAME", help="bring this panel's tab to the front (stream, guided, compare, export, "
                   "rates, degradation)")
    g.add_argument("--demo-size", type=int, metavar="N", help="the demo capture's size (N×N, default 256)")


def _ints(text: str | None, n: int, flag: str) -> tuple[int, ...] | None:
    if text is None:
        return None
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n:
        raise ParameterError(f"{flag} {text!r}: give {n} whole numbers separated by commas.")
    return vals


def run(args: argparse.Namespace) -> int:
    try:
        from spikeview.gui.app import run_app
    except ImportError as e:
        raise ParameterError(f"the desktop app is not available in this installation ({e}); use the sub-commands (spikeview --help).") from None
    if args.screenshot:
        return screenshot(args)
    given = [flag for flag, value in (("--run", args.run), ("--view", args.view), ("--truth", args.truth),
                                      ("--tick", args.tick), ("--roi", args.roi), ("--pixel", args.pixel),
                                      ("--export", args.export), ("--reset-layout", args.reset_layout),
                                      ("--panel", args.panel), ("--demo-size", args.demo_size)) if value]
    if given or args.size != "1366x768":
        given = given or ["--size"]
        raise ParameterError(f"{', '.join(given)} only act{'s' if len(given) == 1 else ''} with --screenshot OUT.png; "
                             "in the open app use its menus (File ▸ Load ground truth…, the canvas's A/B menus, Guided ▸ Run).")
    return run_app(args.input)


def screenshot(args: argparse.Namespace) -> int:
    from spikeview.gui import screenshot as shot

    try:
        size = shot.parse_size(args.size)
        shot.parse_view(args.view) if args.view else None
    except ValueError as e:
        raise ParameterError(str(e)) from None
    try:
        r = shot.render(args.screenshot, args.input, size=size, run=args.run, view=args.view, truth=args.truth,
                        roi=_ints(args.roi, 4, "--roi"), tick=args.tick, pixel=_ints(args.pixel, 2, "--pixel"),
                        export=args.export, reset_layout=args.reset_layout, demo_size=args.demo_size,
                        panel=args.panel)
    except (RuntimeError, TimeoutError, ValueError) as e:
        raise ParameterError(str(e)) from None
    return shot.report(args.screenshot, r, size)
