"""Scenario loading: built-ins, --set overrides, and one clear error per bad input."""

from __future__ import annotations

import math

import pytest

from admittance.diagrams.scenario.files import builtin_scenario_names, load_scenario
from admittance.diagrams.scenario.schema import ScenarioError


def test_builtin_scenarios_exist_and_load():
    names = builtin_scenario_names()
    assert {"paper_stiffness_step", "paper_moving_wall"} <= set(names)
    for name in names:
        scenario = load_scenario(name)
        assert scenario.name == name


def test_paper_stiffness_step_has_the_papers_values():
    s = load_scenario("paper_stiffness_step")
    assert s.wall.position == 0.20 and s.wall.stiffness == 5e4
    assert [(step.time, step.stiffness) for step in s.wall.stiffness_steps] == [(15.0, 1e5)]
    assert s.force_reference == 5.0
    assert s.admittance.gamma == 1e-5 and s.admittance.alpha == 0.1
    assert s.pid.kp == [2500.0, 2500.0, 1000.0] and s.pid.kd == [50.0, 50.0, 5.0]
    assert s.trajectory.center == pytest.approx([0.2, -0.25, math.pi / 2])


def test_overrides_by_dotted_key():
    s = load_scenario(
        "paper_stiffness_step",
        [
            "wall.stiffness=2e4",
            "force_reference=8",
            "admittance.enabled=false",
            "sensor.kind=ideal",
            "wall.stiffness_steps=[{time: 3, stiffness: 1e5}]",
            "simulator.integration_scheme=implicit_euler",
        ],
    )
    assert s.wall.stiffness == 2e4 and s.force_reference == 8.0
    assert s.admittance.enabled is False and s.sensor.kind == "ideal"
    assert s.wall.stiffness_steps[0].time == 3.0
    assert s.simulator.integration_scheme == "implicit_euler"


def test_force_reference_beyond_the_sensor_is_rejected():
    with pytest.raises(ScenarioError, match=r"force_reference: must be < 99.92 N with sensor"):
        load_scenario(
            "paper_stiffness_step",
            ["sensor.kind=flexiforce", "admittance.max_push=0.5", "force_reference=150"],
        )


@pytest.mark.parametrize(
    "override, message",
    [
        ("wall.stifness=2e4", "wall.stifness: unknown scenario key; did you mean 'wall.stiffness'"),
        ("wall.stiffness=abc", "wall.stiffness: expected a number"),
        ("wall.stiffness=-5", "wall.stiffness: must be in (0, 1e+09] N/m"),
        ("admittance.gamma=0", "admittance.gamma: must be in (0, 0.1]"),
        ("admittance.alpha=-0.1", "admittance.alpha: must be in [0, 10] s"),
        ("admittance.enabled=maybe", "admittance.enabled: expected true or false"),
        ("duration=0", "duration: must be in (0, 1e5] s"),
        ("sensor.kind=strain_gauge", "sensor.kind: must be 'ideal' or 'flexiforce'"),
        ("sensor.noise_std=-1", "sensor.noise_std: must be in [0, 100] N"),
        ("pid.kp=[1, 2]", "pid.kp: must be 3 values"),
        ("seed=1.5", "seed: expected an integer"),
        ("simulator.integration_scheme=magic", "simulator.integration_scheme: must be one of"),
        ("wall.stiffness", "expected KEY=VALUE"),
        ("admittance.alpha=1e300", "admittance.alpha: must be in [0, 10] s"),
        ("wall.stiffness=1e12", "wall.stiffness: must be in (0, 1e+09] N/m"),
        ("force_reference=60", "admittance.max_push: must be > force_reference / pid.kp[0]"),
        ("wal.stiffness=1", "wal.stiffness: unknown scenario key; did you mean 'wall"),
        # A section that exists with a key it lacks: its keys, not the section itself.
        (
            "safety.bogus=1",
            "safety.bogus: unknown scenario key; safety has damping_ratio, enabled, "
            "max_stiffness, payload_mass, stability_margin",
        ),
    ],
)
def test_bad_input_names_the_key(override, message):
    with pytest.raises(ScenarioError) as error:
        load_scenario("paper_stiffness_step", [override])
    assert message in str(error.value)
    assert "\n" not in str(error.value)


def test_unknown_scenario_lists_the_builtins():
    with pytest.raises(ScenarioError, match="paper_stiffness_step"):
        load_scenario("no_such_scenario")


def test_yaml_file_with_unknown_key(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("duration: 2\nwall:\n  stifness: 1e4\n")
    with pytest.raises(ScenarioError, match="wall.stifness: unknown scenario key"):
        load_scenario(path)
    path.write_text("duration: 2\nwall:\n  stiffness: 1.0e4\n")
    scenario = load_scenario(path)
    assert scenario.duration == 2.0 and scenario.wall.stiffness == 1e4 and scenario.name == "mine"
