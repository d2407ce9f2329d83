"""The layout: the library never imports the application, nor any module a private name.

The library (admittance.systems, and admittance.diagrams' concept packages: scenario,
robots, loop, run, analysis, views) builds and runs the model; the application
(admittance.diagrams.app: the command line, result folders, bench, compare, sweep, the
stability report) is a layer on top of it. The dependency goes one way only. No module
reaches into another's private (`_`-prefixed) names: what one module offers another is
public.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
APPLICATION = "admittance.diagrams.app"
# The folders of the library, and their import names.
LIBRARY = {"systems": "admittance.systems", "diagrams": "admittance.diagrams"}
# A module longer than this holds more than one topic.
MAX_MODULE_LINES = 500
# The concept packages of admittance.diagrams.
CONCEPTS = ("scenario", "robots", "loop", "run", "analysis", "views", "hardware", "app")


def _library_files() -> dict[str, Path]:
    """Module name -> file, for every library module in the repository."""
    modules = {}
    for folder, package in LIBRARY.items():
        for path in sorted((REPOSITORY / folder).rglob("*.py")):
            parts = path.relative_to(REPOSITORY / folder).with_suffix("").parts
            if parts[0] == "app":
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join((package, *parts))] = path
    return modules


def _every_module() -> dict[str, Path]:
    """Module name -> file, for every module of the project, the application included."""
    modules = {}
    for folder, package in {**LIBRARY, "urdf": "admittance.urdf"}.items():
        for path in sorted((REPOSITORY / folder).rglob("*.py")):
            parts = path.relative_to(REPOSITORY / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join((package, *parts))] = path
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
        "admittance.diagrams.robots.planar_arm.loop" in modules
        and "admittance.systems.flexiforce" in modules
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


def test_no_module_holds_more_than_one_topic():
    lengths = {
        str(path.relative_to(REPOSITORY)): len(path.read_text().splitlines())
        for path in _every_module().values()
    }
    assert len(lengths) > 50
    assert {n: k for n, k in lengths.items() if k > MAX_MODULE_LINES} == {}


def test_diagrams_is_grouped_by_concept():
    """Every module of admittance.diagrams lives in a concept package; no family of
    name-prefixed modules stands in for a package."""
    loose = sorted(p.name for p in (REPOSITORY / "diagrams").glob("*.py") if p.stem != "__init__")
    assert loose == []
    packages = sorted(
        p.name for p in (REPOSITORY / "diagrams").iterdir() if (p / "__init__.py").is_file()
    )
    assert set(CONCEPTS) <= set(packages)
    folders = [p.parent for p in (REPOSITORY / "diagrams").rglob("__init__.py")]
    for folder in folders:
        stems = [p.stem for p in folder.glob("*.py")]
        prefixes = [s.split("_")[0] for s in stems if "_" in s and s != "__init__"]
        families = {p for p in prefixes if prefixes.count(p) > 2}
        assert families == set(), (folder.name, families)


def _private_imports(path: Path, module: str, modules: dict[str, Path]) -> list[str]:
    """`from X import _name` (and `X._name`) where X is another module of the project."""
    found = []
    package = module if path.stem == "__init__" else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            if base.startswith("admittance") and base != module:
                found += [
                    f"{base}.{a.name}"
                    for a in node.names
                    if a.name.startswith("_") and not a.name.startswith("__")
                ]
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            chain, value = [node.attr], node.value
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id == "admittance":
                found.append(".".join(["admittance", *reversed(chain)]))
    return found


def test_no_module_imports_a_private_name_of_another():
    modules = _every_module()
    assert "admittance.diagrams.app.cli" in modules
    tests = {f"tests.{p.stem}": p for p in (REPOSITORY / "tests").glob("*.py")}
    offending = {
        name: found
        for name, path in {**modules, **tests}.items()
        if (found := _private_imports(path, name, modules))
    }
    assert offending == {}


def test_the_private_import_check_catches_one(tmp_path):
    """The check above is not vacuous: a module importing another's private name fails it."""
    module = tmp_path / "offender.py"
    module.write_text(
        "from admittance.diagrams.run.metrics import _hidden\n"
        "import admittance.diagrams.run.metrics\n"
        "x = admittance.diagrams.run.metrics._other\n"
    )
    assert _private_imports(module, "admittance.offender", {}) == [
        "admittance.diagrams.run.metrics._hidden",
        "admittance.diagrams.run.metrics._other",
    ]


def test_the_command_line_loads_every_drake_module_the_project_imports():
    """`admittance` loads Drake's extension modules with Ctrl-C held back (a Ctrl-C inside
    their C++ initialization becomes ImportError); a module missing from its list would
    load later, unprotected."""
    from admittance.diagrams.app.cli import DRAKE_MODULES

    imported = set()
    for folder in ("systems", "diagrams", "urdf"):  # every sub-package too
        for path in (REPOSITORY / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pydrake"):
                    imported.add(node.module)
                elif isinstance(node, ast.Import):
                    imported.update(a.name for a in node.names if a.name.startswith("pydrake"))
    assert "pydrake.systems.framework" in imported
    assert imported <= set(DRAKE_MODULES), sorted(imported - set(DRAKE_MODULES))


def test_no_public_name_of_a_package_hides_one_of_its_modules():
    """`from admittance.diagrams.run import simulate` is the function and
    `import admittance.diagrams.run.simulation` the module: a package's re-exported names
    never take a module's name (monkeypatching `package.module` would patch a function)."""
    import importlib
    import pkgutil

    packages = [p for p in CONCEPTS if p != "app"]
    for name in packages:
        package = importlib.import_module(f"admittance.diagrams.{name}")
        for module in pkgutil.iter_modules(package.__path__):
            loaded = importlib.import_module(f"{package.__name__}.{module.name}")
            assert getattr(package, module.name) is loaded, (name, module.name)


def test_every_public_function_and_class_of_the_library_is_exported():
    """What a library module defines without a leading underscore is in its __all__, so
    that its package re-exports it (`from admittance.diagrams.run import settled_from`)."""
    import importlib
    import inspect
    import pkgutil

    unexported = {}
    for name in (p for p in CONCEPTS if p != "app"):
        package = importlib.import_module(f"admittance.diagrams.{name}")
        for info in pkgutil.iter_modules(package.__path__):
            module = importlib.import_module(f"{package.__name__}.{info.name}")
            defined = {
                n
                for n, v in vars(module).items()
                if not n.startswith("_")
                and (inspect.isfunction(v) or inspect.isclass(v))
                and v.__module__ == module.__name__
            }
            missing = defined - set(getattr(module, "__all__", ()))
            if missing:
                unexported[module.__name__] = sorted(missing)
    assert unexported == {}
