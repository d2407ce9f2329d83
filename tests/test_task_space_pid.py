"""A Cartesian PID on a task space given at construction: a finger of Drake's planar hand."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.planar_gripper.plant import (
    FINGER_COORDINATES,
    AddHand,
    contact_frame,
    tip_centre_frame,
)
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.planar_kinematics import PlanarKinematics

# --- a PID on a task space given at construction -----------------------------------------


@pytest.fixture(scope="module")
def hand():
    builder = DiagramBuilder()
    plant, _, geometry = AddHand(builder, GraspScenario())
    return plant, geometry


def _finger_pid(plant, finger, kp):
    """finger's PlanarKinematics (generated code) and a PD (ki = 0) on its tip."""
    kinematics = PlanarKinematics(
        plant,
        frame_name=tip_centre_frame(finger),
        coordinates=FINGER_COORDINATES,
        expressed_in=contact_frame(finger),
    )
    pid = CartesianPid(
        plant,
        frame_name=tip_centre_frame(finger),
        kp=kp,
        kd=[0.0, 0.0],
        ki=[0.0, 0.0],
        coordinates=FINGER_COORDINATES,
        expressed_in=contact_frame(finger),
    )
    return kinematics, pid


def test_finger_pid_is_the_transpose_jacobian_law_on_its_own_joints(hand):
    """tau = B^T J^T Kp (Xc - X) with J the tip's 2 x nv Jacobian in its face frame.

    Independent: X and J from Drake's point position and translational Jacobian of the tip
    centre in world, turned into the face frame by hand (R_CW), not through the task-space
    kinematics (generated code) that the PID reads.
    """
    plant, geometry = hand
    finger = "finger1"
    kp = np.array([2500.0, 1500.0])
    kinematics, pid = _finger_pid(plant, finger, kp)
    plant_context = plant.CreateDefaultContext()
    q = np.linspace(-0.4, 0.5, plant.num_positions())
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, np.linspace(0.3, -0.2, plant.num_velocities()))
    state = plant.GetPositionsAndVelocities(plant_context)
    kinematics_context = kinematics.CreateDefaultContext()
    kinematics.estimated_state_input.FixValue(kinematics_context, state)
    values = kinematics.kinematics_output.Eval(kinematics_context)

    X_WC = geometry.face_frames[0]
    tip = plant.GetFrameByName(tip_centre_frame(finger))
    p_WT = plant.CalcPointsPositions(plant_context, tip, np.zeros(3), plant.world_frame())[:, 0]
    J_W = plant.CalcJacobianTranslationalVelocity(
        plant_context,
        JacobianWrtVariable.kV,
        tip,
        np.zeros(3),
        plant.world_frame(),
        plant.world_frame(),
    )
    R_CW = X_WC.rotation().inverse().matrix()
    p_CT = X_WC.inverse().multiply(p_WT)
    J_C = (R_CW @ J_W)[:2]
    v = state[plant.num_positions() :]
    # The generated code against Drake's own kinematics: X, dX/dt = J v, J.
    np.testing.assert_allclose(values[:2], p_CT[:2], rtol=0, atol=1e-14)
    np.testing.assert_allclose(values[2:4], J_C @ v, rtol=0, atol=1e-13)
    np.testing.assert_allclose(values[4:].reshape(2, -1), J_C, rtol=0, atol=1e-13)

    context = pid.CreateDefaultContext()
    offset = np.array([0.003, -0.002])
    pid.kinematics_input.FixValue(context, values)
    pid.commanded_position_input.FixValue(context, p_CT[:2] + offset)
    pid.commanded_velocity_input.FixValue(context, J_C @ v)  # no rate error
    expected = (J_C.T @ (kp * offset))[:6]  # the actuators drive the six finger joints
    torque = pid.actuation_output.Eval(context)
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-12)
    # finger1's PID moves only finger1's two joints.
    assert np.all(torque[2:] == 0.0)
    assert pid.coordinates == ("x", "y")
    assert pid.law.ToAutoDiffXd().coordinates == ("x", "y")
    assert kinematics.ToAutoDiffXd().coordinates == ("x", "y")


def test_finger_holding_integral_balances_a_tip_force(hand):
    """With the integral from holding_integral and zero error, the PID's torque is the
    generalized force asked for on the finger's own joints."""
    plant, _ = hand
    finger = "finger3"
    kinematics, _ = _finger_pid(plant, finger, [2500.0, 2500.0])
    pid = CartesianPid(
        plant,
        frame_name=tip_centre_frame(finger),
        kp=[2500.0, 2500.0],
        kd=[50.0, 50.0],
        ki=[200.0, 150.0],
        coordinates=FINGER_COORDINATES,
        expressed_in=contact_frame(finger),
    )
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, np.linspace(0.2, -0.3, plant.num_positions()))
    state = plant.GetPositionsAndVelocities(plant_context)
    wanted = np.zeros(plant.num_velocities())
    wanted[4:6] = [0.7, -0.4]  # finger3's joints
    integral = pid.holding_integral(state, wanted)
    kinematics_context = kinematics.CreateDefaultContext()
    kinematics.estimated_state_input.FixValue(kinematics_context, state)
    values = kinematics.kinematics_output.Eval(kinematics_context)
    context = pid.CreateDefaultContext()
    pid.set_integral(context, integral)
    pid.kinematics_input.FixValue(context, values)
    pid.commanded_position_input.FixValue(context, values[:2])
    pid.commanded_velocity_input.FixValue(context, values[2:4])
    np.testing.assert_allclose(pid.actuation_output.Eval(context), wanted[:6], atol=1e-12)


def test_task_space_is_checked(hand):
    plant, _ = hand
    with pytest.raises(ValueError, match="coordinates must be distinct names"):
        CartesianPid(plant, frame_name="finger1_tip_centre", kp=1, kd=0, ki=0, coordinates=("q",))
    with pytest.raises(ValueError, match="no frame named 'nowhere'"):
        CartesianPid(
            plant,
            frame_name="finger1_tip_centre",
            coordinates=FINGER_COORDINATES,
            kp=1,
            kd=0,
            ki=0,
            expressed_in="nowhere",
        )
