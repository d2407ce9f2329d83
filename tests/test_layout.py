"""The library never imports the application.

The library (admittance.systems and admittance.diagrams outside app/: scenario, closed
loop, simulation, analysis, plots) builds and runs the model; the application
(admittance.diagrams.app: the command line, result folders, bench, compare, sweep, the
stability report) is a layer on top of it. The dependency goes one way only.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
APPLICATION = "admittance.diagrams.app"
# The folders of the library, and their import names.
LIBRARY = {"systems": "admittance.systems", "diagrams": "admittance.diagrams"}
# A module longer than this holds more than one topic (the longest today: bench.py, 593).
MAX_MODULE_LINES = 650


def _library_files() -> dict[str, Path]:
    """Module name -> file, for every library module in the repository."""
    modules = {}
    for folder, package in LIBRARY.items():
        for path in sorted((REPOSITORY / folder).glob("*.py")):
            name = package if path.stem == "__init__" else f"{package}.{path.stem}"
            modules[name] = path
    return modules


def _imported_names(path: Path, module: str) -> set[str]:
    """Every module `path` imports, absolute, at any depth (function bodies included)."""
    names = set()
    package = module if path.stem == "__init__" else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the module's package
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def test_library_modules_import_no_application_module():
    modules = _library_files()
    assert (
        "admittance.diagrams.closed_loop" in modules and "admittance.systems.flexiforce" in modules
    )
    offending = {
        name: sorted(n for n in _imported_names(path, name) if n.startswith(APPLICATION))
        for name, path in modules.items()
    }
    assert {name: found for name, found in offending.items() if found} == {}


def test_importing_the_whole_library_loads_no_application_module():
    """In a fresh interpreter: every library module imported, no application module loaded."""
    modules = sorted(_library_files())
    script = (
        "import importlib, json, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        f"print(json.dumps(sorted(m for m in sys.modules if m.startswith({APPLICATION!r}))))\n"
    )
    completed = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr
    assert json.loads(completed.stdout) == []


@pytest.mark.parametrize("folder", ["systems", "diagrams", "diagrams/app", "diagrams/app/sweep"])
def test_no_module_holds_more_than_one_topic(folder):
    lengths = {
        path.name: len(path.read_text().splitlines()) for path in (REPOSITORY / folder).glob("*.py")
    }
    assert lengths and {n: k for n, k in lengths.items() if k > MAX_MODULE_LINES} == {}


def test_the_command_line_loads_every_drake_module_the_project_imports():
    """`admittance` loads Drake's extension modules with Ctrl-C held back (a Ctrl-C inside
    their C++ initialization becomes ImportError); a module missing from its list would
    load later, unprotected."""
    from admittance.diagrams.app.cli import DRAKE_MODULES

    imported = set()
    for folder in ("systems", "diagrams", "urdf"):
        for path in (REPOSITORY / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pydrake"):
                    imported.add(node.module)
                elif isinstance(node, ast.Import):
                    imported.update(a.name for a in node.names if a.name.startswith("pydrake"))
    assert "pydrake.systems.framework" in imported
    assert imported <= set(DRAKE_MODULES), sorted(imported - set(DRAKE_MODULES))
