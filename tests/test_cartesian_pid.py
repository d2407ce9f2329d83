"""The Cartesian PID (eq. 14-16) against the paper's kinematics (eq. 18) written by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.analysis import Simulator

from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.cartesian_pid_law import CartesianPidLaw
from admittance.systems.planar_kinematics import PLANAR_COORDINATES
from admittance.urdf import PLANAR_ARM_URDF

LENGTHS = (0.20, 0.20, 0.10)
KP, KD, KI = [2500.0, 2500.0, 1000.0], [50.0, 50.0, 5.0], [200.0, 200.0, 200.0]


def eq18(q):
    """X = h(q) and J(q) of the paper's eq. 18, written out independently of the plant."""
    l1, l2, l3 = LENGTHS
    a1, a2, a3 = q[0], q[0] + q[1], q[0] + q[1] + q[2]
    x = l1 * math.sin(a1) + l2 * math.sin(a2) + l3 * math.sin(a3)
    y = -l1 * math.cos(a1) - l2 * math.cos(a2) - l3 * math.cos(a3)
    jx = [
        l1 * math.cos(a1) + l2 * math.cos(a2) + l3 * math.cos(a3),
        l2 * math.cos(a2) + l3 * math.cos(a3),
        l3 * math.cos(a3),
    ]
    jy = [
        l1 * math.sin(a1) + l2 * math.sin(a2) + l3 * math.sin(a3),
        l2 * math.sin(a2) + l3 * math.sin(a3),
        l3 * math.sin(a3),
    ]
    return np.array([x, y, a3]), np.array([jx, jy, [1.0, 1.0, 1.0]])


def eq18_kinematics(q, v):
    """The PID's ``kinematics`` input [X; J v; J row by row], from eq. 18 by hand."""
    X, J = eq18(q)
    return np.concatenate([X, J @ v, J.reshape(-1)])


def _pid_context(pid, q, v, commanded, commanded_rate, integral):
    context = pid.CreateDefaultContext()
    pid.kinematics_input.FixValue(context, eq18_kinematics(q, v))
    pid.commanded_position_input.FixValue(context, commanded)
    pid.commanded_velocity_input.FixValue(context, commanded_rate)
    pid.set_integral(context, integral)
    return context


def _sampled_update(pid, context):
    """The sampled PID's next (integral, held torque): its two discrete state groups."""
    updated = pid.EvalUniquePeriodicDiscreteUpdate(context)
    return (updated.get_vector(group).CopyToVector() for group in (0, 1))


def test_torque_is_jacobian_transpose_of_pid_wrench(arm_plant):
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = np.array([-0.45, 1.66, 0.36]) + rng.uniform(-0.3, 0.3, 3)
        v = rng.uniform(-0.1, 0.1, 3)
        X, J = eq18(q)
        commanded = X + rng.uniform(-1e-3, 1e-3, 3)
        commanded_rate = rng.uniform(-0.01, 0.01, 3)
        integral = rng.uniform(-1e-3, 1e-3, 3)
        context = _pid_context(pid, q, v, commanded, commanded_rate, integral)
        error = commanded - X
        error_rate = commanded_rate - J @ v
        wrench = np.multiply(KP, error) + np.multiply(KD, error_rate) + np.multiply(KI, integral)
        expected = J.T @ wrench
        assert np.all(np.abs(expected) < pid.effort_limits)  # not clipped in this test
        np.testing.assert_allclose(pid.actuation_output.Eval(context), expected, atol=1e-9)
        np.testing.assert_allclose(
            pid.EvalTimeDerivatives(context).CopyToVector(), error, atol=1e-12
        )


def test_torque_is_clipped_to_the_urdf_effort_limits(arm_plant):
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    # 1 m of error along x asks for 2500 N: far beyond every joint's limit.
    context = _pid_context(pid, q, np.zeros(3), X + [1.0, 0, 0], np.zeros(3), np.zeros(3))
    torque = pid.actuation_output.Eval(context)
    unclipped = J.T @ np.array([2500.0, 0.0, 0.0])
    limits = pid.effort_limits
    np.testing.assert_allclose(limits, [30.0, 20.0, 5.0])
    np.testing.assert_allclose(torque, np.clip(unclipped, -limits, limits), atol=1e-12)
    assert np.any(np.abs(unclipped) > limits)


