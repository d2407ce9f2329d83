"""The planar arm's benchmark (its package's ``bench``) on a short run: every field is there
and sane.

No assertion on a wall time: only that times are positive and counts consistent.
"""

from __future__ import annotations

import json

import pytest

from admittance.diagrams.robots.planar_arm.bench import run_benchmark
from admittance.diagrams.robots.planar_arm.bench_report import (
    format_benchmark,
    load_benchmark_report,
)
from admittance.diagrams.scenario.files import load_scenario


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
    cpu = loop["cpu_time"]
    assert 0 < cpu["min"] <= cpu["median"] <= cpu["max"]
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
    # Every derivative evaluation calls the sensor filter's DoCalcTimeDerivatives (the one
    # Python system with continuous state) and the laws of the kinematics, the wall, the
    # PID and the admittance block at least once.
    assert python["callbacks_per_derivative_evaluation"] >= 5
    assert 0 < python["time_in_callbacks"] < python["profiled_wall_time"]
    assert 0 < python["fraction_of_wall_time"] < 1
    names = {entry["name"] for entry in python["callbacks"]}
    assert "flexiforce_sensor.DoCalcTimeDerivatives" in names
    # Systems inside a subdiagram are named after both (the laws of the PID, the wall and
    # the admittance block).
    for law in ("cartesian_pid/law", "compliant_wall/law", "optimal_admittance/law"):
        assert f"{law}._CalcLaw" in names
    for entry in python["callbacks"]:
        assert entry["calls"] > 0 and entry["time"] >= 0 and entry["mean_us"] >= 0
    derivatives = next(
        e for e in python["callbacks"] if e["name"] == "flexiforce_sensor.DoCalcTimeDerivatives"
    )
    assert derivatives["calls"] == loop["derivative_evaluations"]


def test_python_callbacks_per_evaluation(report):
    # Per derivative evaluation of this loop (FlexiForce sensor): the fingertip kinematics
    # 1, the wall 1 (F and the plant's generalized force in one law), the sensor 2 (its
    # output and its filter's derivative), the PID 1 and the admittance block 1 (each its
    # law; their integrals are Drake's Integrators): 6, plus the contexts that only the
    # loggers see (measured 6.44 on this 0.5 s run: 9 % more evaluations of the laws than
    # derivative evaluations). The admittance block as a LeafSystem with its own state
    # (law, output, derivative) and the wall's two outputs made 9 (9.4 measured); before
    # the PID's integral moved to C++, the trajectory to Drake's Sine and the kinematics
    # were shared, the same loop made 12.5.
    assert report["python"]["callbacks_per_derivative_evaluation"] <= 6 * 1.1


def test_each_law_runs_once_per_evaluation(report):
    # The fingertip kinematics (read by the PID and the wall), the PID's law (read by the
    # plant and its integral), the wall's law (read by the plant and the sensor) and the
    # admittance law (read by the commanded position and its integral) run once per
    # derivative evaluation, plus the few contexts that only the loggers and monitor see
    # (about 5 %). Computed by each reader, they would run twice.
    calls = {entry["name"]: entry["calls"] for entry in report["python"]["callbacks"]}
    evaluations = report["closed_loop"]["derivative_evaluations"]
    for law in (
        "fingertip_kinematics._CalcGenerated",
        "cartesian_pid/law._CalcLaw",
        "compliant_wall/law._CalcLaw",
        "optimal_admittance/law._CalcLaw",
    ):
        assert evaluations <= calls[law] <= 1.2 * evaluations, law
    # No other system computes kinematics: the PID and the wall share them.
    kinematics = sum(n for name, n in calls.items() if name.endswith("._CalcGenerated"))
    assert kinematics == calls["fingertip_kinematics._CalcGenerated"]


def test_sampled_controllers_run_only_at_their_samples():
    # The sampled PID and admittance hold their outputs as discrete states that the output
    # ports read directly: their laws run once per sample (1 kHz over 50 ms: the 50 samples
    # at t = 0 to 49 ms, as the 30 s run makes 30,000) and never between samples, whatever
    # the integrator evaluates.
    report = run_benchmark(load_scenario("digital_controller", ["duration=0.05"]), repeat=1)
    calls = {entry["name"]: entry["calls"] for entry in report["python"]["callbacks"]}
    assert report["closed_loop"]["derivative_evaluations"] > 200
    assert calls["cartesian_pid/law._DiscreteUpdate"] == 50
    assert calls["optimal_admittance/law._DiscreteUpdate"] == 50
    assert not [
        name
        for name in calls
        if name.startswith(("cartesian_pid", "optimal_admittance"))
        and "_DiscreteUpdate" not in name
    ]


