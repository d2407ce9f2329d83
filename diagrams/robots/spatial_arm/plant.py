"""A real serial arm in six dimensions: its tool on a table through Drake's contact engine.

The paper states its law for any n-joint serial arm with a task vector X in R^m. This module
loads one from its published description (a URDF or SDF file, or a ``package://`` URL;
example-robot-data's Franka Panda and UR5 are the built-in scenarios' arms) through
:mod:`.model`, which welds its base to the world, gives an actuator to each joint that
moves the flange (where the description has none) and makes the others rigid, so the hand
is a rigid part of the last link. This module adds what the task needs:

* **the tool**: a body welded to the flange by the weld joint ``tool_weld`` (where a wrist
  force/torque sensor sits), a shaft along the flange's z axis ending in a sphere or a
  disc; its tip frame ``tool_tip`` (the sphere's or the disc's face's point on the axis),
  whose z axis points along the tool, is the controlled frame;
* **the table**: a box welded to the world whose real top differs from the plan by
  ``surface.height_error`` and the tilts ``surface.tilt_x``, ``surface.tilt_y`` about the
  planned contact point;
* **the control frame** ``control_frame`` (E), fixed at the planned contact point, its z
  axis along the planned INWARD normal (into the table, world -z for a level plan) and its
  x axis along the slide: the law's force, Fr and Xr are positive into the surface, as the
  paper arm's are along its wall's normal. The tool is aligned with E when its tip frame's
  orientation in E is the identity, so the plan's rotation vector is zero;
* **the force-controlled point** (``spatial_point``): the tool tip in E, its sensor, law
  and PID.

**Contact.** Drake's compliant point contact on a discrete plant (SAP, "lagged"
approximation), as the gripper's (docs/evidence/grasp.md): a sphere on a box face is one contact
point with a linear stiffness, the paper's Ke of eq. 4, set directly by
``surface.stiffness`` (1e5 N/m by default: a steel ball on a rubber-padded table, 0.1 mm
deep at 10 N; a bare steel table, ~1e7 N/m, needs a step well under 1 ms for the PID's
sampled loop), with Hunt-Crossley dissipation and Coulomb friction. Only the tool and the
table collide: the arm's own collision geometry is removed (its links never come near the
table in these tasks, and Drake's default filter would still let non-adjacent links
touch each other).

The inverse kinematics of the tool tip is :mod:`.inverse_kinematics`'s and the model's
source :mod:`.model`'s; ``SolveSpatialInverseKinematics`` and
``example_robot_data_packages`` are importable from here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    Box,
    Cylinder,
    ProximityProperties,
    Role,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    SpatialInertia,
    UnitInertia,
    WeldJoint,
)
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.description import ForcePoint, force_law, sensor_chain
from admittance.diagrams.robots.spatial_arm.inverse_kinematics import (
    SolveSpatialInverseKinematics,
)
from admittance.diagrams.robots.spatial_arm.model import example_robot_data_packages, load_arm
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES, SpatialScenario
from admittance.systems.posture_task import PostureTask

__all__ = [
    "CONTROL_FRAME",
    "NORMAL_AXIS",
    "TABLE_BODY",
    "TOOL_BODY",
    "TOOL_TIP_FRAME",
    "TOOL_WELD",
    "AddSpatialArm",
    "SpatialGeometry",
    "spatial_point",
    "tool_tip_offset",
    # Where the loop and the tests import them from (defined in .inverse_kinematics and
    # .model).
    "SolveSpatialInverseKinematics",
    "example_robot_data_packages",
]

# The names this module gives to what it adds to the plant.
TOOL_BODY = "tool"
TOOL_WELD = "tool_weld"
TOOL_TIP_FRAME = "tool_tip"
TABLE_BODY = "table"
CONTROL_FRAME = "control_frame"
# The force-controlled axis: z of the control frame, the planned inward normal.
NORMAL_AXIS = 2
# The table's size (world x, y of its top, and its thickness), m.
TABLE_SIZE = (1.0, 1.0, 0.05)
# The shaft's radius as a fraction of the tool's radius (drawing only: it never touches).
SHAFT_RADIUS = 0.4


@dataclass
class SpatialGeometry:
    """What the builder placed and what the plan assumes."""

    # X_WE: the control frame at the planned contact point (z into the planned table).
    X_WE: RigidTransform
    # X_WS: the real table's top at the point above/below the planned one (z up, out of
    # the table), tilted and shifted by the surface's errors.
    X_WS: RigidTransform
    # The tool tip in the flange frame, m (on the flange's z axis).
    tip_offset: float
    # The actuated joints, in the order of the actuation vector.
    actuated_joints: list[str]
    # The tool's mass, kg, and its centre of mass in the flange frame, m.
    tool_mass: float
    tool_com: np.ndarray


def _contact_properties(scenario: SpatialScenario) -> ProximityProperties:
    """The tool's and the table's point-contact material: Drake combines two geometries'
    stiffnesses in series and their dissipations and frictions as weighted means, so both
    sides get 2 k, d and mu to give the pair k, d and mu."""
    surface = scenario.surface
    properties = ProximityProperties()
    AddContactMaterial(
        dissipation=surface.dissipation,
        point_stiffness=2.0 * surface.stiffness,
        friction=CoulombFriction(surface.friction, surface.friction),
        properties=properties,
    )
    return properties


def tool_tip_offset(scenario: SpatialScenario) -> float:
    """The tool tip's distance from the flange along its z axis, m: the sphere's far point,
    or the disc's face."""
    tool = scenario.tool
    if tool.shape == "sphere":
        return tool.length + tool.radius
    return tool.length + 0.5 * tool.thickness


