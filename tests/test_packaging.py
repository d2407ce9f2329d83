"""The distribution as a user installs it: a wheel, run from a directory outside the checkout.

The wheel goes into a fresh virtualenv that sees the test environment's third-party
packages (drake, numpy, matplotlib) through a .pth line but not its editable install of
this project, so every file the commands read must come from the wheel itself.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest
from test_hardware_processes import needs_namespace, run_pair

from admittance.diagrams.robots.spatial_arm.plant import example_robot_data_packages

REPOSITORY = Path(__file__).resolve().parents[1]


def _run(arguments: list, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(a) for a in arguments], cwd=cwd, capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture(scope="module")
def wheel_env(tmp_path_factory) -> Path:
    """A virtualenv with the project's wheel installed (not editable); returns its bin/."""
    root = tmp_path_factory.mktemp("wheel")
    built = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", root / "dist", REPOSITORY],
        cwd=root,
    )
    assert built.returncode == 0, built.stderr
    (wheel,) = (root / "dist").glob("optimal_admittance-*.whl")
    environment = root / "venv"
    venv.EnvBuilder(with_pip=False).create(environment)
    purelib = Path(
        sysconfig.get_path("purelib", vars={"base": str(environment), "platbase": str(environment)})
    )
    # Third-party packages from the test environment; its editable finder (a .pth of its
    # own site-packages) is not processed from here, so `admittance` comes from the wheel.
    here = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (purelib / "test_environment.pth").write_text("\n".join(sorted(here)) + "\n")
    installed = _run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            environment / "bin" / "python",
            "install",
            "-q",
            "--no-deps",
            wheel,
        ],
        cwd=root,
    )
    assert installed.returncode == 0, installed.stderr
    return environment / "bin"


def test_wheel_runs_a_simulation_from_an_unrelated_directory(wheel_env, tmp_path):
    located = _run(
        [
            wheel_env / "python",
            "-c",
            "import admittance.diagrams, importlib.util as u; print(admittance.diagrams.__file__);"
            "print(u.find_spec('diagrams'), u.find_spec('systems'))",
        ],
        cwd=tmp_path,
    )
    package_file, foreign = located.stdout.splitlines()
    assert Path(package_file).is_relative_to(wheel_env.parent), package_file
    # No generic top-level names: `diagrams` and `systems` are left to other distributions.
    assert foreign == "None None"

    version = _run([wheel_env / "admittance", "--version"], cwd=tmp_path)
    assert version.returncode == 0 and version.stdout.startswith("admittance "), version

    out = tmp_path / "run"
    ran = _run(
        [wheel_env / "admittance", "simulate", "--set", "duration=0.2", "--out", out], tmp_path
    )
    assert ran.returncode == 0, ran.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["first_contact_time"] is not None and metrics["peak_force"] > 0


def test_wheel_loads_a_users_own_urdf_and_scenario_by_path(wheel_env, tmp_path):
    # The user's own copy of the arm, named relative to the scenario file that uses it.
    shutil.copy(REPOSITORY / "urdf" / "planar_arm.urdf", tmp_path / "my_arm.urdf")
    (tmp_path / "mine.yaml").write_text(
        "duration: 0.2\nforce_reference: 4.0\narm:\n  urdf: my_arm.urdf\n"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "run"
    ran = _run(
        [wheel_env / "admittance", "simulate", tmp_path / "mine.yaml", "--out", out], elsewhere
    )
    assert ran.returncode == 0, ran.stderr
    assert "force_reference: 4.0" in (out / "scenario.yaml").read_text()
    assert str(tmp_path / "my_arm.urdf") in (out / "scenario.yaml").read_text()

    missing = _run(
        [wheel_env / "admittance", "simulate", "--set", "arm.urdf=nowhere.urdf", "--out", out],
        elsewhere,
    )
    assert missing.returncode == 2
    assert missing.stderr.strip().splitlines() == [
        "admittance: error: arm.urdf: must be an existing URDF file, got 'nowhere.urdf'"
    ]


@pytest.mark.skipif(
    example_robot_data_packages() is None, reason="needs the robots extra (example-robot-data)"
)
def test_wheel_presses_the_panda_and_analyses_its_whole_loop(wheel_env, tmp_path):
    """The spatial arm from the wheel: the Panda of the robots extra pressing its table
    (in contact within the run: first contact 0.92 s, measured), and `admittance
    stability`'s whole-loop linearization with P > 0 (its figures are tested in
    test_spatial_analysis.py; here, that the wheel carries everything they need)."""
    out = tmp_path / "press"
    ran = _run(
        [
            wheel_env / "admittance",
            "simulate",
            "panda_surface_press",
            "--set",
            "duration=4.5",
            "--out",
            out,
            "-q",
        ],
        tmp_path,
    )
    assert ran.returncode == 0, ran.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert 0.8 < metrics["first_contact_time"] < 1.0 and metrics["peak_force"] > 5.0
    report = tmp_path / "stability"
    analysed = _run(
        [wheel_env / "admittance", "stability", "panda_surface_press", "--quick", "--out", report],
        tmp_path,
    )
    assert analysed.returncode == 0, analysed.stderr
    whole = json.loads((report / "report.json").read_text())["whole_loop"]
    assert whole["stable"] and whole["lyapunov"]["positive_definite"]


@pytest.mark.skipif(
    example_robot_data_packages() is None, reason="needs the robots extra (example-robot-data)"
)
@needs_namespace
@pytest.mark.slow
def test_wheel_runs_the_station_and_the_controller_as_two_processes(wheel_env, tmp_path):
    """`admittance station` and `admittance control` from the wheel, in a network namespace
    of their own: the press settles to Fr (10.000 N over the last second, measured; 5 %
    band) with no command lost, and both exit 0."""
    result = run_pair(
        tmp_path,
        ["--set", "duration=4"],
        ["--set", "duration=4"],
        admittance=str(wheel_env / "admittance"),
    )
    assert result["station"] == 0 and result["control"] == 0, result
    metrics = json.loads((tmp_path / "station" / "metrics.json").read_text())
    assert metrics["command_loss_time"] is None
    assert abs(metrics["steady_state_force"] - 10.0) < 0.5
