"""A real serial arm in six dimensions: its tool on a table through Drake's contact engine.

The paper states its law for any n-joint serial arm with a task vector X in R^m. This module
loads one from its published description (a URDF or SDF file, or a ``package://`` URL;
example-robot-data's Franka Panda and UR5 are the built-in scenarios' arms), welds its base
to the world, and adds what the task needs:

* **actuators**: one per joint that moves the flange, where the description has none (the
  Panda's URDF has no ``transmission``), with the effort limit of its ``<limit effort>``;
  joints that do not move the flange and have no actuator (the Panda's fingers) become
  welds at their zero position, so the hand is a rigid part of the last link;
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
  orientation in E is the identity, so the plan's rotation vector is zero.

**Contact.** Drake's compliant point contact on a discrete plant (SAP, "lagged"
approximation), as the gripper's (docs/grasp.md): a sphere on a box face is one contact
point with a linear stiffness, the paper's Ke of eq. 4, set directly by
``surface.stiffness`` (1e5 N/m by default: a steel ball on a rubber-padded table, 0.1 mm
deep at 10 N; a bare steel table, ~1e7 N/m, needs a step well under 1 ms for the PID's
sampled loop), with Hunt-Crossley dissipation and Coulomb friction. Only the tool and the
table collide: the arm's own collision geometry is removed (its links never come near the
table in these tasks, and Drake's default filter would still let non-adjacent links
touch each other).
"""

from __future__ import annotations

import importlib.metadata
import math
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

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
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    FrameIndex,
    JacobianWrtVariable,
    SpatialInertia,
    UnitInertia,
    WeldJoint,
)
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.description import ForcePoint, force_law, sensor_chain
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES, SpatialScenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.posture_task import PostureTask
from admittance.systems.spatial_kinematics import rotation_vector

