"""Grasp scenarios: told apart from the arm's by `kind`, every key checked by its own schema."""

from __future__ import annotations

import pytest

from admittance.diagrams.app.cli import main
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError


def test_grasp_builtins_load_as_grasp_scenarios():
    hold = load_scenario("grasp_hold")
    assert isinstance(hold, GraspScenario) and hold.name == "grasp_hold"
    assert hold.controller.kind == "optimal_admittance" and hold.duration >= 11.0
    disturbance = load_scenario("grasp_disturbance")
    assert disturbance.disturbance.kind != "none"
    # The arm's scenarios are what they were.
    assert isinstance(load_scenario("paper_stiffness_step"), Scenario)


def test_grasp_keys_by_dotted_override():
    scenario = load_scenario(
        "grasp_hold",
        [
            "brick.size_error=-0.002",
            "brick.stiffness_error=10",
            "contact.friction=0.8",
            "contact.stiction_tolerance=1e-5",
            "controller.kind=pid_only",
            "force_reference=[1.5, 1.5, 0.5]",
        ],
    )
    assert scenario.brick.size_error == -0.002
    assert scenario.true_contact_stiffness == pytest.approx(10 * scenario.contact.stiffness)
    assert scenario.contact.friction == 0.8 and scenario.controller.kind == "pid_only"
    assert scenario.contact.stiction_tolerance == 1e-5
    # Drake's default unless set.
    assert load_scenario("grasp_hold").contact.stiction_tolerance == 1e-4
    assert scenario.force_reference == [1.5, 1.5, 0.5]


@pytest.mark.parametrize(
    "override, message",
    [
        ("brick.size_error=0.05", r"^brick\.size_error: must be in \[-0\.01, 0\.01\] m"),
        ("brick.stiffness_error=0", r"^brick\.stiffness_error: must be in \[0\.01, 100\]"),
        ("contact.friction=0", r"^contact\.friction: must be in \(0, 2\]"),
        ("contact.friction=abc", r"^contact\.friction: expected a number"),
        (
            "contact.stiction_tolerance=0",
            r"^contact\.stiction_tolerance: must be in \[1e-7, 0\.01\] m/s",
        ),
        ("contact.stiction_tolerance=0.1", r"^contact\.stiction_tolerance: must be in"),
        ("controller.kind=fixed_reference", r"^controller\.kind: must be one of"),
        ("force_reference=[1, 2]", r"^force_reference: must be 3 values"),
        ("time_step=0.1", r"^time_step: must be 0 \(continuous\) or in \[0\.0001, 0\.005\] s"),
        ("brick.sise_error=0.001", r"^brick\.sise_error: unknown scenario key; did you mean"),
        # The arm's keys are not a grasp's.
        ("wall.stiffness=1e4", r"^wall\.stiffness: unknown scenario key"),
        ("disturbance.kind=earthquake", r"^disturbance\.kind: must be one of"),
    ],
)
def test_bad_grasp_keys_name_the_key(override, message):
    with pytest.raises(ScenarioError, match=message):
        load_scenario("grasp_hold", [override])


def test_scenario_kind_is_checked(tmp_path):
    odd = tmp_path / "odd.yaml"
    odd.write_text("kind: banana\nduration: 1\n")
    with pytest.raises(ScenarioError, match=r"^kind: must be one of arm, grasp"):
        load_scenario(odd)
    # The grasp keys are not an arm's.
    arm = tmp_path / "arm.yaml"
    arm.write_text("kind: arm\nbrick: {size_error: 0.001}\n")
    with pytest.raises(ScenarioError, match=r"^brick: unknown scenario key"):
        load_scenario(arm)


@pytest.mark.parametrize("command", ["bench", "compare", "sweep"])
def test_arm_only_commands_refuse_a_grasp_in_one_line(command, capsys, tmp_path):
    # (stability analyses a grasp too: tests/test_grasp_stability.py)
    out = ["--out", str(tmp_path / "sweep")] if command == "sweep" else []
    assert main([command, "grasp_hold", *out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "grasp scenario" in err[0], err


def test_simulate_rejects_a_bad_grasp_key_before_running(tmp_path, capsys):
    out = tmp_path / "never"
    assert main(["simulate", "grasp_hold", "--set", "brick.size_error=1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("admittance: error: brick.size_error:")
    assert not out.exists()
