"""A Cartesian PID on a task space given at construction: a finger of Drake's planar hand."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.grasp import (
    FINGER_COORDINATES,
    AddHand,
    contact_frame,
    tip_centre_frame,
)
from admittance.diagrams.grasp_scenario import GraspScenario
from admittance.systems.cartesian_pid import CartesianPid

# --- a PID on a task space given at construction -----------------------------------------


@pytest.fixture(scope="module")
def hand():
    builder = DiagramBuilder()
    plant, _, geometry = AddHand(builder, GraspScenario())
    return plant, geometry


def test_finger_pid_is_the_transpose_jacobian_law_on_its_own_joints(hand):
    """tau = B^T J^T Kp (Xc - X) with J the tip's 2 x nv Jacobian in its face frame.

    Independent: J from Drake's translational Jacobian of the tip centre rotated into the
    face frame by hand (R_CW), not through the PID's kinematics.
    """
    plant, geometry = hand
    finger = "finger1"
    kp = np.array([2500.0, 1500.0])
    pid = CartesianPid(
        plant,
        frame_name=tip_centre_frame(finger),
        kp=kp,
        kd=[0.0, 0.0],
        ki=[0.0, 0.0],
        coordinates=FINGER_COORDINATES,
        expressed_in=contact_frame(finger),
    )
    context = pid.CreateDefaultContext()
    plant_context = plant.CreateDefaultContext()
    q = np.linspace(-0.4, 0.5, plant.num_positions())
    plant.SetPositions(plant_context, q)
    state = plant.GetPositionsAndVelocities(plant_context)
    X_WC = geometry.face_frames[0]
    p_WT = plant.CalcPointsPositions(
        plant_context,
        plant.GetFrameByName(tip_centre_frame(finger)),
        np.zeros(3),
        plant.world_frame(),
    )[:, 0]
    p_CT = X_WC.inverse().multiply(p_WT)
    offset = np.array([0.003, -0.002])
    pid.estimated_state_input.FixValue(context, state)
    pid.commanded_position_input.FixValue(context, p_CT[:2] + offset)
    pid.commanded_velocity_input.FixValue(context, [0.0, 0.0])
    J_W = plant.CalcJacobianTranslationalVelocity(
        plant_context,
        JacobianWrtVariable.kV,
        plant.GetFrameByName(tip_centre_frame(finger)),
        np.zeros(3),
        plant.world_frame(),
        plant.world_frame(),
    )
    J_C = (X_WC.rotation().inverse().matrix() @ J_W)[:2]
    expected = (J_C.T @ (kp * offset))[:6]  # the actuators drive the six finger joints
    torque = pid.actuation_output.Eval(context)
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-12)
    # finger1's PID moves only finger1's two joints.
    assert np.all(torque[2:] == 0.0)
    assert pid.coordinates == ("x", "y")
    assert pid.ToAutoDiffXd().coordinates == ("x", "y")


def test_task_space_is_checked(hand):
    plant, _ = hand
    with pytest.raises(ValueError, match="coordinates must be distinct names"):
        CartesianPid(plant, frame_name="finger1_tip_centre", kp=1, kd=0, ki=0, coordinates=("q",))
    with pytest.raises(ValueError, match="no frame named 'nowhere'"):
        CartesianPid(
            plant, frame_name="finger1_tip_centre", kp=1, kd=0, ki=0, expressed_in="nowhere"
        )