def test_back_calculation_while_saturated(arm_plant):
    """Anti-windup: while an actuator is at its limit the integral is pulled back.

    dz/dt = ec + J^-T (clip(tau) - tau) / (Ki Tt) with Tt = sqrt(Kd / Ki) (>= 10 ms): the
    correction is exactly the Cartesian wrench the clipping removed, scaled by 1 / (Ki Tt).
    """
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    small = _pid_context(pid, q, np.zeros(3), X + [1e-4, 0, 0], np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(pid.EvalTimeDerivatives(small).CopyToVector(), [1e-4, 0, 0])
    error = np.array([0.5, 0.0, 0.0])
    blocked = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    torque = pid.actuation_output.Eval(blocked)
    assert np.any(np.abs(torque) == pid.effort_limits)
    unclipped = J.T @ (np.array(KP) * error)
    wrench_excess = np.linalg.solve(J.T, torque - unclipped)
    tracking = np.maximum(np.sqrt(np.array(KD) / np.array(KI)), 0.01)
    expected = error + wrench_excess / (np.array(KI) * tracking)
    rate = pid.EvalTimeDerivatives(blocked).CopyToVector()
    np.testing.assert_allclose(rate, expected, rtol=1e-9, atol=1e-12)
    # It opposes the error along x: the integral unwinds instead of growing.
    assert rate[0] < 0


def test_angle_error_is_wrapped(arm_plant):
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    commanded = X + [0.0, 0.0, 2 * math.pi + 0.001]  # the same angle plus 1 mrad
    context = _pid_context(pid, q, np.zeros(3), commanded, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(
        pid.EvalTimeDerivatives(context).CopyToVector(), [0, 0, 0.001], atol=1e-12
    )


def test_holding_integral_cancels_gravity(arm_plant):
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    plant_context = arm_plant.CreateDefaultContext()
    arm_plant.SetPositions(plant_context, q)
    gravity = arm_plant.CalcGravityGeneralizedForces(plant_context)
    integral = pid.holding_integral(np.concatenate([q, np.zeros(3)]), -gravity)
    context = _pid_context(pid, q, np.zeros(3), X, np.zeros(3), integral)
    np.testing.assert_allclose(pid.actuation_output.Eval(context), -gravity, atol=1e-10)


def test_sampled_pid_holds_its_torque(arm_plant):
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=KD,
        ki=KI,
        period=0.001,
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = _pid_context(pid, q, np.zeros(3), X + [1e-3, 0, 0], np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(pid.actuation_output.Eval(context), 0.0)  # nothing latched yet
    updated = pid.EvalUniquePeriodicDiscreteUpdate(context)
    integral, held = (updated.get_vector(group).CopyToVector() for group in (0, 1))
    np.testing.assert_allclose(integral, [1e-6, 0, 0], atol=1e-15)  # integral += h ec
    np.testing.assert_allclose(held, J.T @ [2.5, 0, 0], atol=1e-9)


def test_autodiff_conversion_gives_the_jacobian_stiffness(arm_plant):
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    ).ToAutoDiffXd()
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = pid.CreateDefaultContext()
    kinematics = eq18_kinematics(q, np.zeros(3))
    pid.GetInputPort("kinematics").FixValue(context, [AutoDiffXd(k) for k in kinematics])
    commanded = [AutoDiffXd(X[i], np.eye(3)[i]) for i in range(3)]
    pid.GetInputPort("commanded_position").FixValue(context, commanded)
    pid.GetInputPort("commanded_velocity").FixValue(context, [AutoDiffXd(0.0, np.zeros(3))] * 3)
    torque = pid.GetOutputPort("actuation").Eval(context)
    gradient = np.array([t.derivatives() for t in torque])
    np.testing.assert_allclose(gradient, J.T @ np.diag(KP), atol=1e-9)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(kp=[0, 1, 1]), "kp must be finite and > 0"),
        (dict(kp=[-1, 1, 1]), "kp must be finite and > 0"),
        (dict(kd=[-1, 1, 1]), "kd must be finite and >= 0"),
        (dict(ki=[1, -1, 1]), "ki must be finite and >= 0"),
        (dict(ki=[1, math.inf, 1]), "ki must be finite"),
        (dict(period=-0.1), "period"),
        (dict(frame_name="nope"), "nope"),
    ],
)
def test_bad_arguments_name_the_argument(arm_plant, kwargs, message):
    arguments = dict(frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        CartesianPid(arm_plant, **arguments)


def test_gains_and_period_are_reported(arm_plant):
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=KD,
        ki=KI,
        period=0.002,
    )
    gains = pid.gains
    for name, value in (("kp", KP), ("kd", KD), ("ki", KI)):
        np.testing.assert_array_equal(gains[name], value)
    assert pid.period == 0.002


