"""The benchmark (diagrams/app/bench.py) on a short run: every field is there and sane.

No assertion on a wall time: only that times are positive and counts consistent.
"""

from __future__ import annotations

import json

import pytest

from admittance.diagrams.app.bench import format_benchmark, run_benchmark
from admittance.diagrams.scenario import load_scenario


@pytest.fixture(scope="module")
def report():
    # A short run of the FlexiForce scenario: noise, sensor state and admittance all active.
    return run_benchmark(load_scenario("paper_moving_wall", ["duration=0.5"]), repeat=1)


def test_report_is_json_serialisable(report):
    assert json.loads(json.dumps(report)) == report


def test_closed_loop_timing_and_integrator_counts(report):
    loop = report["closed_loop"]
    wall = loop["wall_time"]
    assert len(wall["samples"]) == report["repeat"] == 1
    assert 0 < wall["min"] <= wall["median"] <= wall["max"]
    assert loop["real_time_factor"] == pytest.approx(0.5 / wall["median"])
    assert loop["integrator_steps"] > 0
    assert loop["derivative_evaluations"] >= loop["integrator_steps"]
    assert loop["derivative_evaluations_per_step"] >= 1
    assert loop["wall_time_per_derivative_evaluation_us"] > 0
    assert loop["build_time"] > 0
    # The seeded loop takes the same steps in every run, the profiled one included.
    assert loop["deterministic"]
    # radau3 (the scenario's integrator) is implicit: Newton iterations and Jacobians.
    integrator = loop["integrator"]
    assert integrator["num_steps_taken"] == loop["integrator_steps"]
    assert integrator["num_newton_raphson_iterations"] > 0
    assert integrator["num_jacobian_evaluations"] > 0
    # The warm-up ran the same physics as `admittance simulate`.
    assert loop["peak_force"] > 5.0
    assert loop["contact_losses"] == 0


def test_python_callbacks_are_counted(report):
    python = report["python"]
    loop = report["closed_loop"]
    assert python["callback_calls"] > loop["derivative_evaluations"]
    # Every derivative evaluation calls DoCalcTimeDerivatives of each Python system with
    # continuous state (PID, admittance, sensor) and the wall's force at least once.
    assert python["callbacks_per_derivative_evaluation"] >= 4
    assert 0 < python["time_in_callbacks"] < python["profiled_wall_time"]
    assert 0 < python["fraction_of_wall_time"] < 1
    names = {entry["name"] for entry in python["callbacks"]}
    assert "cartesian_pid.DoCalcTimeDerivatives" in names
    assert any(name.startswith("compliant_wall.") for name in names)
    for entry in python["callbacks"]:
        assert entry["calls"] > 0 and entry["time"] >= 0 and entry["mean_us"] >= 0
    derivatives = next(
        e for e in python["callbacks"] if e["name"] == "cartesian_pid.DoCalcTimeDerivatives"
    )
    assert derivatives["calls"] == loop["derivative_evaluations"]


def test_each_law_runs_once_per_evaluation(report):
    # The PID's kinematics and torque, and the admittance law, are cached per context and
    # read by both the output and the derivatives: one run per derivative evaluation, plus
    # the few contexts that only the loggers and monitor see (about 5 %). Without the
    # cache they would run twice.
    calls = {entry["name"]: entry["calls"] for entry in report["python"]["callbacks"]}
    evaluations = report["closed_loop"]["derivative_evaluations"]
    for law in ("cartesian_pid._CalcLaw", "optimal_admittance._CalcContinuousLaw"):
        assert evaluations <= calls[law] <= 1.2 * evaluations, law


def test_floor_stays_put_and_is_cheaper(report):
    floor = report["floor"]
    assert floor["wall_time"]["median"] > 0
    assert floor["integrator_steps"] > 0 and floor["derivative_evaluations"] > 0
    assert floor["max_joint_drift"] < 1e-6  # held by the gravity torques
    assert report["ratio_to_floor"] > 0
    assert report["per_evaluation_ratio_to_floor"] > 0


def test_logging_and_memory(report):
    every_step, variant = report["logging"]
    assert every_step["logging"] == "every step"
    assert variant["logging"] == "none"
    assert variant["wall_time"] > 0 and variant["relative_to_timed"] > 0
    # Logging does not change the integration.
    assert variant["integrator_steps"] == every_step["integrator_steps"]
    memory = report["memory"]
    assert memory["peak_rss_mb"] > 0 and memory["python_peak_mb"] > 0


def test_format_benchmark_is_a_table(report):
    text = format_benchmark(report)
    for label in (
        "AdvanceTo wall time, median",
        "real-time factor",
        "integrator steps",
        "derivative evaluations",
        "closed loop / floor",
        "Python callbacks",
        "logging (",
        "memory:",
    ):
        assert label in text
    assert "paper_moving_wall" in text


def test_repeat_must_be_positive():
    with pytest.raises(ValueError, match="repeat"):
        run_benchmark(load_scenario("paper_moving_wall", ["duration=0.1"]), repeat=0)
