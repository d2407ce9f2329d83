"""The momentum observer of the contact force (systems/contact_force_observer.py) against the
arm's dynamics written with the plant's own terms: r = K_o (M v - p_I) is the external joint
torque once settled, F_hat = -(J^-T r)_n, and dp_I/dt = B u + tau_g + C(q, v)^T v + r."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.plant import AddPlanarArm
from admittance.diagrams.robots.spatial_arm.loop import BuildSpatialLoop
from admittance.diagrams.robots.spatial_arm.plant import (
    CONTROL_FRAME,
    TOOL_TIP_FRAME,
    example_robot_data_packages,
)
from admittance.diagrams.scenario.files import load_scenario
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics
from admittance.systems.spatial_kinematics import SPATIAL_COORDINATES, SpatialFrameKinematics
from admittance.urdf import PLANAR_ARM_URDF

# The planar arm's fingertip, X = (x, y, theta) in world, the wall's normal x.
TIP = ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0)

POSE = [0.2, -0.25, math.pi / 2]


@pytest.fixture
def arm(arm_plant):
    q = SolvePlanarInverseKinematics(
        arm_plant, "fingertip", POSE, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    v = np.array([0.3, -0.2, 0.1])  # moving: p = M v is not zero
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, v]))
    return arm_plant, np.concatenate([q, v]), kinematics.jacobian()


@pytest.mark.parametrize("wall_force", [[5.0, 0.0, 0.0], [2.0, -3.0, 0.1]])
def test_a_settled_observer_reads_the_wall_force_from_the_joint_torques(arm, wall_force):
    """With r set to the external torque J^T (-F) of a wall force F (compressive along x),
    the estimate is F_x: the normal force, whatever the tangential force and moment."""
    plant, state, jacobian = arm
    observer = ContactForceObserver(plant, contact=TIP)
    context = observer.CreateDefaultContext()
    observer.estimated_state_input.FixValue(context, state)
    observer.actuation_input.FixValue(context, np.zeros(3))
    observer.set_external_torque(context, jacobian.T @ -np.asarray(wall_force))
    # J^-T of the arm at this pose: the least-squares solve is exact to rounding (3e-15 N
    # measured); 1e-9 N leaves room for the condition of J.
    assert observer.contact_force_output.Eval(context)[0] == pytest.approx(wall_force[0], abs=1e-9)


def test_the_integral_follows_the_applied_gravity_and_external_torques(arm):
    """dp_I/dt = B u + tau_g(q) + dT/dq + r, with B = I (one actuator per joint, in joint
    order), tau_g from the plant, dT/dq (= C(q, v)^T v) the kinetic energy's gradient by
    AutoDiffXd, and r = K_o (M v - p_I) = the external torque set."""
    plant, state, jacobian = arm
    observer = ContactForceObserver(plant, contact=TIP, gain=50.0)
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
    ad_plant = plant.ToAutoDiffXd()
    coriolis = _kinetic_energy_gradient(ad_plant, ad_plant.CreateDefaultContext(), state)
    # dT/dq is 3e-4 to 1e-3 N m here; the central difference of M(q) is within 1e-12 N m
    # of the AutoDiffXd gradient (measured 4e-13), 1e-10 leaves room for the rounding.
    assert np.max(np.abs(coriolis)) > 1e-4
    np.testing.assert_allclose(
        rate, actuation + gravity + external + coriolis, rtol=1e-12, atol=1e-10
    )
    # Without the term (the observer as it was), the plant's terms alone.
    plain = ContactForceObserver(plant, contact=TIP, gain=50.0, coriolis=False)
    plain_context = plain.CreateDefaultContext()
    plain.estimated_state_input.FixValue(plain_context, state)
    plain.actuation_input.FixValue(plain_context, actuation)
    plain.set_external_torque(plain_context, external)
    np.testing.assert_allclose(
        plain.EvalTimeDerivatives(plain_context).CopyToVector(),
        actuation + gravity + external,
        rtol=1e-12,
        atol=1e-12,
    )
    # p_I itself: M v - r / K_o (equal to the bit as well).
    momentum = plant.CalcMassMatrix(plant_context) @ state[3:]
    np.testing.assert_allclose(
        context.get_continuous_state_vector().CopyToVector(),
        momentum - external / 50.0,
        rtol=1e-12,
    )


def test_the_gain_is_checked_keyword_only_and_defaults_to_100_per_second(arm_plant):
    assert ContactForceObserver(arm_plant, contact=TIP).gain == 100.0
    assert ContactForceObserver(arm_plant, contact=TIP, gain=0.5).gain == 0.5
    for gain in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError, match="gain must be > 0"):
            ContactForceObserver(arm_plant, contact=TIP, gain=gain)
    with pytest.raises(TypeError):
        ContactForceObserver(arm_plant, TIP, 100.0)


# --- the full momentum dynamics: C(q, v)^T v ------------------------------------------


def _kinetic_energy_gradient(ad_plant, ad_context, state) -> np.ndarray:
    """dT/dq at fixed v, T = v^T M(q) v / 2, by AutoDiffXd through the plant's own kinetic
    energy: the Lagrangian's term of p' (for q' = v), derived apart from the observer's
    dM/dt v - C v."""
    nq = ad_plant.num_positions()
    ad_plant.SetPositions(ad_context, InitializeAutoDiff(state[:nq]).ravel())
    ad_plant.SetVelocities(ad_context, np.array([AutoDiffXd(x, np.zeros(nq)) for x in state[nq:]]))
    return ad_plant.CalcKineticEnergy(ad_context).derivatives()


def _falling_arm(plant, coriolis: bool, duration: float):
    """The arm falling freely (no torque, no contact) from joint speeds of about 1 rad/s,
    with the observer started at r = 0: (times, states, F_hat, r) logged every 2 ms."""
    builder = DiagramBuilder()
    arm, _ = AddPlanarArm(builder, PLANAR_ARM_URDF)
    arm.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])  # coasting
    observer = builder.AddSystem(ContactForceObserver(arm, contact=TIP, coriolis=coriolis))
    torque = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    builder.Connect(arm.get_state_output_port(), observer.estimated_state_input)
    builder.Connect(torque.get_output_port(), observer.actuation_input)
    builder.Connect(torque.get_output_port(), arm.get_actuation_input_port())
    logs = [
        LogVectorOutput(port, builder, 0.002)
        for port in (
            arm.get_state_output_port(),
            observer.contact_force_output,
            observer.external_torque_output,
        )
    ]
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.get_mutable_integrator().set_target_accuracy(1e-9)
    context = simulator.get_mutable_context()
    arm_context = arm.GetMyMutableContextFromRoot(context)
    q0 = SolvePlanarInverseKinematics(
        arm, "fingertip", POSE, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    arm.SetPositions(arm_context, q0)
    arm.SetVelocities(arm_context, [1.0, -1.0, 1.0])
    observer.set_external_torque(observer.GetMyMutableContextFromRoot(context), np.zeros(3))
    simulator.AdvanceTo(duration)
    data = [log.FindLog(context) for log in logs]
    return data[0].sample_times(), *(d.data().T for d in data)


def test_the_full_observer_reads_no_force_on_an_arm_moving_freely_at_1_rad_per_s():
    """Falling freely at about 1 rad/s (no contact): the observer without C^T v shows a
    spurious torque r that follows dT/dq through its lag, dr/dt = K_o (dT/dq - r), dT/dq
    the plant's kinetic energy differentiated by AutoDiffXd along the logged states; the
    full observer's r stays near zero."""
    plant, _ = AddPlanarArm(DiagramBuilder(), PLANAR_ARM_URDF)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    ad_plant = plant.ToAutoDiffXd()
    ad_context = ad_plant.CreateDefaultContext()
    duration = 0.3
    times, states, old_force, old_torque = _falling_arm(plant, False, duration)
    _, _, new_force, new_torque = _falling_arm(plant, True, duration)
    assert np.max(np.abs(states[:, 3:])) > 0.9  # joint speeds of about 1 rad/s
    gradient = np.array([_kinetic_energy_gradient(ad_plant, ad_context, s) for s in states])
    # r of the observer without the term: the first-order lag of dT/dq (K_o = 100 1/s),
    # integrated exactly over each 2 ms sample with dT/dq linear between samples.
    expected = np.zeros_like(gradient)
    for k in range(1, len(times)):
        h = times[k] - times[k - 1]
        decay = math.exp(-100.0 * h)
        slope = (gradient[k] - gradient[k - 1]) / h
        expected[k] = (
            decay * expected[k - 1]
            + (1 - decay) * gradient[k]
            + slope * (decay * h - (1 - decay) / 100.0)
        )
    # Measured: |dT/dq| lagged up to 5.44e-3 N m at joint speeds up to 1.34 rad/s.
    size = np.max(np.abs(expected))
    assert size > 4e-3
    # The observer without the term is that lag: 2.4e-8 N m apart (the integrator's
    # accuracy and the lag's linear interpolation); 1e-6 N m is 40 times that.
    np.testing.assert_allclose(old_torque, expected, rtol=0, atol=1e-6)
    # Its spurious force along the wall normal, -(J^-T r)_x, with r from the lag model:
    # up to 21 mN here (measured), 1e-6 N apart (5e-8 measured).
    kinematics = PlanarFrameKinematics(plant, "fingertip", coordinates=PLANAR_COORDINATES)
    spurious = []
    for state, torque in zip(states, expected, strict=True):
        kinematics.set_state(state)
        wrench = np.linalg.solve(kinematics.jacobian().T, torque)
        spurious.append(-wrench[0])
    np.testing.assert_allclose(old_force[:, 0], spurious, rtol=0, atol=1e-6)
    assert np.max(np.abs(spurious)) > 0.015
    # The full observer: r 2.4e-8 N m and F_hat 1.2e-7 N at most (measured), the
    # integrator's error; 1e-6 leaves 8 to 40 times that and is 2e-4 of the lag's size.
    assert np.max(np.abs(new_torque)) < 1e-6
    assert np.max(np.abs(new_force)) < 1e-6


@pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason='example-robot-data is not installed: pip install "optimal-admittance[robots]"',
)
def test_on_the_panda_the_observer_reads_the_force_along_the_control_frame_z():
    """The Panda at its press's start, every joint at 1 rad/s, the observer on the spatial
    task (x, y, z, rx, ry, rz of the tool tip in the control frame, the normal z): r set to
    J^T (-F e_z) reads F, and dp_I/dt carries dT/dq (AutoDiffXd of the kinetic energy). The
    observer without the term would settle at r = dT/dq: its force is printed (-s) and
    kept below the detector's allowance (docs/evidence/safety.md)."""
    loop = BuildSpatialLoop(load_scenario("panda_surface_press"))
    plant = loop.plant
    nv = plant.num_velocities()
    state = np.concatenate([loop.initial_positions, np.ones(nv)])
    task = dict(coordinates=SPATIAL_COORDINATES, expressed_in=CONTROL_FRAME)
    tool = ContactFrame(frame_name=TOOL_TIP_FRAME, normal_axis=2, **task)
    observer = ContactForceObserver(plant, contact=tool)
    context = observer.CreateDefaultContext()
    observer.estimated_state_input.FixValue(context, state)
    observer.actuation_input.FixValue(context, np.zeros(plant.num_actuated_dofs()))
    kinematics = SpatialFrameKinematics(plant, TOOL_TIP_FRAME, **task)
    kinematics.set_state(state)
    jacobian = kinematics.jacobian()
    wrench = np.array([1.0, -2.0, 10.0, 0.1, 0.0, -0.05])  # 10 N into the table, and more
    observer.set_external_torque(context, jacobian.T @ -wrench)
    # J^T has full column rank (7 joints, 6 coordinates): the least-squares solve is exact
    # to rounding (measured 0 N); 1e-9 N for the condition of J.
    assert observer.contact_force_output.Eval(context)[0] == pytest.approx(10.0, abs=1e-9)
    observer.set_external_torque(context, np.zeros(nv))
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, state)
    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    ad_plant = plant.ToAutoDiffXd()
    coriolis = _kinetic_energy_gradient(ad_plant, ad_plant.CreateDefaultContext(), state)
    rate = observer.EvalTimeDerivatives(context).CopyToVector()
    # Measured 2e-10 N m apart (the central difference); 1e-8 N m is 5e-9 of the term.
    np.testing.assert_allclose(rate, gravity + coriolis, rtol=0, atol=1e-8)
    spurious = -np.linalg.lstsq(jacobian.T, coriolis, rcond=None)[0][2]
    print(
        f"Panda at 1 rad/s: |dT/dq| {np.max(np.abs(coriolis)):.3g} N m, the observer "
        f"without it reads {spurious:+.3g} N along z"
    )
    assert abs(spurious) < 2.3


