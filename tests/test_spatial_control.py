"""The spatial task space and the 6-D Cartesian PID, on the Franka Panda's published URDF.

The expected values come from Drake's own poses and rotations (RigidTransform,
RotationMatrix, AngleAxis) and finite differences, never from the code under test.
"""

from __future__ import annotations

import math
import site
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cmeel", reason="the Panda's URDF comes from example-robot-data")

from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff  # noqa: E402
from pydrake.common.eigen_geometry import AngleAxis  # noqa: E402
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix  # noqa: E402
from pydrake.multibody.parsing import Parser  # noqa: E402
from pydrake.multibody.plant import MultibodyPlant  # noqa: E402
from pydrake.multibody.tree import (  # noqa: E402
    FixedOffsetFrame,
    JacobianWrtVariable,
    MultibodyForces,
)
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
from pydrake.systems.primitives import ConstantVectorSource  # noqa: E402

from admittance.diagrams.loop.point import AddPointKinematics, AddPointPid  # noqa: E402
from admittance.diagrams.robots.description import ForcePoint  # noqa: E402
from admittance.systems.cartesian_pid import CartesianPid, PostureTask  # noqa: E402
from admittance.systems.optimal_admittance import OptimalAdmittance  # noqa: E402
from admittance.systems.spatial_kinematics import (  # noqa: E402
    SPATIAL_COORDINATES,
    SpatialKinematics,
    orientation_error,
    rotation_vector,
)

TOOL = "panda_hand_tcp"
# The Panda's rated joint torques (Franka's datasheet), N m; the fingers' motors, N.
EFFORT_LIMITS = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0, 100.0, 100.0]
# A ready pose: elbow up, the hand pointing down (R_WF 180 degrees about x).
READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.02, 0.02])
# 6-D gains: N/m, N s/m, N/(m s) on x, y, z; N m/rad, N m s/rad, N m/(rad s) on rx, ry, rz.
# kd_i = 2 zeta sqrt(kp_i Lambda_ii), zeta = 0.8, with the tool's apparent inertia
# Lambda = (J M^-1 J^T)^-1 at READY: diagonal (11.0, 4.3, 5.1) kg, (0.16, 0.51, 0.007)
# kg m^2 (rz is the last joint alone). Ki: an integral time Kp / Ki of 0.5 s.
KP = [2000.0] * 3 + [100.0] * 3
KD = [240.0, 150.0, 160.0, 6.5, 11.0, 1.4]
KI = [4000.0] * 3 + [200.0] * 3
# The null-space posture: about 3 rad/s on the elbow's self-motion.
POSTURE_KP, POSTURE_KD = 10.0, 4.0


def _description_folder(package: str = "panda_description") -> Path:
    for base in map(Path, site.getsitepackages()):
        folder = base / "cmeel.prefix/share/example-robot-data/robots" / package
        if folder.is_dir():
            return folder
    pytest.skip(f"example-robot-data's {package} is not installed")


def panda(time_step: float = 1e-3, *, surface: RigidTransform | None = None) -> MultibodyPlant:
    """The Panda welded at its base, a motor on each joint, optionally a frame 'surface'."""
    folder = _description_folder()
    plant = MultibodyPlant(time_step)
    parser = Parser(plant)
    parser.package_map().Add("panda_description", str(folder))
    parser.AddModels(str(folder / "urdf/panda.urdf"))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    single = [j for j in joints if j.num_velocities() == 1]
    for joint, limit in zip(single, EFFORT_LIMITS, strict=True):
        plant.AddJointActuator(f"{joint.name()}_motor", joint, limit)
    if surface is not None:
        plant.AddFrame(FixedOffsetFrame("surface", plant.world_frame(), surface))
    plant.Finalize()
    return plant


def _pose(plant, q, frame=TOOL, expressed_in="world") -> RigidTransform:
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    return plant.CalcRelativeTransform(
        context, plant.GetFrameByName(expressed_in), plant.GetFrameByName(frame)
    )


def _drake_rotation_vector(rotation: RotationMatrix) -> np.ndarray:
    angle_axis = rotation.ToAngleAxis()
    return angle_axis.angle() * angle_axis.axis()


