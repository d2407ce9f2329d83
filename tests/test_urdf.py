"""Tests of the planar arm model (urdf/planar_arm.urdf) against the paper and its derivation."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from pydrake.geometry import Role, SceneGraph, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, RevoluteJoint
from pydrake.systems.framework import Context, DiagramBuilder

URDF_DIR = Path(__file__).resolve().parents[1] / "urdf"
URDF_PATH = URDF_DIR / "planar_arm.urdf"
JOINTS = ("joint1", "joint2", "joint3")
LINKS = ("link1", "link2", "link3")
GRAVITY_VECTOR = np.array([0.0, -9.81, 0.0])
# The project's default (docs/evidence/paper-notes.md, section 6).
LINK_LENGTHS = (0.20, 0.20, 0.10)
TASK_X = (0.14, 0.21)
TASK_Y = (-0.275, -0.225)
TASK_THETA = math.pi / 2
SENSOR_FULL_SCALE = 100.0  # N


def _load_derivation() -> ModuleType:
    """Imports urdf/derive_parameters.py by path (urdf/ is not a package)."""
    spec = importlib.util.spec_from_file_location(
        "derive_parameters", URDF_DIR / "derive_parameters.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


derive = _load_derivation()


@pytest.fixture(scope="module")
def plant() -> MultibodyPlant:
    """The arm in a continuous-time plant with gravity along -y, as the project loads it."""
    arm = MultibodyPlant(time_step=0.0)
    Parser(arm).AddModels(str(URDF_PATH))
    arm.mutable_gravity_field().set_gravity_vector(GRAVITY_VECTOR)
    arm.Finalize()
    return arm


@pytest.fixture()
def context(plant: MultibodyPlant) -> Context:
    """A fresh default context of the plant."""
    return plant.CreateDefaultContext()


def eq18(q: np.ndarray) -> tuple[float, float, float]:
    """Paper eq. 18: fingertip x, y and angle theta."""
    l1, l2, l3 = LINK_LENGTHS
    a1, a2, a3 = q[0], q[0] + q[1], q[0] + q[1] + q[2]
    x = l1 * math.sin(a1) + l2 * math.sin(a2) + l3 * math.sin(a3)
    y = -l1 * math.cos(a1) - l2 * math.cos(a2) - l3 * math.cos(a3)
    return x, y, a3


def closed_form_ik(x: float, y: float, theta: float, elbow: int) -> np.ndarray:
    """Inverse of eq. 18 through the wrist point; elbow = +1 or -1 is the sign of q2."""
    l1, l2, l3 = LINK_LENGTHS
    wx, wy = x - l3 * math.sin(theta), y + l3 * math.cos(theta)
    cos_q2 = (wx**2 + wy**2 - l1**2 - l2**2) / (2 * l1 * l2)
    assert abs(cos_q2) < 1.0, f"({x}, {y}) out of reach"
    q2 = elbow * math.acos(cos_q2)
    q1 = math.atan2(wx, -wy) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    return np.array([q1, q2, theta - q1 - q2])


def task_grid() -> list[np.ndarray]:
    """Both elbow solutions on a grid over the task region, theta = pi/2."""
    return [
        closed_form_ik(x, y, TASK_THETA, elbow)
        for x in np.linspace(*TASK_X, 8)
        for y in np.linspace(*TASK_Y, 6)
        for elbow in (1, -1)
    ]


def fingertip_jacobian(plant: MultibodyPlant, context: Context) -> np.ndarray:
    """Rows (x, y, theta) of the fingertip frame's Jacobian with respect to v."""
    frame, world = plant.GetFrameByName("fingertip"), plant.world_frame()
    J = plant.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
    )
    return J[[3, 4, 2]]


