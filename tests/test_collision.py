"""The collision reflex (docs/evidence/safety-collision.md, "The collision reflex"): a torque on a
link that the
contact sensor does not explain is a collision, not a sensor fault, and the arm stops.

* the classification by hand: at the pose (0.2, -0.25, pi/2) a residual along
  j = J_x^T (a fingertip force along the normal) is explained whatever its size, one
  orthogonal to j is not, and a torque on one joint leaves sqrt(1 - j_i^2 / |j|^2) of
  itself unexplained;
* the detector sample by sample: a collision is flagged after three samples and never as
  a sensor fault; a sensor at zero with the arm's torques consistent is still implausible,
  and in closed loop a reading at zero or stuck is still implausible, no collision;
* the joint_torque fault's torque on the plant, and its keys' checks;
* in closed loop (the moving-wall arm on a static 1e5 N/m wall, the ideal sensor, the
  layer on): 2 N m on the elbow is a collision, detected within the delay derived from
  the observer's lag, the force stays under Fmax, and the tip stops within the time its
  PID's slow mode gives.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.safety_layer import STOP_SPEED
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.collision_check import collision_tolerance, unexplained_torque
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import FAULT_FLAGS, FaultDetectorParams, SensorFaultDetector
from admittance.systems.joint_torque_fault import JointTorqueFault, JointTorqueFault_
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

PERIOD = 0.005
TOLERANCE = 1.12  # 0.2 Fr + 6 sigma for Fr = 5 N, sigma = 0.02 N
OBSERVER_GAIN = 100.0
FMAX = 10.0
POSE = [0.2, -0.25, math.pi / 2]


def _normal_row(arm_plant, pose=POSE):
    q = SolvePlanarInverseKinematics(
        arm_plant, "fingertip", pose, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    return q, kinematics.jacobian()


def test_a_torque_along_j_is_explained_and_one_orthogonal_to_it_is_not(arm_plant):
    _, jacobian = _normal_row(arm_plant)
    j = jacobian[0]
    # A fingertip force of 3 N along the normal, pushing back: r = -3 j, nothing unexplained.
    assert unexplained_torque(-3.0 * j, j) < 1e-12
    assert unexplained_torque(40.0 * j, j) < 1e-10
    # Orthogonal to j (in the plane of j and e_2): all of it unexplained.
    orthogonal = np.cross(j, np.cross(np.array([0.0, 0.0, 1.0]), j))
    assert abs(orthogonal @ j) < 1e-12
    assert unexplained_torque(orthogonal, j) == pytest.approx(np.linalg.norm(orthogonal), 1e-12)
    # A torque tau on joint i: |tau e_i - j j_i tau / |j|^2| = |tau| sqrt(1 - j_i^2 / |j|^2).
    for joint in range(3):
        torque = np.zeros(3)
        torque[joint] = 2.0
        by_hand = 2.0 * math.sqrt(1.0 - j[joint] ** 2 / (j @ j))
        assert unexplained_torque(torque, j) == pytest.approx(by_hand, 1e-12)
    # The threshold: the torque norm of a fingertip force error of F_tol.
    assert collision_tolerance(j, TOLERANCE) == pytest.approx(np.linalg.norm(TOLERANCE * j), 1e-12)


def _monitor(arm_plant):
    detector = SensorFaultDetector(
        arm_plant,
        contact=ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0),
        params=FaultDetectorParams(
            period=PERIOD,
            noise_std=0.02,
            saturation_force=111.03,
            contact_force=0.5,
            force_tolerance=TOLERANCE,
            observer_gain=OBSERVER_GAIN,
        ),
    )
    context = detector.CreateDefaultContext()
    q, jacobian = _normal_row(arm_plant)
    detector.estimated_state_input.FixValue(context, np.concatenate([q, np.zeros(3)]))
    detector.stiffness_estimate_input.FixValue(context, [5e4])
    detector.set_reading(context, 5.0)
    return detector, context, jacobian[0]


def _noisy(count, seed=1, mean=5.0):
    """Readings with the sensor's noise (a constant one would be stuck)."""
    return mean + 0.02 * np.random.default_rng(seed).standard_normal(count)


def _sample(detector, context, reading, observed, residual):
    detector.measured_force_input.FixValue(context, [reading])
    detector.observed_force_input.FixValue(context, [observed])
    detector.external_torque_input.FixValue(context, residual)
    update = detector.EvalUniquePeriodicDiscreteUpdate(context)
    context.get_mutable_discrete_state().SetFrom(update)
    flags = dict(zip(FAULT_FLAGS, detector.fault_flags_output.Eval(context) > 0.5, strict=True))
    flags["collision"] = detector.collision_output.Eval(context)[0] > 0.5
    flags["sensor_fault"] = detector.sensor_fault_output.Eval(context)[0] > 0.5
    return flags