def _kinematics(system, state) -> np.ndarray:
    context = system.CreateDefaultContext()
    system.estimated_state_input.FixValue(context, state)
    return system.kinematics_output.Eval(context)


# --- the rotation vector and the orientation error ----------------------------------------


@pytest.mark.parametrize(
    "angle, axis",
    [
        (math.pi / 2, [0.0, 0.0, 1.0]),
        (math.pi / 2, [1.0, 2.0, 3.0]),
        (0.3, [0.0, 1.0, 0.0]),
        (3.0, [-1.0, 0.5, 0.2]),
        (1e-9, [1.0, 1.0, 0.0]),
    ],
)
def test_rotation_vector_of_a_known_rotation(angle, axis):
    axis = np.array(axis) / np.linalg.norm(axis)
    matrix = RotationMatrix(AngleAxis(angle, axis)).matrix()
    np.testing.assert_allclose(rotation_vector(matrix), angle * axis, atol=1e-12)


@pytest.mark.parametrize("angle", [0.01, 0.5, math.pi / 2, 3.0])
@pytest.mark.parametrize("axis", [[0.0, 0.0, 1.0], [1.0, -2.0, 0.5]])
def test_orientation_error_is_the_relative_rotation_at_90_degrees_of_pitch(angle, axis):
    """R at 90 degrees of pitch, where ZYX Euler angles lose a degree of freedom; R_d is R
    turned by `angle` about `axis` in E: e_R = angle * axis, whichever the vectors' branch."""
    axis = np.array(axis) / np.linalg.norm(axis)
    rotation = RollPitchYaw(0.4, math.pi / 2, -0.7).ToRotationMatrix()
    desired = RotationMatrix(AngleAxis(angle, axis)) @ rotation
    error = orientation_error(_drake_rotation_vector(desired), _drake_rotation_vector(rotation))
    np.testing.assert_allclose(error, angle * axis, atol=1e-9)


def test_orientation_error_derivative_at_zero_error_is_exact():
    """At zero error (R_d R^T = I, where |v| = 0 has no derivative through a square root)
    the AutoDiffXd gradient of e_R, the linearized loop's error gain, equals the finite
    differences of e_R."""
    commanded = _drake_rotation_vector(RollPitchYaw(0.2, -0.3, 1.0).ToRotationMatrix())
    measured = InitializeAutoDiff(commanded)[:, 0]
    error = orientation_error(commanded.tolist(), list(measured))
    assert all(abs(e.value()) < 1e-12 for e in error)
    gradient = ExtractGradient(np.array(error))
    assert np.linalg.matrix_rank(gradient) == 3
    step = 1e-6
    for j in range(3):
        shifted = commanded.copy()
        shifted[j] += step
        finite = np.array(orientation_error(commanded.tolist(), shifted.tolist())) / step
        np.testing.assert_allclose(gradient[:, j], finite, atol=1e-5)


# --- the kinematics -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def panda_with_surface():
    surface = RigidTransform(RollPitchYaw(0.1, -0.2, 0.5), [0.5, 0.1, 0.2])
    return panda(surface=surface)