def test_arguments_are_keyword_only(arm_plant):
    """Kp, Kd and Ki are all 3-vectors: a positional call could swap them unnoticed."""
    with pytest.raises(TypeError):
        CartesianPid(arm_plant, "fingertip", KP, KD, KI)
    with pytest.raises(TypeError):  # the frame and the task are the caller's: no default
        CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)


def test_small_positive_and_zero_gains_are_accepted(arm_plant):
    """kp > 0 (not >= 1), kd and ki >= 0: a soft, undamped, integral-free PID is valid."""
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=[0.5, 0.5, 0.5],
        kd=0.0,
        ki=0.0,
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = _pid_context(pid, q, np.zeros(3), X + [0.1, 0, 0], np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(pid.actuation_output.Eval(context), J.T @ [0.05, 0, 0], atol=1e-12)


def test_holding_the_arm_through_the_integral_needs_ki_on_every_axis(arm_plant):
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=KD,
        ki=[200.0, 0.0, 200.0],
    )
    q = np.array([-0.45, 1.66, 0.36])
    with pytest.raises(ValueError, match="ki > 0 on all axes"):
        pid.holding_integral(np.r_[q, 0, 0, 0], np.ones(3))


def test_torque_is_clipped_when_every_joint_saturates(arm_plant):
    """1 m and 1 rad of error on every axis ask for far more than any actuator gives: the
    output is the limits themselves, with the unclipped torque's signs."""
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    for sign in (+1.0, -1.0):
        error = sign * np.array([1.0, 1.0, 1.0])
        context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
        unclipped = J.T @ (np.array(KP) * error)
        assert np.all(np.abs(unclipped) > pid.effort_limits)
        np.testing.assert_allclose(
            pid.actuation_output.Eval(context), np.sign(unclipped) * pid.effort_limits
        )


@pytest.mark.parametrize("sign", [+1.0, -1.0], ids=["positive", "negative"])
def test_autodiff_pid_clips_and_winds_back_like_the_float_one(arm_plant, sign):
    """The AutoDiffXd law (what Linearize uses) saturates at the same limits, both signs,
    with zero derivative where clipped, and the same back-calculation rate."""
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    pid_ad = pid.ToAutoDiffXd()
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    commanded = X + sign * np.array([0.5, 0.0, 0.0])
    context = _pid_context(pid, q, np.zeros(3), commanded, np.zeros(3), np.zeros(3))
    # The converted PID is a plain Diagram: its ports by name, its integral the state of
    # its Integrator (the diagram's only continuous state).
    context_ad = pid_ad.CreateDefaultContext()
    kinematics = eq18_kinematics(q, np.zeros(3))
    pid_ad.GetInputPort("kinematics").FixValue(context_ad, [AutoDiffXd(k) for k in kinematics])
    pid_ad.GetInputPort("commanded_position").FixValue(
        context_ad, [AutoDiffXd(c, np.eye(3)[i]) for i, c in enumerate(commanded)]
    )
    pid_ad.GetInputPort("commanded_velocity").FixValue(
        context_ad, [AutoDiffXd(0.0, np.zeros(3))] * 3
    )
    context_ad.SetContinuousState([AutoDiffXd(0.0, np.zeros(3))] * 3)
    torque = pid.actuation_output.Eval(context)
    torque_ad = pid_ad.GetOutputPort("actuation").Eval(context_ad)
    np.testing.assert_allclose([t.value() for t in torque_ad], torque, atol=1e-12)
    clipped = np.abs(torque) == pid.effort_limits
    assert np.any(clipped)
    for t in np.asarray(torque_ad)[clipped]:
        np.testing.assert_array_equal(t.derivatives(), 0.0)  # (Drake may leave it empty)
    rate = pid.EvalTimeDerivatives(context).CopyToVector()
    rate_ad = pid_ad.EvalTimeDerivatives(context_ad).CopyToVector()
    np.testing.assert_allclose([r.value() for r in rate_ad], rate, rtol=1e-12)