def test_a_torque_on_the_elbow_is_a_collision_after_three_samples_not_a_sensor_fault(
    arm_plant,
):
    """The arm presses 5 N (r = -5 j); then 2 N m on the elbow: F_hat moves by
    -(J^-T e_1)_x 2 N (the observer's estimate no longer agrees with the reading), and
    |r_perp| is above |j| F_tol. Three samples of evidence flag a collision; the
    plausibility check takes no evidence meanwhile; sensor_fault stays 0; it latches."""
    detector, context, j = _monitor(arm_plant)
    in_contact = -5.0 * j
    for reading in _noisy(5):
        assert not any(_sample(detector, context, reading, 5.0, in_contact).values())
    torque = np.array([0.0, 2.0, 0.0])
    assert unexplained_torque(torque, j) > collision_tolerance(j, TOLERANCE)
    _, jacobian = _normal_row(arm_plant)
    shifted = 5.0 - np.linalg.solve(jacobian.T, torque)[0]  # F_hat with the elbow's torque
    assert abs(shifted - 5.0) > 2 * TOLERANCE
    flags = [
        _sample(detector, context, reading, shifted, in_contact + torque)
        for reading in _noisy(6, seed=2)
    ]
    assert [f["collision"] for f in flags] == [False, False, True, True, True, True]
    assert not any(f["implausible"] or f["sensor_fault"] for f in flags)
    # Latched: the torque gone, the flag stays.
    assert _sample(detector, context, 5.01, 5.0, in_contact)["collision"]


def test_a_torque_below_the_threshold_and_a_force_along_j_raise_nothing(arm_plant):
    detector, context, j = _monitor(arm_plant)
    e_elbow = np.array([0.0, 1.0, 0.0])
    minimum = collision_tolerance(j, TOLERANCE) / unexplained_torque(e_elbow, j)
    for reading in _noisy(10):
        flags = _sample(detector, context, reading, 5.0, -5.0 * j + 0.9 * minimum * e_elbow)
        assert not flags["collision"]
    for reading in _noisy(10, mean=40.0):  # 40 N along the normal: explained, however large
        assert not _sample(detector, context, reading, 40.0, -40.0 * j)["collision"]


def test_a_sensor_at_zero_is_still_implausible_when_the_arm_s_torques_agree(arm_plant):
    """The reading drops to about 0 N while r stays -5 j: the fault is in the reading, r has
    nothing unexplained, so it is a sensor fault (implausible), not a collision."""
    detector, context, j = _monitor(arm_plant)
    readings = 0.0 + 0.02 * np.random.default_rng(3).standard_normal(6)
    flags = [_sample(detector, context, r, 5.0, -5.0 * j) for r in readings]
    assert [f["implausible"] for f in flags] == [False, False, False, True, True, True]
    assert not any(f["collision"] for f in flags)


def test_the_joint_torque_fault_adds_its_torque_inside_its_window_and_converts():
    fault = JointTorqueFault(3, [(1.0, 2.0, 2.5, 1), (1.5, 3.0, -1.0, 2)])
    context = fault.CreateDefaultContext()
    fault.generalized_force_input.FixValue(context, [0.1, 0.2, 0.3])
    for time, expected in (
        (0.5, [0.1, 0.2, 0.3]),
        (1.0, [0.1, 2.7, 0.3]),
        (1.7, [0.1, 2.7, -0.7]),
        (2.0, [0.1, 0.2, -0.7]),
        (3.0, [0.1, 0.2, 0.3]),
    ):
        context.SetTime(time)
        np.testing.assert_allclose(fault.generalized_force_output.Eval(context), expected)
    converted = fault.ToAutoDiffXd()
    assert isinstance(converted, JointTorqueFault_[AutoDiffXd])
    converted_context = converted.CreateDefaultContext()
    converted.generalized_force_input.FixValue(converted_context, [AutoDiffXd(0.0)] * 3)
    converted_context.SetTime(1.2)
    assert [x.value() for x in converted.generalized_force_output.Eval(converted_context)] == [
        0.0,
        2.5,
        0.0,
    ]
    with pytest.raises(ValueError, match="joint must be in"):
        JointTorqueFault(3, [(1.0, 2.0, 1.0, 3)])


@pytest.mark.parametrize(
    "fault, message",
    [
        ("{kind: joint_torque, start: 1, end: 2, value: 2}", "faults[0].joint: missing"),
        ("{kind: joint_torque, start: 1, end: 2, joint: 1}", "faults[0].value: missing"),
        (
            "{kind: joint_torque, start: 1, end: 2, value: 2, joint: 3}",
            "faults[0].joint: must be a joint index in [0, 2]",
        ),
        (
            "{kind: joint_torque, start: 1, end: 2, value: 0, joint: 1}",
            "faults[0].value: must be non-zero and within +-60 N m",
        ),
    ],
)
def test_bad_joint_torque_faults_are_one_line_naming_the_key(fault, message):
    with pytest.raises(ScenarioError) as error:
        load_scenario("safe_contact", [f"faults=[{fault}]"])
    text = str(error.value)
    assert "\n" not in text and text.startswith(message), text


ELBOW_TORQUE = 2.0
START, END = 1.0, 1.5