@pytest.mark.parametrize("expressed_in", ["world", "surface"])
def test_pose_and_jacobian_against_drake_poses_and_finite_differences(
    panda_with_surface, expressed_in
):
    plant = panda_with_surface
    system = SpatialKinematics(
        plant, frame_name=TOOL, coordinates=SPATIAL_COORDINATES, expressed_in=expressed_in
    )
    rng = np.random.default_rng(7)
    q = READY + np.r_[rng.uniform(-0.4, 0.4, 7), 0.0, 0.0]
    v = rng.uniform(-1.0, 1.0, 9)
    values = _kinematics(system, np.r_[q, v])
    X, rate, J = values[:6], values[6:12], values[12:].reshape(6, 9)
    X_EF = _pose(plant, q, expressed_in=expressed_in)
    np.testing.assert_allclose(X[:3], X_EF.translation(), atol=1e-12)
    np.testing.assert_allclose(X[3:], _drake_rotation_vector(X_EF.rotation()), atol=1e-9)
    step = 1e-6
    for j in range(9):  # q and v are one for these joints: dq/dt = v
        plus, minus = q.copy(), q.copy()
        plus[j] += step
        minus[j] -= step
        X_plus = _pose(plant, plus, expressed_in=expressed_in)
        X_minus = _pose(plant, minus, expressed_in=expressed_in)
        linear = (X_plus.translation() - X_minus.translation()) / (2 * step)
        turn = X_plus.rotation() @ X_minus.rotation().inverse()  # rotation in E over 2 step
        angular = _drake_rotation_vector(turn) / (2 * step)
        np.testing.assert_allclose(J[:3, j], linear, atol=1e-6)
        np.testing.assert_allclose(J[3:, j], angular, atol=1e-6)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    frame_E = plant.GetFrameByName(expressed_in)
    J_angular = plant.CalcJacobianAngularVelocity(
        context, JacobianWrtVariable.kV, plant.GetFrameByName(TOOL), frame_E, frame_E
    )
    np.testing.assert_allclose(J[3:], J_angular, atol=1e-12)
    np.testing.assert_allclose(rate, J @ v, atol=1e-12)


def test_autodiff_kinematics_match_the_double_ones(panda_with_surface):
    system = SpatialKinematics(panda_with_surface, frame_name=TOOL, coordinates=SPATIAL_COORDINATES)
    state = np.r_[READY, np.linspace(-0.5, 0.5, 9)]
    autodiff = system.ToAutoDiffXd()
    context = autodiff.CreateDefaultContext()
    autodiff.get_input_port(0).FixValue(context, InitializeAutoDiff(state)[:, 0])
    values = autodiff.get_output_port(0).Eval(context)
    assert isinstance(values[0], AutoDiffXd)
    np.testing.assert_allclose([x.value() for x in values], _kinematics(system, state), atol=1e-12)


def test_a_subset_of_rotation_coordinates_or_theta_with_them_is_refused(panda_with_surface):
    for coordinates in [("x", "rx"), ("x", "y", "z", "rx", "ry", "rz", "theta")]:
        with pytest.raises(ValueError, match="rotation vector needs all of"):
            SpatialKinematics(panda_with_surface, frame_name=TOOL, coordinates=coordinates)


# --- the 6-D PID in closed loop ---------------------------------------------------------------


def _hold_loop(
    plant,
    commanded,
    *,
    gravity_compensation=True,
    posture=None,
    kp=KP,
    kd=KD,
    ki=KI,
    frame=TOOL,
):
    """The arm (free space, gravity) under the 6-D PID wired by loop.point, holding the
    pose `commanded` of `frame` (X in world). Returns (diagram, kinematics, pid)."""
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    point = ForcePoint(
        name="",
        frame=frame,
        coordinates=SPATIAL_COORDINATES,
        force_axes=(2,),
        kp=list(kp),
        kd=list(kd),
        ki=list(ki),
        gravity_compensation=gravity_compensation,
        posture=posture,
    )
    kinematics = AddPointKinematics(builder, plant, point)
    rate = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    pid = AddPointPid(builder, plant, point, kinematics, rate.get_output_port())
    position = builder.AddSystem(ConstantVectorSource(np.asarray(commanded, dtype=float)))
    builder.Connect(position.get_output_port(), pid.commanded_position_input)
    builder.Connect(pid.actuation_output, plant.get_actuation_input_port())
    return builder.Build(), kinematics, pid


def _run(diagram, plant, q_start, duration, *, record=None):
    """Simulates from rest at `q_start`; `record(context)` is called every 10 ms."""
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), q_start)
    simulator.Initialize()
    steps = round(duration / 0.01)
    for step in range(1, steps + 1):
        simulator.AdvanceTo(step * 0.01)
        if record is not None:
            record(context)
    return context


def _step_target(plant, q, frame=TOOL) -> RigidTransform:
    """The pose of `frame` at q moved 5 cm along world x and turned 10 degrees about z."""
    start = _pose(plant, q, frame)
    return RigidTransform(
        RotationMatrix.MakeZRotation(math.radians(10.0)) @ start.rotation(),
        start.translation() + [0.05, 0.0, 0.0],
    )


