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


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports_anywhere(path: Path, module: str) -> list[tuple[str, list[str]]]:
    """``(imported module, names)`` of every import in the file, at module level or inside functions
    (lazy imports count: they run too), relative imports resolved; ``if TYPE_CHECKING:`` blocks skipped."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for child in node.body for n in ast.walk(child))
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            out.append((base, [a.name for a in node.names]))
    return out


def _import_graph() -> dict[str, set[str]]:
    """Module → the package modules it imports (``from a import b`` names the submodule ``a.b`` when it
    is one; importing ``a.b.c`` also runs the packages ``a`` and ``a.b``)."""
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps: set[str] = set()
        for base, names in _imports_anywhere(path, name):
            if not base.startswith("spikeview"):
                continue
            targets = [f"{base}.{n}" if f"{base}.{n}" in modules else base for n in names] or [base]
            for t in targets:
                parts = t.split(".")
                deps.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
        graph[name] = {d for d in deps if d in modules and d != name and not name.startswith(d + ".")}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return groups


def test_no_import_circles_inside_the_package():
    """Every import counts, lazy ones too: a circle means two modules that cannot be understood (or moved)
    apart. Packages count as their ``__init__``: importing ``spikeview.a.b`` runs ``spikeview.a`` first."""
    graph = _import_graph()
    assert "spikeview.pipeline" in graph and graph["spikeview.cli.main"], "the scan found no modules"
    assert _cycles(graph) == [], f"import circles: {_cycles(graph)}"


def test_the_cycle_scan_finds_a_planted_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]


def _private_library_imports(path, module: str) -> list[str]:
    """The library's private names (``_name``, ``spikeview.x._module``) that ``path`` (module ``module`` of the
    app) imports; the app's own modules (``spikeview.gui`` and below, not ``spikeview.guided``) do not count."""
    out = []
    for base, names in _imports_anywhere(path, module):
        if not base.startswith("spikeview") or base == "spikeview.gui" or base.startswith("spikeview.gui."):
            continue
        private = [n for n in names if n.startswith("_") and not n.startswith("__")]  # __version__ is public
        if private or any(part.startswith("_") for part in base.split(".")):
            out.append(f"{base} {private}")
    return out


def test_gui_takes_no_private_names_from_the_library():
    """The app is display and interaction only: what it needs from the library is public API
    (no ``from spikeview.x import _name``, no ``spikeview.x._module``)."""
    offenders = [f"{path.relative_to(PKG)}: {o}" for path in (PKG / "gui").rglob("*.py")
                 for o in _private_library_imports(path, _module_name(path))]
    assert offenders == [], f"gui imports private library names: {offenders}"


def test_the_private_name_scan_finds_a_planted_import_from_guided(tmp_path):
    """``spikeview.guided`` starts with ``spikeview.gui``: the scan once skipped it, and two private imports passed."""
    planted = tmp_path / "planted.py"
    planted.write_text("def f():\n    from spikeview.guided.video import _crop_obs\n    return _crop_obs\n")
    assert _private_library_imports(planted, "spikeview.gui.planted") == ["spikeview.guided.video ['_crop_obs']"]
    fine = tmp_path / "fine.py"
    fine.write_text("from spikeview.gui import _helpers\nfrom spikeview.guided.window import crop_to_roi\n")
    assert _private_library_imports(fine, "spikeview.gui.fine") == []


FIRST_ROW = {"errors", "cfa", "config", "transfer", "_files", "_lazy", "memory", "metrics"}


def _package_imports() -> dict[str, set[str]]:
    """``{package: packages it imports}`` (spikeview's top-level names; module-level and lazy imports)."""
    out: dict[str, set[str]] = {}
    for mod, targets in _import_graph().items():
        p = mod.split(".")[1] if "." in mod else mod
        for t in targets:
            q = t.split(".")[1] if "." in t else t
            if q != p:
                out.setdefault(p, set()).add(q)
    return out


def _doc_table() -> list[tuple[list[str], str]]:
    """The rows of docs/ARCHITECTURE.md's package table: ``(packages, imports cell)``."""
    import re

    text = (PKG.parent / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    table = text.split("| package | holds | imports |", 1)[1].split("\n\n", 1)[0]
    rows = []
    for line in table.strip().splitlines()[1:]:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows.append((re.findall(r"`([\w.]+)`", cells[0]), cells[-1]))
    return rows


def test_the_architecture_docs_package_table_is_the_code():
    """Each row's imports column is what its packages import beyond the first row, no more and no less."""
    import re

    actual = _package_imports()
    rows = _doc_table()
    named = {p for pkgs, _ in rows for p in pkgs}
    real = {p for p in actual} | {t for ts in actual.values() for t in ts}
    assert real - {"__main__"} <= named, f"packages missing from the table: {sorted(real - named - {'__main__'})}"
    for pkgs, cell in rows:
        if pkgs and set(pkgs) == FIRST_ROW:
            for p in pkgs:
                assert actual.get(p, set()) <= FIRST_ROW, f"{p} imports {sorted(actual[p] - FIRST_ROW)} beyond the first row"
            continue
        if cell.startswith("everything"):
            continue
        stated = set(re.findall(r"`([\w.]+)`", cell))
        got = set().union(*(actual.get(p, set()) for p in pkgs)) - FIRST_ROW - set(pkgs)
        assert got == stated, f"docs/ARCHITECTURE.md row {pkgs}: says {sorted(stated)}, the code imports {sorted(got)}"


def test_an_observation_is_built_from_a_capture_in_one_module():
    """The one window planner: ``Observation.from_source(`` is called from guided/window.py only."""
    callers = sorted(str(p.relative_to(PKG)) for p in PKG.rglob("*.py")
                     if "from_source(" in p.read_text(encoding="utf-8") and p.name != "observation.py")
    assert callers == ["guided/window.py"], callers