def _add_tool(plant: MultibodyPlant, scenario: SpatialScenario, flange) -> tuple[float, float]:
    """The tool body, welded to the flange by TOOL_WELD; returns (tip offset, mass)."""
    tool = scenario.tool
    com = np.array([0.0, 0.0, 0.5 * tool.length])
    inertia = UnitInertia.SolidCylinder(
        SHAFT_RADIUS * tool.radius, max(tool.length, 1e-3), [0.0, 0.0, 1.0]
    )
    body = plant.AddRigidBody(
        TOOL_BODY,
        plant.AddModelInstance(TOOL_BODY),
        SpatialInertia(tool.mass, com, inertia.ShiftFromCenterOfMass(-com)),
    )
    plant.AddJoint(WeldJoint(TOOL_WELD, flange, body.body_frame(), RigidTransform()))
    end = RigidTransform([0.0, 0.0, tool.length])
    tip = tool_tip_offset(scenario)
    if tool.shape == "sphere":
        shape = Sphere(tool.radius)
    else:
        shape = Cylinder(tool.radius, tool.thickness)
    properties = _contact_properties(scenario)
    plant.RegisterCollisionGeometry(body, end, shape, "tool_collision", properties)
    plant.RegisterVisualGeometry(body, end, shape, "tool_visual", [0.8, 0.5, 0.1, 1.0])
    if tool.length > 0:
        plant.RegisterVisualGeometry(
            body,
            RigidTransform([0.0, 0.0, 0.5 * tool.length]),
            Cylinder(SHAFT_RADIUS * tool.radius, tool.length),
            "tool_shaft",
            [0.6, 0.6, 0.6, 1.0],
        )
    plant.AddFrame(FixedOffsetFrame(TOOL_TIP_FRAME, body.body_frame(), RigidTransform([0, 0, tip])))
    return tip, tool.mass


def _surface_frames(scenario: SpatialScenario) -> tuple[RigidTransform, RigidTransform]:
    """(X_WE, X_WS): the control frame at the planned point, the real table's top."""
    surface, plan = scenario.surface, scenario.trajectory
    point = np.array([*surface.position, surface.height])
    heading = math.radians(plan.slide_direction)
    x_axis = np.array([math.cos(heading), math.sin(heading), 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    R_WE = RotationMatrix(np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis]))
    X_WE = RigidTransform(R_WE, point)
    tilt = RotationMatrix(
        RollPitchYaw(math.radians(surface.tilt_x), math.radians(surface.tilt_y), 0.0)
    )
    X_WS = RigidTransform(tilt, point + [0.0, 0.0, surface.height_error])
    return X_WE, X_WS