def test_loads_with_named_joints_actuators_and_frame(plant: MultibodyPlant) -> None:
    """Three revolute joints about +z, three actuators, the weld and the fingertip frame."""
    assert (plant.num_positions(), plant.num_velocities(), plant.num_actuators()) == (3, 3, 3)
    weld = plant.GetJointByName("base_weld")
    assert weld.type_name() == "weld"
    assert weld.parent_body().name() == "world" and weld.child_body().name() == "base"
    parents = ("base", "link1", "link2")
    for index, (name, parent, child) in enumerate(zip(JOINTS, parents, LINKS, strict=True)):
        joint = plant.GetJointByName(name)
        assert isinstance(joint, RevoluteJoint)
        assert (joint.parent_body().name(), joint.child_body().name()) == (parent, child)
        assert joint.position_start() == index and joint.velocity_start() == index
        np.testing.assert_array_equal(joint.revolute_axis(), [0.0, 0.0, 1.0])
        assert joint.default_damping() == 0.0
        assert joint.position_lower_limits()[0] <= -math.pi + 1e-9
        assert joint.position_upper_limits()[0] >= math.pi - 1e-9
        actuator = plant.GetJointActuatorByName(name)
        assert actuator.joint().name() == name and actuator.input_start() == index
    fingertip = plant.GetFrameByName("fingertip")
    assert fingertip.body().name() == "link3"
    X_L3F = fingertip.GetFixedPoseInBodyFrame()
    np.testing.assert_allclose(X_L3F.translation(), [0.0, -LINK_LENGTHS[2], 0.0], atol=1e-15)
    np.testing.assert_allclose(X_L3F.rotation().matrix(), np.eye(3), atol=1e-15)


def test_fingertip_kinematics_match_eq18(plant: MultibodyPlant, context: Context) -> None:
    """Fingertip x, y and rotation about z equal eq. 18 at random configurations."""
    rng = np.random.default_rng(seed=18)
    frame, world = plant.GetFrameByName("fingertip"), plant.world_frame()
    for q in rng.uniform(-math.pi, math.pi, size=(50, 3)):
        plant.SetPositions(context, q)
        X_WF = plant.CalcRelativeTransform(context, world, frame)
        x, y, theta = eq18(q)
        np.testing.assert_allclose(X_WF.translation(), [x, y, 0.0], rtol=0, atol=1e-12)
        R = X_WF.rotation().matrix()
        np.testing.assert_allclose(R[:, 2], [0.0, 0.0, 1.0], atol=1e-12)
        angle_error = math.atan2(R[1, 0], R[0, 0]) - theta
        assert abs(math.remainder(angle_error, 2 * math.pi)) < 1e-12


