"""Runs that fail: unreachable input, a diverging simulation, sampled controllers."""

from __future__ import annotations

import json

import pytest

import admittance.diagrams.run.engine as engine
from admittance.diagrams.app.cli import main
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.run.engine import SimulationDivergedError
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError


def test_unreachable_trajectory_is_rejected_before_simulating():
    scenario = load_scenario("paper_stiffness_step", ["trajectory.center=[0.6, -0.25, 1.57]"])
    with pytest.raises(ScenarioError, match=r"\(0.6, -0.25, 1.57\) is out of the arm's reach"):
        run_scenario(scenario)


def test_wall_behind_the_base_is_rejected():
    with pytest.raises(ScenarioError, match="wall.position: must be in front of the base"):
        load_scenario("paper_stiffness_step", ["wall.position=-0.05"])


def test_divergence_stops_the_run_and_keeps_the_partial_log(monkeypatch, tmp_path, capsys):
    # Any motion at all counts as "diverged" here, so the monitor must fire early.
    monkeypatch.setattr(engine, "DIVERGED_JOINT_SPEED", 1e-3)
    scenario = load_scenario("paper_moving_wall", ["duration=2"])
    message = r"joint speed exceeds 0.001 rad/s at t = "
    with pytest.raises(SimulationDivergedError, match=message) as error:
        run_scenario(scenario)
    partial = error.value.result
    assert partial.metrics["failed"] is True
    assert 0 < partial.time[-1] < 2.0
    out = tmp_path / "run"
    assert main(["simulate", "paper_moving_wall", "--set", "duration=2", "--out", str(out)]) == 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["failed"] is True and "joint speed" in metrics["failure"]
    assert "simulation diverged" in capsys.readouterr().err


def test_sampled_admittance_at_10khz_follows_the_continuous_law():
    overrides = ["duration=0.4", "sensor.kind=ideal"]
    continuous = run_scenario(load_scenario("paper_moving_wall", overrides))
    sampled = run_scenario(
        load_scenario("paper_moving_wall", [*overrides, "admittance.period=0.0001"])
    )
    assert sampled.metrics["contact_losses"] == 0
    assert sampled.force[-1] == pytest.approx(continuous.force[-1], rel=0.02)
    assert sampled.metrics["peak_force"] == pytest.approx(
        continuous.metrics["peak_force"], rel=0.05
    )


def test_sampled_pid_at_1khz_is_unstable_with_the_papers_theta_gains():
    """Kd = 5 on the light last link puts a pole near -1e4 1/s: 1 kHz sampling is too slow."""
    result = run_scenario(
        load_scenario("paper_stiffness_step", ["pid.period=0.001", "duration=0.5"])
    )
    assert result.metrics["contact_losses"] > 0
    assert result.metrics["peak_force"] > 10 * result.force_reference