def _errors(pid, context):
    """(position error m, orientation error rad) of the PID at the context."""
    error = pid.cartesian_error(pid.GetMyContextFromRoot(context))
    return float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:]))


def _worst_errors(pid):
    """([worst position error, worst orientation error], a `record` for ``_run``)."""
    worst = [0.0, 0.0]

    def record(context):
        for k, error in enumerate(_errors(pid, context)):
            worst[k] = max(worst[k], error)

    return worst, record


def _tool_pose(plant, context) -> RigidTransform:
    plant_context = plant.GetMyContextFromRoot(context)
    return plant.CalcRelativeTransform(
        plant_context, plant.world_frame(), plant.GetFrameByName(TOOL)
    )


def _pose_vector(X_WF: RigidTransform) -> np.ndarray:
    return np.r_[X_WF.translation(), _drake_rotation_vector(X_WF.rotation())]


def test_the_pid_with_gravity_compensation_holds_the_pose_it_starts_at():
    """Released at rest at the commanded pose: with g(q) compensated nothing pulls the
    tool away (the steady error is zero, and Ki has nothing to carry): the error stays
    under 1 mm and 0.5 degree throughout 1 s (measured 2026-12-02: zero to rounding, the
    gravity torque cancelled exactly at rest). Without the compensation it sags by centimetres first
    (``test_without_gravity_compensation_the_tool_sags_by_the_weight_over_the_stiffness``)."""
    plant = panda()
    start = _pose(plant, READY)
    posture = PostureTask(READY, POSTURE_KP, POSTURE_KD)
    diagram, _, pid = _hold_loop(plant, _pose_vector(start), posture=posture)
    worst, record = _worst_errors(pid)
    _run(diagram, plant, READY, 1.0, record=record)
    assert worst[0] < 1e-3 and math.degrees(worst[1]) < 0.5, worst


def test_the_pid_with_gravity_compensation_tracks_a_step_in_six_dimensions():
    """A step of 5 cm along x and 10 degrees about world z, from rest at the ready pose
    (the hand pointing down: R_WF is 180 degrees about x, the rotation vector at |r| = pi,
    where a difference of rotation vectors would jump by 2 pi). With g(q) compensated,
    the PD alone has zero steady error in free space; after 1 s: < 1 mm and < 0.5 degree
    (measured 2026-12-02: 0.03 mm, 0.004 degree)."""
    plant = panda()
    target = _step_target(plant, READY)
    posture = PostureTask(READY, POSTURE_KP, POSTURE_KD)
    diagram, _, pid = _hold_loop(plant, _pose_vector(target), posture=posture, ki=[0.0] * 6)
    context = _run(diagram, plant, READY, 1.0)
    reached = _tool_pose(plant, context)
    position = np.linalg.norm(reached.translation() - target.translation())
    angle = target.rotation().inverse().multiply(reached.rotation()).ToAngleAxis().angle()
    assert position < 1e-3 and math.degrees(angle) < 0.5, (position, math.degrees(angle))
    # The PID's own error agrees with Drake's pose of the tool.
    assert _errors(pid, context) == pytest.approx((position, angle), abs=1e-6)


def test_the_same_pid_tracks_the_step_on_the_ur5():
    """Any arm: the UR5's published URDF (6 joints, not redundant: J is square and the
    posture's null space is empty), its actuators and effort limits from the URDF's
    transmissions, the tool frame tool0, kd from its own apparent inertia (zeta = 0.8).
    The same step as the Panda's, after 1 s: < 1 mm and < 0.5 degree (measured
    2026-12-02: 0.001 mm, 0.001 degree)."""
    folder = _description_folder("ur_description")
    plant = MultibodyPlant(1e-3)
    parser = Parser(plant)
    parser.package_map().Add("ur_description", str(folder))
    parser.AddModels(str(folder / "urdf/ur5_robot.urdf"))  # its link "world" welds the base
    plant.Finalize()
    q = np.array([0.0, -1.2, 1.5, -1.9, -math.pi / 2, 0.0])
    _, _, _, inertia = _apparent_inertia(plant, q, "tool0")
    damping = 2.0 * 0.8 * np.sqrt(np.array(KP) * np.diag(inertia))
    target = _step_target(plant, q, "tool0")
    posture = PostureTask(q, POSTURE_KP, POSTURE_KD)
    diagram, _, pid = _hold_loop(
        plant, _pose_vector(target), posture=posture, kd=damping, ki=[0.0] * 6, frame="tool0"
    )
    context = _run(diagram, plant, q, 1.0)
    position, angle = _errors(pid, context)
    assert position < 1e-3 and math.degrees(angle) < 0.5, (position, math.degrees(angle))