def test_the_sampled_observer_steps_r_toward_the_external_torque_by_euler(arm_plant):
    """With a period h the observer steps p_I by Euler once per tick. On the arm at rest
    (p = M v = 0) under constant torques tau, the torque that holds it still is
    tau_ext = -(tau + tau_g), and by hand r[k+1] = r[k] + K_o h (tau_ext - r[k]), so from
    r[0] = 0: r[n] = tau_ext (1 - (1 - K_o h)^n). Measured to rounding (1e-15 N m); 1e-12."""
    plant = arm_plant
    h, gain = 1e-3, 100.0
    q = SolvePlanarInverseKinematics(
        plant, "fingertip", POSE, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    state = np.concatenate([q, np.zeros(3)])
    torque = np.array([0.4, -0.2, 0.05])
    observer = ContactForceObserver(plant, contact=TIP, gain=gain, period=h)
    context = observer.CreateDefaultContext()
    observer.estimated_state_input.FixValue(context, state)
    observer.actuation_input.FixValue(context, torque)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, state)
    holding = -(torque + plant.CalcGravityGeneralizedForces(plant_context))
    simulator = Simulator(observer, context)
    for n in (1, 10, 100):
        # Ticks at 0, h, ..., (n - 1) h have run once the clock passes (n - 1) h.
        simulator.AdvanceTo((n - 0.5) * h)
        expected = holding * (1.0 - (1.0 - gain * h) ** n)
        residual = observer.external_torque_output.Eval(context)
        assert np.allclose(residual, expected, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="period"):
        ContactForceObserver(plant, contact=TIP, gain=gain, period=0.03)  # K_o h = 3 > 2: unstable