@pytest.fixture(scope="module")
def elbow_collision():
    """The moving-wall arm 5 mm before a static 1e5 N/m wall, the ideal sensor, the layer
    on: in contact at Fr by 1 s; 2 N m on the elbow from 1 to 1.5 s (3 s of wall time)."""
    return run_scenario(
        load_scenario(
            "safe_contact",
            [
                "arm.initial_position=[0.145,-0.25,1.5707963267948966]",
                "wall.velocity=0",
                "sensor.kind=ideal",
                f"duration={END}",
                f"faults=[{{kind: joint_torque, start: {START}, end: {END}, "
                f"value: {ELBOW_TORQUE}, joint: 1}}]",
            ],
        )
    )


def test_a_torque_on_the_elbow_is_a_collision_and_the_arm_stops_under_fmax(
    arm_plant, elbow_collision
):
    """Detection: r_perp rises as |tau_perp| (1 - e^(-K_o t)) and crosses |j| F_tol at
    t_r = -ln(1 - |j| F_tol / |tau_perp|) / K_o; then three samples, the first within T of
    the crossing: at most t_r + 4 T. Stop: the wall holds x, so the torque moves the tip
    along y with the force w_y = (J^-T tau)_y against the PID's spring and damper
    (Kp 1200 N/m, Kd 170 N s/m, m_y 0.046 kg: overdamped, the slow mode p = 7.07 1/s,
    nearly Kp / Kd). The speed never passes |w_y| / Kd (where the acceleration is zero,
    Kd v = w_y - Kp y) and then decays as e^(-p t): below STOP_SPEED by
    t_peak + ln(|w_y| / (Kd STOP_SPEED)) / p, t_peak = ln(p2 / p) / (p2 - p) (0.38 s),
    within a margin of 20 %."""
    result = elbow_collision
    (fault,) = result.metrics["faults"]
    assert fault["detected_kind"] == "collision"
    assert [d["kind"] for d in result.metrics["safety"]["detections"]] == ["collision"]
    q, jacobian = _normal_row(arm_plant, [0.15, -0.25, math.pi / 2])
    j = jacobian[0]
    torque = np.array([0.0, ELBOW_TORQUE, 0.0])
    tolerance = collision_tolerance(j, 0.2 * 5.0)  # the ideal sensor: F_tol = 0.2 Fr
    rise = -math.log(1.0 - tolerance / unexplained_torque(torque, j)) / OBSERVER_GAIN
    assert 0.0 < fault["detection_delay"] <= rise + 4 * PERIOD
    # The stop.
    context = arm_plant.CreateDefaultContext()
    arm_plant.SetPositions(context, q)
    mass_matrix = arm_plant.CalcMassMatrix(context)
    mass = 1.0 / (jacobian[1] @ np.linalg.solve(mass_matrix, jacobian[1]))
    kp, kd = 1200.0, 170.0
    root = math.sqrt(kd**2 - 4 * mass * kp)
    slow, fast = (kd - root) / (2 * mass), (kd + root) / (2 * mass)
    push = abs(np.linalg.solve(jacobian.T, torque)[1])
    peak_time = math.log(fast / slow) / (fast - slow)
    stop_bound = peak_time + math.log(push / (kd * STOP_SPEED)) / slow
    after = result.time >= START
    assert np.max(result.safety["tip_speed"][after]) <= push / kd
    assert fault["time_to_stop"] is not None
    assert fault["detection_delay"] < fault["time_to_stop"] <= 1.2 * stop_bound
    # The force: never above Fmax, and unloaded by the reflex to the contact threshold
    # F_c = 0.5 N, where the retreat stops (measured 0.482-0.5004 N after 0.2 s).
    assert fault["peak_force_after_collision"] <= FMAX
    late = result.time >= START + 0.2
    assert np.max(result.force[late]) < 1.05 * 0.5
    assert fault["peak_joint_torque_after_collision"] < 30.0  # the shoulder's effort limit


@pytest.mark.parametrize("kind", ["sensor_zero", "sensor_stuck"])
def test_a_sensor_fault_in_closed_loop_is_still_that_sensor_fault_and_no_collision(kind):
    """The stiffness-step arm pressing 5 N, the ideal sensor: a reading at 0 N or stuck at
    4 N from 0.6 to 0.8 s is flagged implausible (the arm's torques agree with the wall's
    force, not with the reading), and nothing is taken for a collision (1.3 s each)."""
    result = run_scenario(
        load_scenario(
            "paper_stiffness_step",
            [
                "duration=1.2",
                "wall.stiffness_steps=[]",
                "sensor.kind=ideal",
                "admittance.max_force=10",
                f"faults=[{{kind: {kind}, start: 0.6, end: 0.8, value: 4.0}}]",
                "safety.enabled=true",
            ],
        )
    )
    assert [d["kind"] for d in result.metrics["safety"]["detections"]] == ["implausible"]
    assert result.metrics["faults"][0]["detected_kind"] == "implausible"
