"""Faults injected from the scenario: the controller's documented behaviour.

Every closed-loop case runs the stiffness-step arm against the 5e4 N/m wall (no Ke step),
Fr = 5 N, with one fault from t = 1.5 s to t = 2.0 s, and checks:

* no NaN reaches the plant: every logged joint torque is finite;
* the force returns to Fr after the fault: within 5 % (the settling band of the metrics)
  in under 1 s, and the mean |F - Fr| over the last 0.5 s is under 1 % of Fr (2 % with
  the FlexiForce noise);
* the worst force during the fault is reported in metrics.json, and bounded as the
  behaviour of each fault predicts.

The sensor faults run in the default suite with the ideal sensor (a few seconds each), and
the NaN reading with the FlexiForce chain too; the wall and stiffness faults and the other
FlexiForce variants are marked slow.
"""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.optimal_admittance import OptimalAdmittance
from admittance.systems.sensor_fault import SensorFault

FR = 5.0
START, END = 1.5, 2.0


def _run(kind: str, value: float = 0.0, sensor: str = "ideal", extra: tuple[str, ...] = ()):
    scenario = load_scenario(
        "paper_stiffness_step",
        [
            "duration=3.5",
            "wall.stiffness_steps=[]",
            f"sensor.kind={sensor}",
            f"faults=[{{kind: {kind}, start: {START}, end: {END}, value: {value}}}]",
            *extra,
        ],
    )
    result = run_scenario(scenario)
    (fault,) = result.metrics["faults"]
    assert fault["kind"] == kind and fault["start"] == START and fault["end"] == END
    return result, fault


def _check_common(result, fault) -> None:
    # The FlexiForce noise leaves a ripple of about 0.1 N: 2 % of Fr on average (the
    # project's tracking criterion); the ideal sensor settles to 1 %.
    tolerance = 0.02 if result.scenario.sensor.kind == "flexiforce" else 0.01
    assert result.metrics["finite_actuation"]
    assert np.all(np.isfinite(result.actuation))
    assert np.all(np.isfinite(result.pose))
    assert math.isfinite(fault["worst_force_during"])
    assert fault["recovery_time"] is not None and fault["recovery_time"] < 1.0
    late = result.time > result.time[-1] - 0.5
    assert np.mean(np.abs(result.force[late] - FR)) < tolerance * FR


def _during(result):
    return (result.time >= START) & (result.time < END)


# --- the blocks' fault behaviour, by hand ---------------------------------------------------


def test_sensor_fault_replaces_the_reading_only_inside_its_window():
    fault = SensorFault([("sensor_stuck", 1.0, 2.0, 3.0), ("sensor_nan", 3.0, 4.0, 0.0)])
    context = fault.CreateDefaultContext()
    fault.measured_force_input.FixValue(context, [7.0])
    for time, expected in ((0.5, 7.0), (1.0, 3.0), (1.99, 3.0), (2.0, 7.0), (3.5, math.nan)):
        context.SetTime(time)
        reported = fault.reported_force_output.Eval(context)[0]
        if math.isnan(expected):
            assert math.isnan(reported)
        else:
            assert reported == expected


def test_sensor_fault_readings_overlaps_and_checks():
    """sensor_zero reads 0, sensor_saturated its value; where two faults overlap the first
    listed wins; the AutoDiffXd copy (for Linearize) reads the same schedule."""
    faults = [("sensor_zero", 1.0, 3.0, 0.0), ("sensor_saturated", 2.0, 4.0, 111.0)]
    fault = SensorFault(faults)
    fault_ad = fault.ToAutoDiffXd()
    for system in (fault, fault_ad):
        context = system.CreateDefaultContext()
        system.measured_force_input.FixValue(context, [7.0])
        for time, expected in ((0.5, 7.0), (1.0, 0.0), (2.5, 0.0), (3.0, 111.0), (4.0, 7.0)):
            context.SetTime(time)
            reported = system.reported_force_output.Eval(context)[0]
            assert (reported if system is fault else reported.value()) == expected, time
    assert fault.active_fault(2.5)[:4] == faults[0] and fault.active_fault(5.0) is None
    with pytest.raises(ValueError, match="fault kind must be one of"):
        SensorFault([("sensor_fire", 1.0, 2.0, 0.0)])
    for start, end in ((2.0, 2.0), (2.0, 1.0), (math.nan, 2.0)):
        with pytest.raises(ValueError, match="must be after start"):
            SensorFault([("sensor_zero", start, end, 0.0)])


