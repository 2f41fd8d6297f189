"""Architecture rules that keep the core usable without Qt and the CLI quick to start."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "spikeview"
QT_MODULES = ("PySide6", "pyqtgraph", "PyQt5", "PyQt6", "shiboken6")


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_only_gui_imports_qt():
    offenders = []
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG)
        if rel.parts[0] == "gui":
            continue
        for name in _imported_modules(path):
            if name.split(".")[0] in QT_MODULES:
                offenders.append(f"{rel}: {name}")
    assert offenders == [], f"Qt imported outside spikeview/gui: {offenders}"


def test_nothing_imports_gui_or_cli():
    offenders = []
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG)
        if rel.parts[0] in ("gui", "cli") or rel.name == "__main__.py":
            continue
        for name in _imported_modules(path):
            if name in ("spikeview.gui", "spikeview.cli") or name.startswith(("spikeview.gui.", "spikeview.cli.")):
                offenders.append(f"{rel}: {name}")
    assert offenders == [], f"core modules import the GUI/CLI: {offenders}"


@pytest.mark.parametrize("argv", [["--help"], ["info", "--help"], ["reconstruct", "--help"], ["simulate", "--help"],
                                  ["export", "--help"]])
def test_help_does_not_import_heavy_modules(argv):
    code = (
        "import sys\n"
        "from spikeview.cli.main import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = [m for m in ('torch', 'PySide6', 'pyqtgraph', 'OpenImageIO', 'av', 'numba', 'dask', 'distributed',\n"
        "                     'zarr') if m in sys.modules]\n"
        "print('HEAVY=' + ','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "usage:" in out.stdout
    assert out.stdout.strip().splitlines()[-1] == "HEAVY=", out.stdout[-300:]


def test_base_import_does_not_load_the_cluster_extra():
    """``spikeview[cluster]`` (dask, zarr) is optional: importing the package and its core must not need it."""
    code = ("import sys, spikeview, spikeview.cluster, spikeview.io, spikeview.classical, spikeview.guided, spikeview.export\n"
            "print('LOADED=' + ','.join(m for m in ('dask', 'distributed', 'zarr') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "LOADED=", out.stdout[-300:]