def test_parameters_match_derivation(plant: MultibodyPlant) -> None:
    """Masses, COMs, inertias, limits, rotor inertias and gear ratios equal the derivation."""
    for name, expected in derive.link_inertials().items():
        body = plant.GetBodyByName(name)
        M_BBo_B = body.default_spatial_inertia()
        com = M_BBo_B.get_com()
        I_BBcm_B = M_BBo_B.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()
        scale = np.abs(expected.inertia).max()
        np.testing.assert_allclose(body.default_mass(), expected.mass, rtol=1e-6)
        np.testing.assert_allclose(com, expected.com, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(I_BBcm_B, expected.inertia, rtol=1e-6, atol=1e-9 * scale)
    expected_drives = zip(
        JOINTS,
        derive.effort_limits(),
        derive.velocity_limits(),
        derive.rotor_inertias(),
        derive.gear_ratios(),
        strict=True,
    )
    for name, effort, velocity, rotor_inertia, gear_ratio in expected_drives:
        actuator = plant.GetJointActuatorByName(name)
        np.testing.assert_allclose(actuator.effort_limit(), effort, rtol=1e-6)
        np.testing.assert_allclose(actuator.default_rotor_inertia(), rotor_inertia, rtol=1e-6)
        np.testing.assert_allclose(actuator.default_gear_ratio(), gear_ratio, rtol=1e-6)
        joint = plant.GetJointByName(name)
        np.testing.assert_allclose(joint.velocity_upper_limits(), [velocity], rtol=1e-6)
        np.testing.assert_allclose(joint.velocity_lower_limits(), [-velocity], rtol=1e-6)
    np.testing.assert_allclose(derive.LINK_LENGTHS, LINK_LENGTHS)
    # The light last link: inertia about joint 3 of order 5e-4 kg m^2 (stiff theta loop).
    link3 = plant.GetBodyByName("link3").default_spatial_inertia()
    assert 4e-4 < link3.CalcRotationalInertia()[2, 2] < 1e-3


def test_task_region_is_reachable_away_from_singularities(
    plant: MultibodyPlant, context: Context
) -> None:
    """Every task point (theta = pi/2) has two elbow solutions with a well-conditioned
    (x, y, theta) Jacobian."""
    configurations = task_grid()
    assert len(configurations) == 96
    world, frame = plant.world_frame(), plant.GetFrameByName("fingertip")
    for q in configurations:
        plant.SetPositions(context, q)
        x, y, theta = eq18(q)
        p_WF = plant.CalcPointsPositions(context, frame, np.zeros(3), world).ravel()
        np.testing.assert_allclose(p_WF[:2], [x, y], atol=1e-12)
        assert TASK_X[0] - 1e-12 <= x <= TASK_X[1] + 1e-12
        assert abs(theta - TASK_THETA) < 1e-12
        assert abs(math.sin(q[1])) > 0.5, "elbow within 30 degrees of straight or folded"
        singular_values = np.linalg.svd(fingertip_jacobian(plant, context), compute_uv=False)
        assert singular_values.min() > 0.05


def test_effort_limits_hold_weight_and_full_scale_press(
    plant: MultibodyPlant, context: Context
) -> None:
    """Holding the arm still while pressing the wall with the sensor's full scale (100 N
    along +x) needs less than each effort limit over the task region, both elbows."""
    limits = np.array([plant.GetJointActuatorByName(name).effort_limit() for name in JOINTS])
    wall_reaction = np.array([-SENSOR_FULL_SCALE, 0.0, 0.0])  # on the tip, (x, y, theta)
    worst = np.zeros(3)
    for q in task_grid():
        plant.SetPositions(context, q)
        tau_gravity = plant.CalcGravityGeneralizedForces(context)
        J = fingertip_jacobian(plant, context)
        tau_hold = -tau_gravity - J.T @ wall_reaction
        np.testing.assert_allclose(
            tau_hold, derive.holding_torques(q, SENSOR_FULL_SCALE), rtol=1e-9, atol=1e-9
        )
        worst = np.maximum(worst, np.abs(tau_hold))
    assert np.all(worst < limits), f"required {worst} N m exceeds limits {limits} N m"


def test_hanging_configuration_is_equilibrium(plant: MultibodyPlant, context: Context) -> None:
    """With gravity along -y, q = 0 (hanging along -y) needs no torque; horizontal does."""
    plant.SetPositions(context, np.zeros(3))
    np.testing.assert_allclose(plant.CalcGravityGeneralizedForces(context), 0.0, atol=1e-12)
    q = np.array([math.pi / 2, 0.0, 0.0])  # arm straight along +x
    plant.SetPositions(context, q)
    tau_gravity = plant.CalcGravityGeneralizedForces(context)
    assert tau_gravity[0] < 0.0, "gravity pulls the horizontal arm down (negative about z)"
    np.testing.assert_allclose(-tau_gravity, derive.holding_torques(q, 0.0), rtol=1e-9)


def test_visual_geometry_matches_mass_model() -> None:
    """Plates are drawn where the mass model puts them; the fingertip sphere's surface
    touches the fingertip frame's origin."""
    builder = DiagramBuilder()
    arm, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    Parser(arm).AddModels(str(URDF_PATH))
    arm.Finalize()
    assert isinstance(scene_graph, SceneGraph)
    inspector = scene_graph.model_inspector()
    for index, link in enumerate(LINKS):
        frame_id = arm.GetBodyFrameIdOrThrow(arm.GetBodyByName(link).index())
        geometries = inspector.GetGeometries(frame_id, Role.kIllustration)
        assert not inspector.GetGeometries(frame_id, Role.kProximity)
        plates = [g for g in geometries if inspector.GetName(g).endswith(f"{link}_plate")]
        assert len(plates) == 1
        box = inspector.GetShape(plates[0])
        np.testing.assert_allclose(
            [box.width(), box.depth(), box.height()], derive.plate_size(index), rtol=1e-9
        )
        np.testing.assert_allclose(
            inspector.GetPoseInFrame(plates[0]).translation(),
            derive.plate_center(index),
            atol=1e-12,
        )
    frame_id = arm.GetBodyFrameIdOrThrow(arm.GetBodyByName("link3").index())
    spheres = [
        g
        for g in inspector.GetGeometries(frame_id, Role.kIllustration)
        if isinstance(inspector.GetShape(g), Sphere)
    ]
    assert len(spheres) == 1
    radius = inspector.GetShape(spheres[0]).radius()
    X_L3S: RigidTransform = inspector.GetPoseInFrame(spheres[0])
    p_L3F = arm.GetFrameByName("fingertip").GetFixedPoseInBodyFrame().translation()
    np.testing.assert_allclose(np.linalg.norm(p_L3F - X_L3S.translation()), radius, atol=1e-12)
    np.testing.assert_allclose(radius, derive.FINGERTIP_RADIUS)