def test_a_noisy_fault_keeps_the_noise_sample_on_the_replaced_reading():
    """By hand: a noisy dropout reads 0 + the noise sample, a noisy stuck reading its value
    + the sample; a noise-free fault has no noise input at all."""
    fault = SensorFault(
        [("sensor_zero", 1.0, 2.0, 0.0, True), ("sensor_stuck", 2.0, 3.0, 4.0, True)]
    )
    context = fault.CreateDefaultContext()
    fault.measured_force_input.FixValue(context, [7.0])
    fault.noise_input.FixValue(context, [-0.03])
    for time, expected in ((0.5, 7.0), (1.5, -0.03), (2.5, 3.97), (3.5, 7.0)):
        context.SetTime(time)
        assert fault.reported_force_output.Eval(context)[0] == pytest.approx(expected, abs=1e-15)
    assert SensorFault([("sensor_zero", 1.0, 2.0, 0.0)]).noise_input is None
    with pytest.raises(ValueError, match="no noise to keep"):
        SensorFault([("sensor_nan", 1.0, 2.0, 0.0, True)])


def test_a_noisy_dropout_in_a_run_shows_the_sensors_noise():
    """paper_moving_wall's FlexiForce (noise std 0.02 N, one sample every 5 ms): during a
    noisy dropout the reading scatters about 0 N with that std; a plain one reads 0 N.
    Over 0.4 s, 80 samples: the std of a sample std is 1/sqrt(2 x 80) = 8 % of it, so
    +-30 % is more than 3 of those."""
    readings = {}
    for noisy in (False, True):
        fault = f"{{kind: sensor_zero, start: 0.3, end: 0.7, noisy: {str(noisy).lower()}}}"
        scenario = load_scenario(
            "paper_moving_wall", ["duration=0.8", "logging.period=0.005", f"faults=[{fault}]"]
        )
        result = run_scenario(scenario)
        during = (result.time >= 0.3 + 1e-9) & (result.time < 0.7 - 1e-9)
        readings[noisy] = result.force_measured[during]
    assert np.all(readings[False] == 0.0)
    noise_std = load_scenario("paper_moving_wall").sensor.noise_std
    assert abs(np.mean(readings[True])) < 4 * noise_std / math.sqrt(readings[True].size)
    assert np.std(readings[True]) == pytest.approx(noise_std, rel=0.3)


def test_admittance_holds_its_reference_on_an_invalid_measurement():
    block = OptimalAdmittance(gamma=1e-5, alpha=0.1, stiffness=2500.0, force_axes=(0,), num_axes=3)
    context = block.CreateDefaultContext()
    context.SetContinuousState([40.0])
    block.desired_force_input.FixValue(context, [5.0])
    block.measured_force_input.FixValue(context, [5.0])  # settled: E = 0
    settled = block.reference_offset_output.Eval(context)[0]
    block.measured_force_input.FixValue(context, [math.nan])
    # The integral stops and Xr stays where E = 0 put it.
    assert block.EvalTimeDerivatives(context).CopyToVector()[0] == 0.0
    assert block.reference_offset_output.Eval(context)[0] == settled == 2.5e-2 * 40.0