__all__ = [
    "CONTROL_FRAME",
    "NORMAL_AXIS",
    "ROBOTS_EXTRA",
    "TABLE_BODY",
    "TOOL_BODY",
    "TOOL_TIP_FRAME",
    "TOOL_WELD",
    "AddSpatialArm",
    "frame_names",
    "SolveSpatialInverseKinematics",
    "SpatialGeometry",
    "example_robot_data_packages",
    "spatial_point",
    "tool_tip_offset",
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
# The optional extra that brings example-robot-data, and the packages it registers.
ROBOTS_EXTRA = 'pip install "optimal-admittance[robots]"'
EXAMPLE_ROBOT_DATA = "example-robot-data"
EXAMPLE_ROBOT_PACKAGES = ("panda_description", "ur_description")


def example_robot_data_packages() -> dict[str, Path] | None:
    """{package name: folder} of example-robot-data's descriptions, None if not installed.

    The distribution (a cmeel package) installs its robots under
    ``cmeel.prefix/share/example-robot-data/robots`` in site-packages; their meshes are
    named from the package ``example-robot-data`` itself (its share folder).
    """
    try:
        distribution = importlib.metadata.distribution(EXAMPLE_ROBOT_DATA)
    except importlib.metadata.PackageNotFoundError:
        return None
    root = Path(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not root.is_dir():
        return None
    packages = {name: root / name for name in EXAMPLE_ROBOT_PACKAGES if (root / name).is_dir()}
    packages[EXAMPLE_ROBOT_DATA] = root.parent
    return packages


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


def _model_source(scenario: SpatialScenario) -> tuple[str, dict[str, Path]]:
    """The model's URL or file path, and the packages to register; one-line errors."""
    url = scenario.arm.urdf
    packages = example_robot_data_packages() or {}
    if url.startswith("package://"):
        package = url[len("package://") :].split("/", 1)[0]
        if package in EXAMPLE_ROBOT_PACKAGES and package not in packages:
            raise ScenarioError(
                f"arm.urdf: {url} comes from example-robot-data, which is not installed: "
                f"{ROBOTS_EXTRA}"
            )
        return url, packages
    path = Path(url).expanduser()
    if not path.is_file():
        raise ScenarioError(f"arm.urdf: must be an existing URDF or SDF file, got {url!r}")
    return str(path.resolve()), packages


def _efforts_from_file(path: Path) -> dict[str, float]:
    """{joint name: effort limit} from a URDF's ``<limit effort>`` or an SDF's ``<effort>``."""
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError):
        return {}
    efforts = {}
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        if limit is None:
            limit = joint.find("axis/limit")
        if limit is None:
            continue
        text = limit.get("effort") or (limit.findtext("effort") or "")
        try:
            value = float(text)
        except ValueError:
            continue
        if value > 0 and math.isfinite(value):
            efforts[joint.get("name")] = value
    return efforts


_COLLISION = re.compile(r"<collision\b[^>]*?/>|<collision\b.*?</collision>", re.DOTALL)
# ROS's soft joint limits (the Panda's), which Drake does not read and warns about.
_SAFETY_CONTROLLER = re.compile(
    r"<safety_controller\b[^>]*?/>|<safety_controller\b.*?</safety_controller>", re.DOTALL
)
_MESH_FILE = re.compile(r'(filename\s*=\s*"|<uri>\s*)([^"<]+)')


def _without_collisions(file: Path) -> str:
    """The model file's text without its collision elements (and without ROS's
    ``safety_controller`` tags, which Drake ignores with a warning each), relative mesh names
    made absolute (the text is parsed from a string).

    Only the tool and the table collide here, and Drake refuses the published arms' STL
    collision meshes (it makes convex hulls of .obj, .vtk and .gltf only), so they are left
    out before parsing rather than removed after.
    """
    text = file.read_text(encoding="utf-8")
    folder = file.resolve().parent

    def absolute(match: re.Match) -> str:
        name = match.group(2).strip()
        if "://" in name or Path(name).is_absolute():
            return match.group(0)
        return match.group(1) + str(folder / name)

    text = _SAFETY_CONTROLLER.sub("", _COLLISION.sub("", text))
    return _MESH_FILE.sub(absolute, text)


# How many names an unknown-frame message lists of the links, and of the other frames.
SHOWN_LINKS = 40
SHOWN_OTHER_FRAMES = 10


def _listed(names: list[str], most: int) -> str:
    """`names` joined, whole names only: the first `most` and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def frame_names(plant: MultibodyPlant) -> tuple[list[str], list[str]]:
    """The names a frame key may take: the links (body frames), then the other frames
    (joint frames, frames the model adds), each sorted; the world and Drake's own
    ``_``-prefixed frames left out."""
    links, others = set(), set()
    for i in range(plant.num_frames()):
        frame = plant.get_frame(FrameIndex(i))
        name = frame.name()
        if not name or name.startswith("_") or name == "world":
            continue
        is_link = frame.index() == frame.body().body_frame().index()
        (links if is_link else others).add(name)
    return sorted(links), sorted(others - links)


def _frame(plant: MultibodyPlant, name: str, key: str):
    if not plant.HasFrameNamed(name):
        links, others = frame_names(plant)
        listed = f"its links: {_listed(links, SHOWN_LINKS)}"
        if others:
            listed += f"; its other frames: {_listed(others, SHOWN_OTHER_FRAMES)}"
        raise ScenarioError(f"{key}: the model has no frame named {name!r}; {listed}")
    return plant.GetFrameByName(name)


def _load_arm(plant: MultibodyPlant, scenario: SpatialScenario) -> list[str]:
    """Parses the model, welds its base, makes its flange chain actuated and its other
    joints rigid; returns the actuated joints' names."""
    source, packages = _model_source(scenario)
    parser = Parser(plant)
    for name, folder in packages.items():
        if not parser.package_map().Contains(name):
            parser.package_map().Add(name, str(folder))
    try:
        file = Path(parser.package_map().ResolveUrl(source)) if "://" in source else Path(source)
        parser.AddModelsFromString(_without_collisions(file), file.suffix.lstrip(".").lower())
    except (RuntimeError, OSError, UnicodeDecodeError) as error:
        first = str(error).strip().splitlines()[0] if str(error).strip() else "unreadable"
        raise ScenarioError(f"arm.urdf: Drake cannot read {source!r}: {first}") from None
    arm = scenario.arm
    base = _frame(plant, arm.base_frame, "arm.base_frame")
    flange = _frame(plant, arm.flange_frame, "arm.flange_frame")
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    parent_joint = {joint.child_body().index(): joint for joint in joints}
    # The joints between the flange and the base (walked before any joint is removed: a
    # removed joint's Python handle points at freed memory).
    chain, body = set(), flange.body().index()
    while body in parent_joint and body not in (base.body().index(), plant.world_body().index()):
        chain.add(parent_joint[body].name())
        body = parent_joint[body].parent_body().index()
    existing = parent_joint.get(base.body().index())
    if existing is not None and existing.parent_body().index() == plant.world_body().index():
        # The description welds its base to its own "world" link (the UR5's): the
        # scenario's weld replaces it.
        joints.remove(existing)
        plant.RemoveJoint(existing)
    plant.WeldFrames(plant.world_frame(), base, RigidTransform(arm.base_position))
    efforts = _efforts_from_file(file)
    actuated = {plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()}
    # Moving joints: those that move the flange get an actuator if they have none; the
    # others become welds at their zero position.
    rigid = []
    for joint in joints:
        if joint.num_velocities() == 0 or joint.name() in actuated:
            continue
        if joint.name() in chain:
            if joint.num_velocities() != 1:
                raise ScenarioError(
                    f"arm.urdf: joint {joint.name()!r} moves the flange with "
                    f"{joint.num_velocities()} degrees of freedom; a serial arm's joints "
                    "have one"
                )
            effort = efforts.get(joint.name(), math.inf)
            plant.AddJointActuator(f"{joint.name()}_actuator", joint, effort)
            continue
        rigid.append(joint)
    if rigid:
        # The description's mimic couplers (the Panda's second finger follows the first)
        # go with the joints they couple: Drake removes a joint only from a plant without
        # constraints.
        for constraint in plant.GetConstraintIds():
            plant.RemoveConstraint(constraint)
    for joint in rigid:
        parent, child, name = joint.frame_on_parent(), joint.frame_on_child(), joint.name()
        plant.RemoveJoint(joint)
        plant.AddJoint(WeldJoint(f"{name}_weld", parent, child, RigidTransform()))
    names = [plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()]
    if not names:
        raise ScenarioError(
            f"arm.flange_frame: no joint moves {arm.flange_frame!r} (is it on the arm?)"
        )
    return names


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
    actuated = _load_arm(plant, scenario)
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


def SolveSpatialInverseKinematics(
    plant: MultibodyPlant,
    frame_name: str,
    X_WT: RigidTransform,
    joint_guess,
    *,
    tolerance: float = 1e-10,
    max_iterations: int = 200,
) -> np.ndarray:
    """Joint positions that put `frame_name` at the pose X_WT, by damped Newton steps.

    The step is the least-squares solution of J dq = (rotation vector, position error);
    a redundant arm's remaining freedom pulls towards `joint_guess` (a null-space step),
    so the guess picks the branch and the posture.

    Raises:
        ValueError: the pose is not reached (out of the workspace, singular, or beyond the
            joint limits).
    """
    context = plant.CreateDefaultContext()
    frame = plant.GetFrameByName(frame_name)
    guess = np.zeros(plant.num_positions())
    given = np.asarray(joint_guess, dtype=float)
    guess[: min(guess.size, given.size)] = given[: guess.size]
    q = guess.copy()
    for _ in range(max_iterations):
        plant.SetPositions(context, q)
        X = plant.CalcRelativeTransform(context, plant.world_frame(), frame)
        error = np.concatenate(
            [
                rotation_vector((X_WT.rotation() @ X.rotation().inverse()).matrix().tolist()),
                X_WT.translation() - X.translation(),
            ]
        )
        if np.linalg.norm(error) < tolerance:
            break
        J = plant.CalcJacobianSpatialVelocity(
            context,
            JacobianWrtVariable.kQDot,
            frame,
            np.zeros(3),
            plant.world_frame(),
            plant.world_frame(),
        )
        pseudo_inverse = np.linalg.pinv(J, rcond=1e-6)
        step = pseudo_inverse @ error
        step += (np.eye(q.size) - pseudo_inverse @ J) @ (0.2 * (guess - q))
        q = q + step * min(1.0, 0.3 / max(np.max(np.abs(step)), 1e-12))
    else:
        raise ValueError(f"the pose is not reached from {given.tolist()} (error {error.tolist()})")
    low, high = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    if np.any(q < low - 1e-9) or np.any(q > high + 1e-9):
        raise ValueError(f"the pose needs joints {q.tolist()} beyond the joint limits")
    return q


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