def _add_table(plant: MultibodyPlant, scenario: SpatialScenario, X_WS: RigidTransform) -> None:
    """The table: a box welded to the world, its top face through X_WS."""
    size = TABLE_SIZE
    body = plant.AddRigidBody(
        TABLE_BODY, plant.AddModelInstance(TABLE_BODY), SpatialInertia.SolidBoxWithMass(10.0, *size)
    )
    X_WB = X_WS @ RigidTransform([0.0, 0.0, -0.5 * size[2]])
    plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WB)
    box = Box(*size)
    plant.RegisterCollisionGeometry(
        body, RigidTransform(), box, "table_collision", _contact_properties(scenario)
    )
    plant.RegisterVisualGeometry(body, RigidTransform(), box, "table_visual", [0.5, 0.4, 0.3, 0.6])


def AddSpatialArm(builder: DiagramBuilder, scenario: SpatialScenario):
    """Adds the arm, its tool, the table and the control frame as a discrete plant.

    Returns:
        (plant, scene_graph, geometry), the plant finalized.

    Raises:
        ScenarioError: the model cannot be read, a frame is missing, an extra is missing.
    """
    config = MultibodyPlantConfig(
        time_step=scenario.time_step,
        contact_model="point",
        discrete_contact_approximation="lagged",
        stiction_tolerance=scenario.surface.stiction_tolerance,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    actuated = load_arm(plant, scenario)
    # Only the tool and the table collide (see the module's docstring).
    inspector = scene_graph.model_inspector()
    for geometry in inspector.GetAllGeometryIds(Role.kProximity):
        scene_graph.RemoveRole(plant.get_source_id(), geometry, Role.kProximity)
    flange = plant.GetFrameByName(scenario.arm.flange_frame)
    tip, mass = _add_tool(plant, scenario, flange)
    X_WE, X_WS = _surface_frames(scenario)
    _add_table(plant, scenario, X_WS)
    plant.AddFrame(FixedOffsetFrame(CONTROL_FRAME, plant.world_frame(), X_WE))
    damping = scenario.arm.joint_damping
    if damping > 0:
        for name in actuated:
            joint = plant.GetJointByName(name)
            joint.set_default_damping(joint.default_damping() + damping)
    plant.Finalize()
    geometry = SpatialGeometry(
        X_WE=X_WE,
        X_WS=X_WS,
        tip_offset=tip,
        actuated_joints=actuated,
        tool_mass=mass,
        tool_com=np.array([0.0, 0.0, 0.5 * scenario.tool.length]),
    )
    return plant, scene_graph, geometry


def spatial_point(
    scenario: SpatialScenario, plant: MultibodyPlant, initial_positions
) -> ForcePoint:
    """The arm's force-controlled point: the tool tip, X = (x, y, z, rx, ry, rz) in the
    control frame (z into the planned table), the force along z, with the scenario's sensor
    (read at time_step), the force law and the 6-D PID sampled at time_step, with gravity
    compensation (as the torque interfaces of such arms provide it) and, for a redundant
    arm (more than six actuated joints), the posture task towards `initial_positions`."""
    period = scenario.time_step
    controller = scenario.controller
    baseline = {
        "mass": controller.mass,
        "damping": controller.damping,
        "stiffness": controller.stiffness,
    }
    sensor = scenario.sensor
    # The readout at the step, or the wrist sensor at its weld with its own period.
    readout = dict(noise_period=period, period=period)
    if sensor.kind == "wrench":
        readout = dict(
            noise_period=sensor.period or period,
            period=sensor.period or period,
            weld_joint=TOOL_WELD,
            tool_mass=scenario.tool.mass,
            tool_com=(0.0, 0.0, 0.5 * scenario.tool.length),
            contact_offset=(0.0, 0.0, tool_tip_offset(scenario)),
            bias=tuple(sensor.bias),
            torque_noise_std=sensor.torque_noise_std,
        )
    chain = sensor_chain(sensor, faults=scenario.faults, **readout)
    pid = scenario.pid
    posture = None
    if plant.num_actuated_dofs() > len(SPATIAL_COORDINATES):
        posture = PostureTask(
            q0=list(initial_positions), kp=scenario.posture.kp, kd=scenario.posture.kd
        )
    return ForcePoint(
        name="",
        frame=TOOL_TIP_FRAME,
        coordinates=SPATIAL_COORDINATES,
        expressed_in=CONTROL_FRAME,
        force_axes=(NORMAL_AXIS,),
        sensor=chain,
        law=force_law(controller.kind, scenario.admittance, period=period, baseline=baseline),
        kp=list(pid.kp),
        kd=list(pid.kd),
        ki=list(pid.ki),
        pid_period=period,
        gravity_compensation=True,
        posture=posture,
    )