def test_admittance_travel_bound_and_back_calculation():
    """Xr = Gamma K (z + alpha E) is clamped to max_push; past it the integral is pulled back
    with rate E + (Xr_clamped - Xr) / (Gamma K tau_aw), tau_aw = 10 ms."""
    gain = 1e-5 * 2500.0
    block = OptimalAdmittance(
        gamma=1e-5,
        alpha=0.1,
        stiffness=2500.0,
        max_push=0.01,
        max_retract=0.02,
        force_axes=(0,),
        num_axes=3,
    )
    context = block.CreateDefaultContext()
    block.desired_force_input.FixValue(context, [5.0])
    block.measured_force_input.FixValue(context, [1.0])  # E = 4 N: pushes into the wall
    context.SetContinuousState([1.0])  # unclamped Xr = 0.025 (1 + 0.4) = 0.035 m
    assert block.reference_offset_output.Eval(context)[0] == pytest.approx(0.01)
    rate = block.EvalTimeDerivatives(context).CopyToVector()[0]
    assert rate == pytest.approx(4.0 + (0.01 - gain * 1.4) / (gain * 0.01))
    assert rate < 0  # winding back, not up
    # Inside the bounds the law is untouched: dz/dt = E.
    context.SetContinuousState([0.0])
    assert block.EvalTimeDerivatives(context).CopyToVector()[0] == pytest.approx(4.0)
    assert block.reference_offset_output.Eval(context)[0] == pytest.approx(gain * 0.4)
    # Retract bound, too high a reading.
    block.measured_force_input.FixValue(context, [111.0])
    context.SetContinuousState([-2.0])
    assert block.reference_offset_output.Eval(context)[0] == pytest.approx(-0.02)
    assert block.EvalTimeDerivatives(context).CopyToVector()[0] > 0


def test_admittance_with_faults_converts_to_autodiff():
    block = OptimalAdmittance(
        gamma=1e-5, alpha=0.1, stiffness=2500.0, max_push=0.01, force_axes=(0,), num_axes=3
    )
    block_ad = block.ToAutoDiffXd()
    context = block_ad.CreateDefaultContext()
    block_ad.GetInputPort("desired_force").FixValue(context, [AutoDiffXd(5.0, [0.0])])
    block_ad.GetInputPort("measured_force").FixValue(context, [AutoDiffXd(4.0, [1.0])])
    offset = block_ad.GetOutputPort("reference_offset").Eval(context)[0]
    # dXr/dF = -Gamma K alpha inside the bounds.
    assert offset.derivatives()[0] == pytest.approx(-1e-5 * 2500.0 * 0.1)


@pytest.mark.parametrize(
    "override, message",
    [
        ("faults=[{kind: sensor_fire, start: 1, end: 2}]", "faults[0].kind: must be one of"),
        ("faults=[{kind: sensor_nan, start: 2, end: 1}]", "faults[0].end: must be > start"),
        ("faults=[{kind: wall_retract, start: 1, end: 2, value: -0.01}]", "faults[0].value"),
        ("faults=[{kind: stiffness_jump, start: 1, end: 2, value: 0}]", "faults[0].value"),
        ("faults=[{kind: sensor_nan, start: -1, end: 2}]", "faults[0].start: must be >= 0"),
    ],
)
def test_bad_faults_are_rejected_with_the_key(override, message):
    with pytest.raises(ScenarioError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_scenario("paper_stiffness_step", [override])


# --- closed loop ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "sensor, extra",
    [("ideal", ()), ("flexiforce", ("simulator.accuracy=1e-3",))],
    ids=["ideal", "flexiforce"],
)
def test_sensor_nan_holds_the_reference_and_recovers(sensor, extra):
    """The FlexiForce case runs the chain's filter and noise between the fault and the law
    (at the accuracy of the other FlexiForce runs of the default suite)."""
    result, fault = _run("sensor_nan", sensor=sensor, extra=extra)
    _check_common(result, fault)
    during = _during(result)
    xr = result.reference_offset[:, 0]
    # Xr held: it moves by under 0.1 mm (the arm stays put, so does the force). Measured:
    # 0 with the ideal sensor; the force's worst is 5.27 N with the FlexiForce noise.
    assert np.ptp(xr[during]) < 1e-4
    assert fault["worst_force_during"] < 1.1 * FR


