"""The ``spikeview`` command.

Only argparse and the error classes are imported at start-up: numpy-heavy and torch/Qt modules are
imported inside the sub-command that needs them, so ``spikeview --help`` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import os
from pathlib import Path
import sys
from typing import Callable, Sequence

from spikeview import __version__
from spikeview.errors import Cancelled, SpikeviewError

EPILOG = """examples:
  spikeview                                   open the app on the built-in demo capture
  spikeview capture.dat                       open a capture in the app
  spikeview info capture.dat --width 1000 --height 1000 --cfa BGGR
  spikeview simulate --demo --ticks 2000 --out demo.dat
  spikeview reconstruct demo.dat --method tfp --window 10 --at 1000 --out frame.png
  spikeview reconstruct demo.dat --method tfi --range 0:2000:20 --out clip.mp4 --fps 30
"""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in the CLI's one-sentence form: the mistake and where the options are listed (its
    default printed the whole usage, ~40 lines for ``reconstruct``, before the one line that mattered)."""

    def error(self, message: str) -> None:  # type: ignore[override]  # argparse's signature
        self.exit(2, f"{self.prog}: error: {message} ({self.prog} --help lists the options)\n")


def _unknown_options(parser: argparse.ArgumentParser, args: argparse.Namespace, extras: list[str]) -> str:
    """The sentence for options the command does not know, with the nearest one it does (``--methd`` → ``--method``)."""
    import difflib

    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)  # noqa: SLF001
    command = sub.choices.get(getattr(args, "command", None) or "") if sub is not None else None
    known = [o for a in (command or parser)._actions for o in a.option_strings]  # noqa: SLF001
    prog = command.prog if command is not None else parser.prog
    names = {o.lstrip("-"): o for o in known if o.startswith("--")}  # the shared "--" made unrelated names look alike
    hints = [names[near[0]] for e in extras if e.startswith("--")
             for near in [difflib.get_close_matches(e.split("=")[0].lstrip("-"), list(names), n=1, cutoff=0.7)] if near]
    return (f"{prog}: error: unrecognized arguments: {' '.join(extras)}"
            + (f" (did you mean {' or '.join(hints)}?)" if hints else "") + f"; {prog} --help lists the options")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="spikeview",
        description="View, simulate and reconstruct chromatic spike-camera captures.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"spikeview {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    from spikeview.cli._common import add_geometry_flags
    from spikeview.cli.commands import COMMANDS

    for name, command in COMMANDS.items():
        module = importlib.import_module(command.module)
        p = sub.add_parser(name, help=command.help, description=command.help,
                           formatter_class=argparse.RawDescriptionHelpFormatter, epilog=getattr(module, "EPILOG", None))
        module.add_args(p)
        if getattr(module, "GEOMETRY", False):
            add_geometry_flags(p)
        p.set_defaults(func=module.run)
    return parser


def _print_error(message: str) -> None:
    print(f"spikeview: error: {message}", file=sys.stderr)


#: the system packages Qt's X11 platform plugin needs on Debian/Ubuntu (README, "Set up")
QT_SYSTEM_PACKAGES = ("libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-randr0 libxcb-render-util0 "
                      "libxcb-shape0 libxcb-xkb1 libxkbcommon-x11-0 libegl1 libgl1 libfontconfig1 libdbus-1-3")


def display_problem(environ: dict[str, str] | None = None, platform: str | None = None,
                    load: Callable[[str], object] | None = None) -> str | None:
    """Why the app cannot open a window here, in one sentence, or ``None`` when it can.

    Checked before Qt starts, because Qt aborts the process (exit 134) without a display or when its
    X11 plugin's libraries are missing. Only Linux and the BSDs are checked (macOS and Windows always
    have a display). ``load`` loads a shared library (default :class:`ctypes.CDLL`; tests inject one).
    """
    env = os.environ if environ is None else environ
    platform = sys.platform if platform is None else platform
    if not platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return None
    qpa = env.get("QT_QPA_PLATFORM", "")
    if not qpa and not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY"):
        return ("no display found; use the command-line sub-commands (spikeview --help), "
                "or set QT_QPA_PLATFORM=offscreen for screenshots.")
    if qpa.split(":")[0] not in ("", "xcb") or (not qpa and env.get("WAYLAND_DISPLAY") and not env.get("DISPLAY")):
        return None  # not the X11 plugin (Wayland, offscreen, …): Qt reports its own problems
    import importlib.util

    spec = importlib.util.find_spec("PySide6")
    if spec is None or not spec.submodule_search_locations:
        return None  # no Qt at all: the app command says so
    plugin = os.path.join(list(spec.submodule_search_locations)[0], "Qt", "plugins", "platforms", "libqxcb.so")
    if not os.path.exists(plugin):
        return None
    if load is None:
        import ctypes

        load = ctypes.CDLL
    try:
        load(plugin)
    except OSError as e:
        missing = str(e).split(":")[0].strip() if "cannot open shared object" in str(e) else str(e)
        return (f"Qt's X11 plugin cannot load ({missing} is missing); on Debian/Ubuntu install the system packages "
                f"with: sudo apt-get install -y {QT_SYSTEM_PACKAGES} (elsewhere: the X11/xcb libraries, libxkbcommon-x11, "
                "EGL/OpenGL, fontconfig and D-Bus from your distribution).")
    return None


def _stdout_closed() -> bool:
    """True when standard output is a pipe whose reader has gone (a BrokenPipeError from a worker's socket is
    not); stdout then points at os.devnull so that Python's flush at exit does not print "Exception ignored …"."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):
        return False
    try:
        import select

        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        gone = any(events & select.POLLERR for _, events in poller.poll(0))  # a pipe without reader: POLLERR
    except (AttributeError, OSError):  # no poll() (Windows): take the broken pipe to be stdout's
        gone = True
    if gone:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    return gone


def _format_warning(message, category, filename, lineno, line=None) -> str:  # noqa: ANN001 - warnings' signature
    """A warning as the CLI's other messages: one line, no source path (e.g. a colour channel without spikes,
    OpenVINO giving up mid-run)."""
    return f"spikeview: warning: {message}\n"


#: what to do when a command runs out of memory (the end of its one sentence)
MEMORY_FIX = {
    "reconstruct": "reconstruct a shorter range or a smaller region.",
    "export": "export a shorter range.",
    "simulate": "simulate a smaller --size or fewer --ticks.",
    "bench": "run it with a smaller --size.",
    "calibrate": "calibrate from shorter captures.",
    "info": "the capture is too large to describe here.",
}


def _unknown_command(word: str, commands: list[str]) -> str | None:
    """The sentence for a first word that is neither a command nor a file (``spikeview infoo x.dat``: it would be
    opened in the app, and argparse would name the wrong thing); ``None`` where the word may be a capture to open."""
    import difflib

    path = Path(word)
    if path.exists() or path.suffix or any(c in word for c in "/\\*?") or not word.isidentifier():
        return None
    near = difflib.get_close_matches(word, commands, n=1)
    hint = f"did you mean '{near[0]}'? " if near else ""
    return (f"{word!r} is not a command nor a file; {hint}the commands are {', '.join(commands)} "
            "(spikeview --help), or give a capture to open in the app.")


def _on_sigterm(flag: list) -> tuple[object] | None:
    """A SIGTERM (``kill``, ``timeout``) ends the command as Ctrl-C does, removing its unfinished output (the default
    action left a simulation's hidden temporary files, 655 MB, behind); returns ``(the handler it replaces,)``
    (``None`` off the main thread, where Python cannot set one)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: object) -> None:
        flag.append(signum)
        raise KeyboardInterrupt

    try:
        return (signal.signal(signal.SIGTERM, handler),)
    except (ValueError, OSError):
        return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status (0 ok, 1 failed, 2 bad usage, 130 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    import warnings

    warnings.formatwarning = _format_warning
    from spikeview.cli.commands import COMMANDS

    # `spikeview` alone or `spikeview FILE` opens the app.
    if not argv or (argv[0] not in COMMANDS and not argv[0].startswith("-")):
        unknown = _unknown_command(argv[0], list(COMMANDS)) if argv else None
        if unknown is not None:
            _print_error(unknown)
            return 2
        argv = ["app", *argv]
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    if extras:
        print(_unknown_options(parser, args, extras), file=sys.stderr)
        return 2
    if args.command == "app":
        inp = getattr(args, "input", None)
        if inp and not Path(str(inp)).exists():  # the file first: a display would not help a missing file
            _print_error(f"{inp}: file not found; check the path.")
            return 1
        if getattr(args, "screenshot", None):  # a screenshot renders off-screen: no display needed
            os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
        problem = display_problem()
        if problem is not None:
            _print_error(problem)
            return 1
    run: Callable[[argparse.Namespace], int] = args.func
    terminated = []
    previous = _on_sigterm(terminated) if args.command not in ("app", "live") else None
    try:
        return int(run(args) or 0)
    except SpikeviewError as e:
        _print_error(str(e))
        return 1
    except (Cancelled, KeyboardInterrupt):
        _print_error(("terminated" if terminated else "interrupted")
                     + "; files already finished are kept, the unfinished one was removed.")
        return 143 if terminated else 130
    except MemoryError:
        _print_error("out of memory; " + MEMORY_FIX.get(args.command, MEMORY_FIX["reconstruct"]))
        return 1
    except Exception as e:  # last resort: one line, never a traceback (set SPIKEVIEW_DEBUG=1 to see it)
        if isinstance(e, BrokenPipeError) and _stdout_closed():
            return 1  # the reader of our output went away (`spikeview info FILE | head`): stop quietly, like cat
        if os.environ.get("SPIKEVIEW_DEBUG"):
            raise
        _print_error(f"unexpected {type(e).__name__}: {e} (this is a bug; rerun with SPIKEVIEW_DEBUG=1 and report the traceback).")
        return 1
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous[0] if previous[0] is not None else signal.SIG_DFL)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
