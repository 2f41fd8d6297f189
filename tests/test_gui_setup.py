"""Setting up and starting the app: system libraries Qt needs, and a clear message without a display.

Issue 10, item 1: on a fresh Debian machine Qt aborted (exit 134) because its X11 plugin's libraries
were missing, and over SSH ``spikeview`` aborted instead of saying there is no display.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from spikeview.cli.main import QT_SYSTEM_PACKAGES, display_problem

ROOT = Path(__file__).resolve().parents[1]


def _readme_first_command() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## Set up\n.*?```bash\n(.*?)\n```", text, re.S)
    assert block is not None, "README's Set up section has no bash block"
    return block.group(1).strip()


def test_readme_first_command_installs_the_qt_system_packages_and_opens_the_app():
    cmd = _readme_first_command()
    assert "\n" not in cmd and cmd.endswith("&& spikeview")
    apt = re.search(r"apt-get install -y ((?:[\w.+-]+ ?)+)", cmd)
    assert apt is not None
    assert set(QT_SYSTEM_PACKAGES.split()) <= set(apt.group(1).split())  # the app's hint names the same packages
    assert "pip install -e" in cmd


def test_ci_installs_the_readme_way():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert "grep -m1 '^sudo apt-get update && sudo apt-get install' README.md" in ci
    assert _readme_first_command().startswith("sudo apt-get update && sudo apt-get install")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the xcb platform plugin exists on Linux only")
def test_qt_x11_plugin_libraries_resolve():
    """``ldd`` on Qt's xcb platform plugin and its QPA library finds every library (README's packages installed)."""
    if shutil.which("ldd") is None:
        pytest.skip("ldd is not available on this system")
    pyside = pytest.importorskip("PySide6")
    qt = Path(pyside.__file__).parent / "Qt"
    plugin = qt / "plugins" / "platforms" / "libqxcb.so"
    qpa = next((qt / "lib").glob("libQt6XcbQpa.so*"), None)
    assert plugin.exists() and qpa is not None
    for lib in (plugin, qpa):
        out = subprocess.run(["ldd", str(lib)], capture_output=True, text=True, check=True).stdout
        missing = sorted({line.split()[0] for line in out.splitlines() if "not found" in line})
        assert not missing, f"{lib.name} misses {missing}: install the README's system packages (README, Set up)"


def test_no_display_is_one_sentence_and_exit_1():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    if not sys.platform.startswith("linux"):
        pytest.skip("macOS and Windows always have a display")
    out = subprocess.run([sys.executable, "-m", "spikeview.cli.main"], capture_output=True, text=True, env=env,
                         timeout=120, check=False)
    assert out.returncode == 1, out.stderr
    assert out.stdout == ""
    assert out.stderr == ("spikeview: error: no display found; use the command-line sub-commands (spikeview --help), "
                          "or set QT_QPA_PLATFORM=offscreen for screenshots.\n")


def test_display_problem_decisions():
    ok = lambda path: None  # noqa: E731 - a loader that finds everything

    def missing(path):
        raise OSError("libxcb-icccm.so.4: cannot open shared object file: No such file or directory")

    assert display_problem({}, "darwin", ok) is None and display_problem({}, "win32", ok) is None
    assert display_problem({}, "linux", ok).startswith("no display found")
    assert display_problem({"QT_QPA_PLATFORM": "offscreen"}, "linux", missing) is None
    assert display_problem({"WAYLAND_DISPLAY": "wayland-0"}, "linux", missing) is None
    assert display_problem({"DISPLAY": ":0"}, "linux", ok) is None
    msg = display_problem({"DISPLAY": ":0"}, "linux", missing)
    if msg is None:
        pytest.skip("PySide6's xcb plugin is not installed here")
    assert "libxcb-icccm.so.4 is missing" in msg and "sudo apt-get install -y libxcb-cursor0" in msg