def test_sensor_zero_pushes_no_further_than_the_travel_bound():
    result, fault = _run("sensor_zero")
    _check_common(result, fault)
    xr = result.reference_offset[:, 0]
    max_push = result.scenario.admittance.max_push
    assert np.max(xr) <= max_push + 1e-9
    # A sensor reading 0 N makes the law push Xr to the bound. Statically the PID then
    # presses with at most Kp max_push plus what its integral held before (< Fr); the step
    # of Xr to the bound overshoots, by less than 100 % for this damped contact mode.
    push = result.scenario.pid.kp[0] * max_push
    late_in_fault = (result.time > END - 0.1) & (result.time < END)
    assert FR < np.max(result.force[late_in_fault]) < push + FR
    assert fault["worst_force_during"] < 2.0 * push + FR


def test_without_the_travel_bound_a_zero_reading_exceeds_that_force():
    """The contrast: the same fault with max_push at its largest allowed value (0.5 m). Xr
    grows at Gamma K Fr = 0.125 m/s for the 0.5 s of the fault, to about 60 mm: the PID
    then presses with about Kp 60 mm = 150 N, beyond the bound's 2 Kp max_push + Fr = 55 N."""
    bounded_push = 2500.0 * 0.01  # Kp max_push of the default scenario, N
    result, fault = _run("sensor_zero", extra=("admittance.max_push=0.5", "duration=2.0"))
    assert np.max(result.reference_offset[:, 0]) > 0.04
    assert fault["worst_force_during"] > 2.0 * bounded_push + FR


def _check_saturated(sensor: str) -> None:
    saturated, fault = _run("sensor_saturated", 111.0, sensor)
    _check_common(saturated, fault)
    # A full-scale reading makes the law retract, never past max_retract; the force drops.
    xr = saturated.reference_offset[:, 0]
    assert np.min(xr) >= -saturated.scenario.admittance.max_retract - 1e-9
    assert fault["worst_force_during"] < 1.1 * FR


@pytest.mark.slow
@pytest.mark.parametrize("sensor", ["ideal", "flexiforce"])
def test_sensor_stuck_and_saturated(sensor):
    stuck, fault = _run("sensor_stuck", 2.0, sensor)
    _check_common(stuck, fault)
    assert np.max(stuck.reference_offset[:, 0]) <= stuck.scenario.admittance.max_push + 1e-9
    _check_saturated(sensor)


@pytest.mark.slow
def test_wall_retract_loses_contact_and_comes_back():
    result, fault = _run("wall_retract", 0.02)
    _check_common(result, fault)
    during = _during(result)
    assert np.min(result.force[during]) == 0.0  # the wall jumped away: contact lost
    xr = result.reference_offset[:, 0]
    assert np.max(xr) <= result.scenario.admittance.max_push + 1e-9
    # The wall snaps back onto a tip that followed it by at most max_push: the force on
    # return is bounded by Ke times that travel (plus the settled penetration).
    ke = result.scenario.wall.stiffness
    assert np.max(result.force) < ke * (result.scenario.admittance.max_push + FR / ke) * 1.1


@pytest.mark.slow
def test_stiffness_jump_is_the_one_fault_no_controller_prevents():
    result, fault = _run("stiffness_jump", 1e7)
    _check_common(result, fault)
    # At fixed penetration the force jumps with Ke before any controller can act:
    # F = Fr * 1e7 / 5e4 = 1000 N at the instant of the jump.
    assert fault["worst_force_during"] == pytest.approx(FR * 1e7 / 5e4, rel=0.02)
