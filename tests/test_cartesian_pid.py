"""The Cartesian PID (eq. 14-16) against the paper's kinematics (eq. 18) written by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from admittance.systems.cartesian_pid import CartesianPid

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


def test_torque_is_jacobian_transpose_of_pid_wrench(arm_plant):
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)
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
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)
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
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)
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
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    commanded = X + [0.0, 0.0, 2 * math.pi + 0.001]  # the same angle plus 1 mrad
    context = _pid_context(pid, q, np.zeros(3), commanded, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(
        pid.EvalTimeDerivatives(context).CopyToVector(), [0, 0, 0.001], atol=1e-12
    )


def test_holding_integral_cancels_gravity(arm_plant):
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI)
    q = np.array([-0.45, 1.66, 0.36])
    X, _ = eq18(q)
    plant_context = arm_plant.CreateDefaultContext()
    arm_plant.SetPositions(plant_context, q)
    gravity = arm_plant.CalcGravityGeneralizedForces(plant_context)
    integral = pid.holding_integral(np.concatenate([q, np.zeros(3)]), -gravity)
    context = _pid_context(pid, q, np.zeros(3), X, np.zeros(3), integral)
    np.testing.assert_allclose(pid.actuation_output.Eval(context), -gravity, atol=1e-10)


def test_sampled_pid_holds_its_torque(arm_plant):
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI, period=0.001)
    q = np.array([-0.45, 1.66, 0.36])
    X, J = eq18(q)
    context = _pid_context(pid, q, np.zeros(3), X + [1e-3, 0, 0], np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(pid.actuation_output.Eval(context), 0.0)  # nothing latched yet
    updated = pid.EvalUniquePeriodicDiscreteUpdate(context)
    integral, held = (updated.get_vector(group).CopyToVector() for group in (0, 1))
    np.testing.assert_allclose(integral, [1e-6, 0, 0], atol=1e-15)  # integral += h ec
    np.testing.assert_allclose(held, J.T @ [2.5, 0, 0], atol=1e-9)


def test_autodiff_conversion_gives_the_jacobian_stiffness(arm_plant):
    pid = CartesianPid(arm_plant, kp=KP, kd=KD, ki=KI).ToAutoDiffXd()
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
        (dict(kp=[0, 1, 1]), "kp"),
        (dict(kd=[-1, 1, 1]), "kd"),
        (dict(ki=[1, -1, 1]), "ki"),
        (dict(period=-0.1), "period"),
        (dict(frame_name="nope"), "nope"),
    ],
)
def test_bad_arguments_name_the_argument(arm_plant, kwargs, message):
    arguments = dict(kp=KP, kd=KD, ki=KI)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        CartesianPid(arm_plant, **arguments)
