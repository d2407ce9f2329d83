"""The safety layer's guarantees in closed loop, each against the same run without it.

Short runs of the moving-wall arm (Kp 1200, Kd 170) started in free space before a static
wall, Fr = 5 N, Fmax = 2 Fr = 10 N, the layer's Ke_max = 1e6 N/m:

* the first contact stays under Fmax and does not bounce, from 1e3 to 1e6 N/m, and the
  force then tracks Fr; without the layer the first contact strikes (impact at the PID's
  full speed) and, on the stiff wall, bounces;
* a sensor that drops to 0 N is caught, and the force stays under Fmax during and after
  the fault; without the layer the law pushes Xr to max_push (README, "Reliability");
* at the corner of the stability map (Ke = 1e7 N/m, Gamma = 1e-3, FlexiForce) the loop
  linearized with the layer is stable, without it unstable.

The ideal sensor keeps the runs short (the FlexiForce noise makes the integrator follow
each sample); the 200-point Monte Carlo with the noise is behind the slow marker.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.stability import max_real_part
from admittance.diagrams.scenario.files import load_scenario

FMAX = 10.0
FR = 5.0
START = "arm.initial_position=[0.145,-0.25,1.5707963267948966]"  # 5 mm before the wall


def _contact_run(stiffness: float, safety: bool, duration: float = 2.5):
    return run_scenario(
        load_scenario(
            "safe_contact",
            [
                START,
                f"wall.stiffness={stiffness}",
                "wall.velocity=0",
                "sensor.kind=ideal",
                f"duration={duration}",
                f"safety.enabled={str(safety).lower()}",
            ],
        )
    )


def _losses_after_first_contact(result) -> int:
    return result.metrics["contact_losses"]


@pytest.mark.parametrize("stiffness", [1e3, 1e5, 1e6])
def test_first_contact_stays_under_fmax_and_keeps_contact(stiffness):
    """The approach speed is v_max = 9.8 mm/s at this pose (Fmax, m, Kp, Kd + c, 1e6 N/m)
    and the tip trails the reference by (Kd + c) v_max / Kp = 3.7 mm: contact after
    (5 + 3.7) / 9.8 = 0.89 s. Measured: contact at 0.86 s, peaks of 5.24, 5.02 and 7.02 N
    at 1e3, 1e5 and 1e6 N/m, and over the last 0.3 s a mean |F - Fr| of 0.014-0.019 N
    (the bound, 2 % of Fr, is 0.1 N); on the soft wall the force reaches Fr after 5 mm of
    penetration."""
    result = _contact_run(stiffness, safety=True)
    metrics = result.metrics
    assert metrics["peak_force"] <= FMAX
    assert _losses_after_first_contact(result) == 0
    assert 0.7 < metrics["first_contact_time"] < 1.0
    late = result.time > result.time[-1] - 0.3
    assert np.mean(np.abs(result.force[late] - FR)) < 0.02 * FR
    assert metrics["safety"]["detections"] == []  # nothing flagged on a healthy sensor
    assert metrics["safety"]["approach_speed"] == pytest.approx(9.8e-3, rel=0.02)


def test_without_the_layer_the_same_first_contact_exceeds_fmax_and_bounces():
    """The paper's law from the same start: Xc = Xd lies 5.5 cm behind the wall, the tip
    strikes it (README: 74-276 N on walls of 1e5-1e6 N/m) and bounces."""
    result = _contact_run(1e6, safety=False, duration=0.3)
    assert result.metrics["peak_force"] > 3 * FMAX
    assert result.metrics["contact_losses"] >= 1


def _sensor_zero(safety: bool):
    overrides = [
        "duration=1.2",
        "wall.stiffness_steps=[]",
        "sensor.kind=ideal",
        "admittance.max_force=10",
        "faults=[{kind: sensor_zero, start: 0.6, end: 0.8, value: 0}]",
        f"safety.enabled={str(safety).lower()}",
    ]
    return run_scenario(load_scenario("paper_stiffness_step", overrides))


def test_a_sensor_that_drops_to_zero_is_caught_and_the_force_stays_under_fmax():
    """No noise is expected from the ideal sensor, so the drop is caught as implausible
    against the arm's own force estimate: three samples after the onset (15 ms, plus the
    sample's phase). During the detection delay the law pushes at most v_adv (alpha + t_d),
    which the derivation bounds to Fmax - Fr of force (systems/safe_admittance.py)."""
    result = _sensor_zero(safety=True)
    (fault,) = result.metrics["faults"]
    assert fault["detected_kind"] == "implausible"
    assert 0.0 < fault["detection_delay"] <= 0.02
    assert fault["worst_force_during"] < FMAX
    assert fault["peak_force_after"] < FMAX
    late = result.time > result.time[-1] - 0.2
    assert np.mean(np.abs(result.force[late] - FR)) < 0.02 * FR


def test_without_the_layer_a_sensor_at_zero_pushes_past_fmax():
    result = _sensor_zero(safety=False)
    assert result.metrics["faults"][0]["worst_force_during"] > 2 * FMAX  # measured 38 N


def test_the_stiff_corner_of_the_stability_map_is_stable_only_with_the_layer():
    """Ke = 1e7 N/m, Gamma = 1e-3 (100 x the paper's), FlexiForce at 5 kHz: the reduced
    model's critical Gamma there is 2.5e-7 (tests/test_safety_model.py), so the paper's
    law is far beyond it; the layer schedules Gamma to a third of it."""
    overrides = {
        "sensor.kind": "flexiforce",
        "wall.stiffness": 1e7,
        "admittance.gamma": 1e-3,
        "admittance.max_force": 10.0,
    }
    without = load_scenario("paper_stiffness_step", overrides)
    with_layer = load_scenario("paper_stiffness_step", {**overrides, "safety.enabled": True})
    assert max_real_part(without) > 0
    assert max_real_part(with_layer) < 0


def test_with_the_layer_off_the_loop_is_the_paper_s():
    """safety.enabled defaults to false: no system of the layer is built, so every
    built-in scenario runs the loop it ran before the layer existed."""
    for name in ("paper_stiffness_step", "paper_moving_wall"):
        scenario = load_scenario(name)
        assert scenario.safety.enabled is False
        names = {
            BuildClosedLoop(scenario).diagram.GetSystems()[i].get_name()
            for i in range(len(BuildClosedLoop(scenario).diagram.GetSystems()))
        }
        assert "safe_admittance" not in names and "optimal_admittance" in names
    assert math.isinf(load_scenario("paper_stiffness_step").admittance.max_force)


# The Monte Carlo of docs/evidence/sweeps.md (200 walls of random stiffness, position and sensor
# noise), with the layer on and Fmax = 10 N (docs/evidence/safety.md has the command and its table).
MONTE_CARLO = {
    "overrides": [
        "duration=8",
        "arm.initial_position=[0.14,-0.25,1.5707963267948966]",
        "safety.enabled=true",
        "admittance.max_force=10",
    ],
    "random": [
        "wall.stiffness=loguniform:1e3:1e6",
        "wall.position=uniform:0.145:0.155",
        "sensor.noise_std=uniform:0:0.1",
    ],
    "samples": 200,
    "seed": 1,
}


@pytest.mark.slow
def test_the_monte_carlo_keeps_every_guarantee(tmp_path):
    """At every one of the 200 points: the largest force, first contact included, at most
    Fmax; no contact loss after first contact; the steady-state error within 2 % of Fr;
    no fault flagged on a healthy sensor. 16-22 min on the shared 2-core machine (2 workers)."""
    from admittance.diagrams.app.sweep.definition import define_sweep
    from admittance.diagrams.app.sweep.points import read_points
    from admittance.diagrams.app.sweep.run import run_sweep

    definition = define_sweep(
        "paper_moving_wall",
        MONTE_CARLO["overrides"],
        random=MONTE_CARLO["random"],
        samples=MONTE_CARLO["samples"],
        seed=MONTE_CARLO["seed"],
    )
    run_sweep(definition, tmp_path / "sweep", workers=2)
    rows, _ = read_points(tmp_path / "sweep" / "points.jsonl")
    assert len(rows) == 200
    for row in rows.values():
        metrics = row["metrics"]
        assert not row["failed"], row["failure"]
        assert metrics["peak_force"] <= FMAX, row["values"]
        assert metrics["contact_losses"] == 0, row["values"]
        assert metrics["steady_state_force_error"] <= 0.02 * FR, row["values"]
        assert metrics["safety_detections"] == 0, row["values"]


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["safety.enabled=true"], "admittance.max_force: must be finite with safety.enabled"),
        (["safety.damping_ratio=0.1"], "safety.damping_ratio: must be in [0.2, 2]"),
        (
            ["safety.enabled=true", "admittance.max_force=10", "controller.kind=pid_only"],
            "safety.enabled: must be used with the paper's controller",
        ),
        (
            ["safety.enabled=true", "admittance.max_force=10", "pid.period=0.001"],
            "pid.period: must be equal to admittance.period with safety.enabled",
        ),
        (
            ["safety.enabled=true", "admittance.max_force=10", "sensor.latency=0.001"],
            "sensor.latency: must be 0 with safety.enabled and the continuous controller",
        ),
        (["safety.payload_mass=-0.1"], "safety.payload_mass: must be in [0, 10] kg, got -0.1"),
        (["safety.payload_mass=12"], "safety.payload_mass: must be in [0, 10] kg, got 12.0"),
        (["arm.payload_mass=11"], "arm.payload_mass: must be in [0, 10] kg, got 11.0"),
    ],
)
def test_bad_safety_input_is_one_line_naming_the_key(overrides, message):
    from admittance.diagrams.scenario.schema import ScenarioError

    with pytest.raises(ScenarioError) as error:
        load_scenario("paper_stiffness_step", overrides)
    assert str(error.value).startswith(message) and "\n" not in str(error.value)


def test_a_tip_beyond_the_reference_s_push_bound_cannot_start_with_the_layer():
    """The plan 2 cm behind the tip's start (x = 0.14 m, Xd at 0.12 m), past max_push =
    1 cm: the reference could not start at the tip (it would jump, and pull the arm): one
    line, before any run. The retract side has no bound with the layer: safe_contact's tip
    6 cm in front of Xd starts with max_retract 5 cm."""
    from admittance.diagrams.robots.planar_arm.loop import CheckScenarioStarts
    from admittance.diagrams.scenario.schema import ScenarioError

    with pytest.raises(ScenarioError, match=r"^arm.initial_position, admittance.max_push"):
        CheckScenarioStarts(
            load_scenario("safe_contact", ["trajectory.center=[0.12,-0.25,1.5707963267948966]"])
        )
    CheckScenarioStarts(load_scenario("safe_contact", ["admittance.max_retract=0.05"]))
