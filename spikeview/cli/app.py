"""``spikeview app`` (also ``spikeview`` alone or ``spikeview FILE``): the desktop app."""

from __future__ import annotations

import argparse

from spikeview.errors import ParameterError


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="FILE", help="capture to open (default: the built-in demo capture)")


def run(args: argparse.Namespace) -> int:
    try:
        from spikeview.gui.app import run_app
    except ImportError as e:
        raise ParameterError(f"the desktop app is not available in this installation ({e}); use the sub-commands (spikeview --help).") from None
    return run_app(args.input)
