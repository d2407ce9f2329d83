"""Each robot in one place: the rules of the house, checked on the code itself.

A robot is one package under ``diagrams/robots/`` that hands the rest of the code one record;
the table of kinds (``robots/kinds.py``) is the only place that lists the robots. So:

* no module outside a robot's package (and the table) imports a robot's package, names a
  robot's scenario or result type, tests ``isinstance`` on one, or spells a kind;
* no robot's package imports another's;
* the hardware controller, which drives one robot, loads no module of the others;
* no module holds more than one topic (500 lines) and no function runs over 80 lines.

Each rule is also run on a small offending module, so that a rule that cannot fail is seen.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from admittance.diagrams.robots.kinds import KINDS, every_robot

REPOSITORY = Path(__file__).resolve().parents[1]
# A module longer than this holds more than one topic; a longer function, more than one step.
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
ROBOTS = REPOSITORY / "diagrams" / "robots"
TABLE = ROBOTS / "kinds.py"


def _robot_packages() -> dict[str, Path]:
    """Package name (admittance.diagrams.robots.X) -> its folder, for each row of the table."""
    return {package: ROBOTS / package.rsplit(".", 1)[1] for package in KINDS.values()}


def _library_files() -> list[Path]:
    return sorted(
        p for top in ("diagrams", "systems", "urdf") for p in (REPOSITORY / top).rglob("*.py")
    )


def _robot_of(path: Path) -> str | None:
    """The robot package a file belongs to, or None for shared code."""
    for package, folder in _robot_packages().items():
        if folder in path.parents:
            return package
    return None


def _imports(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _robot_type_names() -> set[str]:
    """The names of the classes the robots' packages define (their scenarios, results,
    loops, sections)."""
    names = set()
    for folder in _robot_packages().values():
        for path in folder.rglob("*.py"):
            tree = ast.parse(path.read_text())
            names.update(n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef))
    return names - {"Impl"}


def robot_mentions(tree: ast.AST, robot_packages, type_names, kinds) -> list[str]:
    """What a shared module says of particular robots: imports of their packages, their
    scenario and result types, isinstance checks on them, and kind strings compared with
    (a string "arm" elsewhere is the section of that name)."""
    found = [
        f"imports {name}"
        for name in sorted(_imports(tree))
        if any(name == p or name.startswith(p + ".") for p in robot_packages)
    ]
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id in type_names:
            found.append(f"names {node.id} (line {node.lineno})")
        elif isinstance(node, ast.Compare):  # kind == "grasp", kind in ("arm", ...)
            for side in (node.left, *node.comparators):
                for leaf in ast.walk(side):
                    if isinstance(leaf, ast.Constant) and leaf.value in kinds:
                        found.append(f"spells the kind {leaf.value!r} (line {node.lineno})")
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "id", "") == "isinstance"
            and len(node.args) == 2
        ):
            kinds_checked = {
                getattr(n, "id", getattr(n, "attr", "")) for n in ast.walk(node.args[1])
            }
            if any(k.endswith(("Scenario", "Result")) for k in kinds_checked):
                found.append(f"isinstance on {sorted(kinds_checked)} (line {node.lineno})")
    return found


def _shared_mentions() -> dict[str, list[str]]:
    packages = list(_robot_packages())
    type_names, kinds = _robot_type_names(), set(KINDS)
    offending = {}
    for path in _library_files():
        if _robot_of(path) is None and path != TABLE:
            found = robot_mentions(ast.parse(path.read_text()), packages, type_names, kinds)
            if found:
                offending[str(path.relative_to(REPOSITORY))] = found
    return offending


def test_the_table_lists_every_robot_package_and_each_exports_one_record():
    folders = sorted(p.parent.name for p in ROBOTS.glob("*/__init__.py"))
    assert folders == sorted(p.rsplit(".", 1)[1] for p in KINDS.values())
    for robot, kind in zip(every_robot(), KINDS, strict=True):
        assert robot.kind == kind
        assert robot.supports("simulate")
        # A record offers what its commands need.
        assert (robot.stability is not None) == robot.supports("stability")
        assert (robot.bench is not None) == robot.supports("bench")
        assert (
            (robot.hardware is not None) == robot.supports("station") == robot.supports("control")
        )
        assert (robot.compare is not None) == any(
            robot.supports(c) for c in ("compare", "grasp-compare")
        )


def test_no_shared_module_names_a_robot():
    assert len(_library_files()) > 100
    assert _shared_mentions() == {}


def test_the_shared_module_check_catches_each_kind_of_mention():
    source = (
        "from admittance.diagrams.robots.planar_gripper.run import GraspResult\n"
        "def f(result, scenario):\n"
        "    if isinstance(result, GraspResult):\n"
        "        return 1\n"
        "    return scenario.kind == 'spatial'\n"
    )
    found = robot_mentions(
        ast.parse(source), list(_robot_packages()), _robot_type_names(), set(KINDS)
    )
    assert any(f.startswith("imports admittance.diagrams.robots.planar_gripper") for f in found)
    assert any(f.startswith("names GraspResult") for f in found)
    assert any(f.startswith("isinstance on") for f in found)
    assert any(f.startswith("spells the kind 'spatial'") for f in found)


def _cross_robot_imports() -> dict[str, list[str]]:
    packages = list(_robot_packages())
    offending = {}
    for path in _library_files():
        own = _robot_of(path)
        if own is None:
            continue
        others = [
            name
            for name in sorted(_imports(ast.parse(path.read_text())))
            if any((name == p or name.startswith(p + ".")) and p != own for p in packages)
        ]
        if others:
            offending[str(path.relative_to(REPOSITORY))] = others
    return offending


def test_no_robot_package_imports_another():
    assert _cross_robot_imports() == {}


def test_the_cross_robot_check_catches_one(tmp_path, monkeypatch):
    offender = ROBOTS / "planar_gripper" / "_offender_for_the_test.py"
    offender.write_text("from admittance.diagrams.robots.planar_arm.plant import AddPlanarArm\n")
    try:
        found = _cross_robot_imports()
    finally:
        offender.unlink()
    assert "diagrams/robots/planar_gripper/_offender_for_the_test.py" in found


def test_the_hardware_controller_loads_no_module_of_another_robot():
    """In a fresh interpreter: the hardware controller's module and the settings of its
    default scenario loaded, with the robot's parts; no planar-arm or gripper module among
    the loaded modules."""
    script = (
        "import json, sys\n"
        "import admittance.diagrams.hardware.controller\n"
        "from admittance.diagrams.hardware.config import hardware_parts, load_hardware_config,"
        " scenario_of\n"
        "config = load_hardware_config('panda_surface_press')\n"
        "hardware_parts(scenario_of(config))\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('admittance'))))\n"
    )
    completed = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr
    loaded = json.loads(completed.stdout.strip().splitlines()[-1])
    assert "admittance.diagrams.robots.spatial_arm.control_law" in loaded
    others = [
        m
        for m in loaded
        if m.startswith(
            ("admittance.diagrams.robots.planar_arm", "admittance.diagrams.robots.planar_gripper")
        )
    ]
    assert others == []


def _long_functions(tree: ast.AST) -> list[str]:
    return [
        f"{node.name} ({node.end_lineno - node.lineno + 1} lines)"
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]


def test_no_module_over_500_lines_and_no_function_over_80():
    big = {
        str(p.relative_to(REPOSITORY)): n
        for p in _library_files()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    }
    long = {
        str(p.relative_to(REPOSITORY)): found
        for p in _library_files()
        if (found := _long_functions(ast.parse(p.read_text())))
    }
    assert big == {}
    assert long == {}


@pytest.mark.parametrize("lines, expected", [(80, []), (81, ["f (81 lines)"])])
def test_the_function_length_check_counts_lines(lines, expected):
    body = "".join(f"    x{i} = {i}\n" for i in range(lines - 1))
    assert _long_functions(ast.parse("def f():\n" + body)) == expected