def test_back_calculation_leaves_axes_without_integral_alone(arm_plant):
    """ki = 0 on y: that axis has no integral to unwind, its rate stays ec_y (finite)."""
    ki = [200.0, 0.0, 200.0]
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=ki
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    error = np.array([0.5, 0.01, 0.0])
    context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    assert np.any(np.abs(pid.actuation_output.Eval(context)) == pid.effort_limits)
    rate = pid.EvalTimeDerivatives(context).CopyToVector()
    assert np.all(np.isfinite(rate))
    assert rate[1] == pytest.approx(error[1], rel=1e-12)  # the error, to rounding
    assert rate[0] < 0  # x still unwinds


def test_sampled_pid_has_no_continuous_state_and_reads_its_integral_anew(arm_plant):
    """The sampled law's cache follows the discrete state: a new integral gives a new update."""
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=KD,
        ki=KI,
        period=0.001,
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = _pid_context(pid, q, np.zeros(3), X, np.zeros(3), np.zeros(3))
    assert pid.EvalTimeDerivatives(context).size() == 0
    _, first = _sampled_update(pid, context)
    np.testing.assert_allclose(first, 0.0, atol=1e-12)
    pid.set_integral(context, [1e-3, 0.0, 0.0])
    _, second = _sampled_update(pid, context)
    np.testing.assert_allclose(second, J.T @ [KI[0] * 1e-3, 0, 0], atol=1e-12)