def test_floor_holds_the_arm_and_the_ratios_are_its_quotients(report):
    floor = report["floor"]
    loop = report["closed_loop"]
    assert floor["max_joint_drift"] < 1e-6  # held by the gravity torques
    # The bare arm at rest needs far fewer integrator steps and derivative evaluations than
    # the closed loop (measured 11 and 51 against 136 and 1569 for 0.5 s): counts, not
    # times, so the comparison holds on a busy machine.
    assert 0 < floor["integrator_steps"] < loop["integrator_steps"]
    assert 0 < floor["derivative_evaluations"] < loop["derivative_evaluations"]
    # The ratios are what their names say, from the reported medians and counts.
    floor_median = floor["wall_time"]["median"]
    assert report["ratio_to_floor"] == pytest.approx(loop["wall_time"]["median"] / floor_median)
    per_evaluation = loop["wall_time"]["median"] / loop["derivative_evaluations"]
    floor_per_evaluation = floor_median / floor["derivative_evaluations"]
    assert report["per_evaluation_ratio_to_floor"] == pytest.approx(
        per_evaluation / floor_per_evaluation
    )
    # The same quotients of CPU times (what to read on a busy machine).
    floor_cpu = floor["cpu_time"]["median"]
    assert report["cpu_ratio_to_floor"] == pytest.approx(loop["cpu_time"]["median"] / floor_cpu)
    assert report["cpu_per_evaluation_ratio_to_floor"] == pytest.approx(
        (loop["cpu_time"]["median"] / loop["derivative_evaluations"])
        / (floor_cpu / floor["derivative_evaluations"])
    )


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


def test_one_evaluation_is_timed_for_both(report):
    one = report["one_evaluation"]
    assert one["closed_loop_us"] > 0 and one["floor_us"] > 0
    assert one["ratio"] == pytest.approx(one["closed_loop_us"] / one["floor_us"])
    assert "one derivative evaluation alone" in format_benchmark(report)


def test_an_earlier_report_is_printed_beside(report, tmp_path):
    path = tmp_path / "before.json"
    path.write_text(json.dumps(report))
    scenario = load_scenario("paper_moving_wall", ["duration=0.5"])
    before = load_benchmark_report(path, scenario)
    text = format_benchmark(report, before)
    assert "against the earlier run" in text
    assert "1.00 x" in text  # the same run on both sides
    # Every callback of either run has a row.
    for entry in report["python"]["callbacks"]:
        assert sum(line.strip().startswith(entry["name"] + " ") for line in text.splitlines()) == 2


def test_an_earlier_report_of_another_scenario_is_refused(report, tmp_path):
    path = tmp_path / "before.json"
    path.write_text(json.dumps(report))
    other = load_scenario("paper_moving_wall", ["duration=1.0"])
    with pytest.raises(
        ValueError, match=r"before\.json: a benchmark of paper_moving_wall \(0\.5 s"
    ):
        load_benchmark_report(path, other)
    path.write_text("{}")
    with pytest.raises(ValueError, match="not a benchmark report"):
        load_benchmark_report(path, other)
    with pytest.raises(ValueError, match="--before .*missing.json"):
        load_benchmark_report(tmp_path / "missing.json", other)


def test_bench_json_may_replace_a_real_report_and_nothing_else(report, tmp_path):
    """`bench --json FILE` recognises its own report (so it replaces it), not other JSON."""
    from admittance.diagrams.app.bench_report import check_bench_file
    from admittance.diagrams.results.folder import OutputExistsError

    path = tmp_path / "bench.json"
    path.write_text(json.dumps(report))
    check_bench_file(path)
    path.write_text(json.dumps({"scenario": report["scenario"]}))
    with pytest.raises(OutputExistsError, match="not a bench report this tool wrote"):
        check_bench_file(path)