def _apparent_inertia(plant, q, frame=TOOL):
    """(M, J (6 x nv, rows x, y, z, wx, wy, wz in world), Lambda) at q, from the plant."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    mass = plant.CalcMassMatrix(context)
    spatial = plant.CalcJacobianSpatialVelocity(
        context,
        JacobianWrtVariable.kV,
        plant.GetFrameByName(frame),
        np.zeros(3),
        plant.world_frame(),
        plant.world_frame(),
    )
    jacobian = np.r_[spatial[3:], spatial[:3]]
    inertia = np.linalg.inv(jacobian @ np.linalg.solve(mass, jacobian.T))
    return context, mass, jacobian, inertia


def test_without_gravity_compensation_the_tool_sags_by_the_weight_over_the_stiffness():
    """No g(q), no Ki, the posture on. At rest, 0 = J^T Kp ec + N^T tau0 + tau_g; with
    Jbar^T = Lambda J M^-1 (Jbar^T J^T = I, Jbar^T N^T = 0): Kp ec = -Jbar^T tau_g, so the
    tool settles at X - Xc = Kp^-1 Jbar^T tau_g(READY), to first order in the sag. Stiff
    gains (4x) keep the sag small enough for that: measured 2026-12-02, z -7.26 mm for
    -7.23 estimated, x -4.02 for -3.76, ry -0.0244 rad for -0.0229; within 10 %."""
    plant = panda()
    stiff = np.array([8000.0] * 3 + [400.0] * 3)
    damping = 2.0 * np.array(KD)  # kd scales with sqrt(kp)
    context, mass, jacobian, inertia = _apparent_inertia(plant, READY)
    tau_g = plant.CalcGravityGeneralizedForces(context)
    expected = inertia @ jacobian @ np.linalg.solve(mass, tau_g) / stiff
    posture = PostureTask(READY, POSTURE_KP, POSTURE_KD)
    diagram, _, pid = _hold_loop(
        plant,
        _pose_vector(_pose(plant, READY)),
        gravity_compensation=False,
        posture=posture,
        kp=stiff,
        kd=damping,
        ki=[0.0] * 6,
    )
    loop = _run(diagram, plant, READY, 1.0)
    sag = -pid.cartesian_error(pid.GetMyContextFromRoot(loop))
    assert abs(expected[2]) > 5e-3  # the weight acts: z sags by millimetres
    for axis in (0, 2, 4):  # x, z and ry: the components the weight loads
        assert sag[axis] == pytest.approx(expected[axis], rel=0.10), (axis, sag, expected)


def _self_motion(plant, q, distance, step=0.01):
    """A posture with the tool's pose of `q`, `distance` rad along the arm's self-motion
    (the null space of the 6 x 7 arm Jacobian, walked in steps, each corrected back onto
    the pose by Newton steps on Drake's pose)."""
    target = _pose(plant, q)
    q = q.copy()
    direction = None
    for _ in range(round(distance / step)):
        _, _, jacobian, _ = _apparent_inertia(plant, q)
        null = np.linalg.svd(jacobian[:, :7])[2][-1]
        if direction is not None and null @ direction < 0:
            null = -null
        direction = null
        q[:7] += step * null
        for _ in range(3):
            here = _pose(plant, q)
            twist = np.r_[
                target.translation() - here.translation(),
                _drake_rotation_vector(target.rotation() @ here.rotation().inverse()),
            ]
            _, _, jacobian, _ = _apparent_inertia(plant, q)
            q[:7] += np.linalg.pinv(jacobian[:, :7]) @ twist
    return q


def test_the_posture_moves_the_elbow_to_q0_without_moving_the_tool():
    """The Panda is redundant (7 joints, a 6-D task): the posture task, projected through
    the dynamically consistent null space, brings the joints from READY to a posture q0
    0.4 rad along the self-motion of the same tool pose, while the tool stays within
    0.1 mm and 0.05 degree. Measured 2026-12-02: 0.4 % of the distance left after 2 s;
    the tool within 0.044 mm and 0.010 degree (the posture unprojected, tau0 added as it
    is: 0.46 mm and 0.30 degree, the PID's stiffness alone holding the tool)."""
    plant = panda()
    q0 = _self_motion(plant, READY, 0.4)
    start = _pose(plant, READY)
    assert np.linalg.norm(_pose(plant, q0).translation() - start.translation()) < 1e-9
    posture = PostureTask(q0, POSTURE_KP, POSTURE_KD)
    diagram, _, pid = _hold_loop(plant, _pose_vector(start), posture=posture)
    worst, record = _worst_errors(pid)
    context = _run(diagram, plant, READY, 2.0, record=record)
    q = plant.GetPositions(plant.GetMyContextFromRoot(context))
    remaining = np.linalg.norm(q - q0) / np.linalg.norm(READY - q0)
    assert remaining < 0.05, remaining
    assert worst[0] < 1e-4 and math.degrees(worst[1]) < 0.05, worst


# --- the paper's law on a subset of the six axes ----------------------------------------------


@pytest.mark.parametrize("axes", [(2,), (2, 3, 4)])
def test_the_admittance_law_runs_on_any_subset_of_six_axes(axes):
    """Eq. 10 (alpha = 0) on a constant force error E: dXr_i/dt = Gamma K_i E_i on each
    force axis i (K_i the PID's Kp there: N/m on z, N m/rad on rx, ry), Xr = 0 on the
    others. After 0.1 s: Xr_i = Gamma K_i E_i 0.1, by hand."""
    point = ForcePoint(name="", frame=TOOL, coordinates=SPATIAL_COORDINATES, force_axes=axes)
    point.kp = list(KP)
    block = OptimalAdmittance(
        gamma=1e-5,
        alpha=0.0,
        stiffness=point.force_axis_stiffness,
        force_axes=list(axes),
        num_axes=6,
        max_push=1.0,
        max_retract=1.0,
    )
    errors = np.array([10.0, -2.0, 3.0][: len(axes)])  # N on z, N m on the tilts
    simulator = Simulator(block)
    context = simulator.get_mutable_context()
    block.measured_force_input.FixValue(context, np.zeros(len(axes)))
    block.desired_force_input.FixValue(context, errors)
    block.set_initial_force_error(context, errors)
    simulator.AdvanceTo(0.1)
    expected = np.zeros(6)
    expected[list(axes)] = 1e-5 * np.array([KP[a] for a in axes]) * errors * 0.1
    offset = block.reference_offset_output.Eval(context)
    np.testing.assert_allclose(offset, expected, rtol=1e-9, atol=1e-15)


# --- the PID's joint-space terms, at one state ----------------------------------------------


def _pid_torque(pid, plant, q, *, converted=False):
    """The PID's torque at rest at q, commanded to where the tool is (zero error)."""
    state = np.r_[q, np.zeros(plant.num_velocities())]
    tool = SpatialKinematics(plant, frame_name=TOOL, coordinates=SPATIAL_COORDINATES)
    kinematics = _kinematics(tool, state)
    system = pid.ToAutoDiffXd() if converted else pid
    context = system.CreateDefaultContext()
    system.GetInputPort("kinematics").FixValue(context, kinematics)
    system.GetInputPort("state").FixValue(
        context, InitializeAutoDiff(state)[:, 0] if converted else state
    )
    system.GetInputPort("commanded_position").FixValue(context, kinematics[:6])
    system.GetInputPort("commanded_velocity").FixValue(context, np.zeros(6))
    torque = system.GetOutputPort("actuation").Eval(context)
    return np.array([t.value() for t in torque]) if converted else torque


def test_the_state_input_exists_only_with_gravity_compensation_or_a_posture(
    panda_with_surface,
):
    arguments = dict(frame_name=TOOL, coordinates=SPATIAL_COORDINATES, kp=KP, kd=KD, ki=KI)
    assert CartesianPid(panda_with_surface, **arguments).state_input is None
    for extra in [dict(gravity_compensation=True), dict(posture=PostureTask(READY))]:
        pid = CartesianPid(panda_with_surface, **arguments, **extra)
        assert pid.state_input.size() == 18


def test_at_zero_error_the_torque_is_the_static_holding_torque_plus_a_null_space_posture(
    panda_with_surface,
):
    """At rest with zero error, F_PID = 0: tau = g(q) + N^T tau0. g(q) is checked against
    Drake's inverse dynamics at rest, zero acceleration, under the plant's force elements
    (gravity), and N^T tau0
    against the definition of dynamic consistency: it accelerates no task coordinate,
    J M^-1 N^T tau0 = 0, while tau0 itself would; up to the damping's leak, at most a
    fraction eps / lambda_min(J M^-1 J^T) of tau0's (measured 2026-12-02: 1.0e-6, under
    that bound of 3.9e-4)."""
    plant = panda_with_surface
    q = READY + np.r_[0.1, -0.2, 0.3, 0.1, -0.2, 0.1, 0.2, 0.0, 0.0]
    arguments = dict(frame_name=TOOL, coordinates=SPATIAL_COORDINATES, kp=KP, kd=KD, ki=KI)
    gravity_only = CartesianPid(plant, **arguments, gravity_compensation=True)
    context, mass, jacobian, _ = _apparent_inertia(plant, q)
    weight = MultibodyForces(plant)
    plant.CalcForceElementsContribution(context, weight)  # gravity, a force element
    holding = plant.CalcInverseDynamics(context, np.zeros(plant.num_velocities()), weight)
    np.testing.assert_allclose(_pid_torque(gravity_only, plant, q), holding, atol=1e-9)
    posture = PostureTask(READY, kp=10.0, kd=4.0)
    pid = CartesianPid(plant, **arguments, gravity_compensation=True, posture=posture)
    null_space = _pid_torque(pid, plant, q) - holding
    rest = 10.0 * (READY - q)
    task_acceleration = jacobian @ np.linalg.solve(mass, null_space)
    unprojected = np.linalg.norm(jacobian @ np.linalg.solve(mass, rest))
    # The damping eps = 1e-6 mean diag(A), A = J M^-1 J^T, leaks eps / lambda_min(A) of it.
    inverse_inertia = jacobian @ np.linalg.solve(mass, jacobian.T)
    leak = 1e-6 * np.trace(inverse_inertia) / 6 / np.linalg.eigvalsh(inverse_inertia)[0]
    assert leak < 1e-3
    ratio = np.linalg.norm(task_acceleration) / unprojected
    assert ratio < leak, (ratio, leak)
    assert np.linalg.norm(null_space) > 0.1  # and it is there
    # Converted to AutoDiffXd (Linearize): the same torque.
    converted = _pid_torque(pid, plant, q, converted=True)
    np.testing.assert_allclose(converted, _pid_torque(pid, plant, q), atol=1e-9)
    # Sampled (1 ms): the torque latched at a sample is the same law's.
    sampled = CartesianPid(plant, **arguments, period=1e-3, gravity_compensation=True)
    context = sampled.CreateDefaultContext()
    state = np.r_[q, np.zeros(plant.num_velocities())]
    tool = SpatialKinematics(plant, frame_name=TOOL, coordinates=SPATIAL_COORDINATES)
    kinematics = _kinematics(tool, state)
    sampled.kinematics_input.FixValue(context, kinematics)
    sampled.state_input.FixValue(context, state)
    sampled.commanded_position_input.FixValue(context, kinematics[:6])
    sampled.commanded_velocity_input.FixValue(context, np.zeros(6))
    held = sampled.EvalUniquePeriodicDiscreteUpdate(context).get_vector(1).CopyToVector()
    np.testing.assert_allclose(held, holding, atol=1e-9)