def test_sampled_anti_windup_tracking_time_is_five_periods(arm_plant):
    """Without D the tracking time sqrt(Kd / Ki) is 0: it is max(10 ms, 5 periods), 50 ms
    at a 10 ms period, so the integral moves by h (ec + J^-T dtau / (Ki 0.05))."""
    period = 0.01
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=0.0,
        ki=KI,
        period=period,
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    error = np.array([0.5, 0.0, 0.0])
    context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    integral, held = _sampled_update(pid, context)
    unclipped = J.T @ (np.array(KP) * error)
    clipped = np.clip(unclipped, -pid.effort_limits, pid.effort_limits)
    assert np.any(clipped != unclipped)
    wrench_excess = np.linalg.solve(J.T, clipped - unclipped)
    rate = error + wrench_excess / (np.array(KI) * 5 * period)
    np.testing.assert_allclose(integral, period * rate, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(held, clipped, atol=1e-12)


def _arm_with_transmissions(order) -> MultibodyPlant:
    """The arm's URDF with its transmissions (actuators) in `order` (indices, repeats
    allowed), parsed into a finalized plant."""
    text = (Path(__file__).resolve().parents[1] / "urdf" / "planar_arm.urdf").read_text()
    head, *transmissions = text.split("<transmission")
    last, tail = transmissions[-1].split("</transmission>", 1)
    transmissions[-1] = last + "</transmission>"
    chosen = []
    for count, index in enumerate(order):
        transmission = transmissions[index]
        if order[:count].count(index):  # a second actuator on the same joint
            transmission = transmission.replace('name="joint', f'name="extra{count}_joint', 1)
            transmission = transmission.replace('<actuator name="', f'<actuator name="x{count}')
        chosen.append("<transmission" + transmission)
    plant = MultibodyPlant(time_step=0.0)
    Parser(plant).AddModelsFromString(head + "".join(chosen) + tail, "urdf")
    plant.mutable_gravity_field().set_gravity_vector([0.0, -9.81, 0.0])
    plant.Finalize()
    return plant


@pytest.mark.parametrize("order", [[0, 1], [0, 1, 2, 2]], ids=["under", "over"])
def test_the_pid_needs_one_actuator_per_joint(order):
    plant = _arm_with_transmissions(order)
    assert plant.num_actuated_dofs() == len(order)
    with pytest.raises(ValueError, match="fully actuated"):
        CartesianPid(
            plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
        )


def test_every_joint_that_moves_the_frame_needs_an_actuator():
    """Two actuators are as many as (x, y) has coordinates, but joint3 also moves the
    fingertip and has none: the torque J^T F_PID asks of it would never be applied."""
    plant = _arm_with_transmissions([0, 1])
    with pytest.raises(ValueError, match="joint 'joint3' moves 'fingertip' but has no actuator"):
        CartesianPid(
            plant, frame_name="fingertip", coordinates=("x", "y"), kp=KP[:2], kd=KD[:2], ki=KI[:2]
        )


def test_actuation_follows_the_actuator_order_not_the_joint_order():
    """With the URDF's transmissions listed in reverse, actuator k drives joint 3 - k: the
    output is B^T tau, the torques in actuator order, each clipped to its own limit."""
    plant = _arm_with_transmissions([2, 1, 0])
    joints = [plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()]
    assert joints == ["joint3", "joint2", "joint1"]
    pid = CartesianPid(
        plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    np.testing.assert_allclose(pid.effort_limits, [5.0, 20.0, 30.0])
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    error = np.array([1e-3, -1e-3, 1e-3])
    context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    tau = J.T @ (np.array(KP) * error)
    assert np.all(np.abs(tau) < [30.0, 20.0, 5.0])
    np.testing.assert_allclose(pid.actuation_output.Eval(context), tau[::-1], atol=1e-9)


def test_continuous_pid_reads_its_integral_anew(arm_plant):
    """The continuous law's cache follows the continuous state: a new integral, a new torque."""
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = _pid_context(pid, q, np.zeros(3), X, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(pid.actuation_output.Eval(context), 0.0, atol=1e-12)
    pid.set_integral(context, [1e-3, 0.0, 0.0])
    np.testing.assert_allclose(pid.actuation_output.Eval(context), J.T @ [0.2, 0, 0], atol=1e-12)


@pytest.mark.parametrize(
    "kd, ki, tracking",
    [(50.0, 0.5, 10.0), (0.0, 200.0, 0.01)],
    ids=["sqrt(Kd/Ki)", "10 ms floor"],
)
def test_back_calculation_tracking_time(arm_plant, kd, ki, tracking):
    """Tt = sqrt(Kd / Ki) on x (10 s for Kd = 50, Ki = 0.5), never under 10 ms (Kd = 0)."""
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=[kd, 50.0, 5.0],
        ki=[ki, 200.0, 200.0],
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    error = np.array([0.5, 0.0, 0.0])
    context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    torque = pid.actuation_output.Eval(context)
    wrench_excess = np.linalg.solve(J.T, torque - J.T @ (np.array(KP) * error))
    rate = pid.EvalTimeDerivatives(context).CopyToVector()
    assert rate[0] == pytest.approx(error[0] + wrench_excess[0] / (ki * tracking), rel=1e-9)


def test_cartesian_error_is_the_wrapped_pose_error_even_when_saturated(arm_plant):
    """ec = Xc - h(q), angle wrapped; while saturated dz/dt differs from it, ec does not."""
    pid = CartesianPid(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    commanded = X + [0.5, -0.01, 2 * math.pi + 0.002]
    context = _pid_context(pid, q, np.zeros(3), commanded, np.zeros(3), np.zeros(3))
    error = pid.cartesian_error(context)
    np.testing.assert_allclose(error, [0.5, -0.01, 0.002], atol=1e-12)
    assert not np.allclose(pid.EvalTimeDerivatives(context).CopyToVector(), error)


def test_sampled_pid_latches_its_first_sample_at_t_0(arm_plant):
    """Samples at t = 0, h, 2h (offset 0); 30 ms: 1 s is no whole number of periods, so no
    other offset gives the same times. After 1.5 periods the held torque is the second
    sample's, with the integral advanced once: J^T (Kp ec + Ki h ec)."""
    period = 0.03
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        kp=KP,
        kd=KD,
        ki=KI,
        period=period,
    )
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    error = np.array([1e-3, 0.0, 0.0])
    context = _pid_context(pid, q, np.zeros(3), X + error, np.zeros(3), np.zeros(3))
    Simulator(pid, context).AdvanceTo(1.5 * period)
    expected = J.T @ (np.array(KP) * error + np.array(KI) * period * error)
    np.testing.assert_allclose(pid.actuation_output.Eval(context), expected, rtol=1e-12)


def test_the_law_alone_is_keyword_only_continuous_by_default_and_reads_its_integral(arm_plant):
    """``CartesianPidLaw`` is public (a Diagram of one's own can hold it): its gains are
    keyword-only as the PID's, it is continuous unless given a period, and its z is an
    input (the Integrator's state in ``CartesianPid``), which it refuses to set itself."""
    with pytest.raises(TypeError):
        CartesianPidLaw(arm_plant, KP, KD, KI)
    law = CartesianPidLaw(arm_plant, coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI)
    assert law.period == 0.0
    assert law.HasOutputPort("actuation_and_integral_rate")
    with pytest.raises(ValueError, match="integral is its input"):
        law.set_integral(law.CreateDefaultContext(), np.zeros(3))


def test_holding_integral_of_a_task_with_fewer_coordinates_than_joints(arm_plant):
    """(x, y) on the three-joint arm: J is 2 x 3 and J^T Ki z = tau is solved in the least
    squares sense. For tau = J^T F (in the range of J^T), the solution is exact: z = F / Ki.
    Measured relative error 2e-16; 1e-12 leaves room for the rounding of the solve."""
    pid = CartesianPid(
        arm_plant,
        frame_name="fingertip",
        coordinates=("x", "y"),
        kp=KP[:2],
        kd=KD[:2],
        ki=KI[:2],
    )
    q = np.array([-0.45, 1.66, 0.36])
    _, J = eq18(q)
    force = np.array([3.0, -7.0])
    integral = pid.holding_integral(np.r_[q, 0.0, 0.0, 0.0], J[:2].T @ force)
    np.testing.assert_allclose(integral, force / KI[:2], rtol=1e-12)


def test_holding_integral_leaves_the_bodies_the_arm_does_not_move_alone():
    """The arm and a free box in one plant: J is 3 x 9 (zero columns for the box's six
    velocities) and only the arm's three actuated rows of J^T Ki z = tau are solved; the
    generalized force on the box (its weight here) is another controller's. With the arm's
    tau = J^T F, z = F / Ki (relative error measured 3e-15; 1e-12 as above)."""
    plant = MultibodyPlant(time_step=0.0)
    (arm,) = Parser(plant).AddModels(PLANAR_ARM_URDF)
    plant.AddRigidBody("box", arm, SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    plant.Finalize()
    assert (plant.num_velocities(), plant.num_actuated_dofs()) == (9, 3)
    pid = CartesianPid(
        plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, kp=KP, kd=KD, ki=KI
    )
    q = np.array([-0.45, 1.66, 0.36])
    _, J = eq18(q)
    context = plant.CreateDefaultContext()
    force = np.array([3.0, -7.0, 0.4])
    generalized_force = np.full(9, -9.81)  # the box's rows: not the arm's to hold
    for k, name in enumerate(("joint1", "joint2", "joint3")):
        joint = plant.GetJointByName(name)
        joint.set_angle(context, q[k])
        generalized_force[joint.velocity_start()] = (J.T @ force)[k]
    integral = pid.holding_integral(plant.GetPositionsAndVelocities(context), generalized_force)
    np.testing.assert_allclose(integral, force / KI, rtol=1e-12)
