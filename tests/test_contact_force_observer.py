"""The momentum observer of the contact force (systems/contact_force_observer.py) against the
arm's dynamics written with the plant's own terms: r = K_o (M v - p_I) is the external joint
torque once settled, F_hat = -(J^-T r)_x, and dp_I/dt = B u + tau_g + r."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.robots.planar_arm import SolvePlanarInverseKinematics
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.planar_kinematics import PlanarFrameKinematics

POSE = [0.2, -0.25, math.pi / 2]


@pytest.fixture
def arm(arm_plant):
    q = SolvePlanarInverseKinematics(arm_plant, "fingertip", POSE, [-0.45, 1.66, 0.36])
    v = np.array([0.3, -0.2, 0.1])  # moving: p = M v is not zero
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip")
    kinematics.set_state(np.concatenate([q, v]))
    return arm_plant, np.concatenate([q, v]), kinematics.jacobian()


@pytest.mark.parametrize("wall_force", [[5.0, 0.0, 0.0], [2.0, -3.0, 0.1]])
def test_a_settled_observer_reads_the_wall_force_from_the_joint_torques(arm, wall_force):
    """With r set to the external torque J^T (-F) of a wall force F (compressive along x),
    the estimate is F_x: the normal force, whatever the tangential force and moment."""
    plant, state, jacobian = arm
    observer = ContactForceObserver(plant)
    context = observer.CreateDefaultContext()
    observer.estimated_state_input.FixValue(context, state)
    observer.actuation_input.FixValue(context, np.zeros(3))
    observer.set_external_torque(context, jacobian.T @ -np.asarray(wall_force))
    # J^-T of the arm at this pose: the least-squares solve is exact to rounding (3e-15 N
    # measured); 1e-9 N leaves room for the condition of J.
    assert observer.contact_force_output.Eval(context)[0] == pytest.approx(wall_force[0], abs=1e-9)


def test_the_integral_follows_the_applied_gravity_and_external_torques(arm):
    """dp_I/dt = B u + tau_g(q) + r, with B = I (one actuator per joint, in joint order),
    tau_g from the plant and r = K_o (M v - p_I) = the external torque set."""
    plant, state, jacobian = arm
    observer = ContactForceObserver(plant, gain=50.0)
    context = observer.CreateDefaultContext()
    observer.estimated_state_input.FixValue(context, state)
    actuation = np.array([1.5, -0.7, 0.2])
    observer.actuation_input.FixValue(context, actuation)
    external = jacobian.T @ [-5.0, 0.0, 0.0]
    observer.set_external_torque(context, external)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, state)
    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    rate = observer.EvalTimeDerivatives(context).CopyToVector()
    # The same plant terms summed: equal to the bit here (measured); 1e-12 allows for
    # another order of the sum.
    np.testing.assert_allclose(rate, actuation + gravity + external, rtol=1e-12, atol=1e-12)
    # p_I itself: M v - r / K_o (equal to the bit as well).
    momentum = plant.CalcMassMatrix(plant_context) @ state[3:]
    np.testing.assert_allclose(
        context.get_continuous_state_vector().CopyToVector(),
        momentum - external / 50.0,
        rtol=1e-12,
    )


def test_the_gain_is_checked_keyword_only_and_defaults_to_100_per_second(arm_plant):
    assert ContactForceObserver(arm_plant).gain == 100.0
    assert ContactForceObserver(arm_plant, gain=0.5).gain == 0.5
    for gain in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError, match="gain must be > 0"):
            ContactForceObserver(arm_plant, gain=gain)
    with pytest.raises(TypeError):
        ContactForceObserver(arm_plant, "fingertip", 100.0)
