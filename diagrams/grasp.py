"""The paper's loop on a hand: Drake's planar gripper holding its brick, one force loop per finger.

The paper closes with "future applications to manipulation and grasping tasks". This builder
loads Drake's three-fingered planar gripper and its brick from the installed drake package
(``package://drake/examples/planar_gripper/``), welds the fingers around the brick as Drake's
planar gripper example does, in the vertical y-z plane with gravity along -z, and wires one
copy of the paper's Fig. 1 per finger:

    Xd_i --(+)--> Xc_i --> CartesianPid_i --tau_i--(+)--> plant --contact results--+
           ^ Xr_i             (tip's (x, y) in its face's frame)                    |
           +--- OptimalAdmittance_i <-- Fm_i -- FlexiForce_i <-- F_i -- ContactForceSensor
                        ^ Fr_i(t)

* Contact is Drake's own compliant point contact (a sphere tip on a box face gives one
  contact point with a linear stiffness, the paper's Ke of eq. 4, swept directly by
  ``contact.stiffness`` and ``brick.stiffness_error``), with Hunt-Crossley dissipation and
  Coulomb friction, on a discrete plant (SAP's convex solver, "lagged" approximation).
  docs/grasp.md gives the measurements behind the choice (time per simulated second, force
  ripple, Linearize).
* Every controller and the sensors' ADC are sampled at the plant's time step.
* Each finger's task space is (x, y) of its tip sphere's centre in a frame C fixed at the
  planned face it touches: x along the face's inward normal (the force axis), y along the
  face in the hand's plane. The plan presses each planned face by Fr / contact.stiffness:
  the paper's eq. 6 (the fixed reference) on the planned brick, where position-only fingers
  press it with Fr once their PID's integral has brought the tips there.

The plan knows the brick only as planned: its size is the real one (Drake's model) minus
``brick.size_error``, its contact stiffness ``contact.stiffness`` (the real one is that
times ``brick.stiffness_error``). At t = 0 the brick rests on finger3 (below it), in
equilibrium under its weight; finger1 and finger2 are open by ``plan.open_distance``. They
close on the planned faces over ``plan.close_time``; then every desired force ramps from
what the finger reads at t = 0 to its Fr over ``plan.force_ramp_time``, and the plan
presses each face over the same interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.geometry import (
    AddContactMaterial,
    Box,
    ProximityProperties,
    Role,
    RoleAssign,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import FixedOffsetFrame, JacobianWrtVariable
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    ConstantVectorSource,
    Demultiplexer,
    Gain,
    LogVectorOutput,
    Multiplexer,
    RandomSource,
    TrajectorySource,
    VectorLogSink,
)
from pydrake.trajectories import PiecewisePolynomial

from admittance.diagrams.closed_loop import SolvePlanarInverseKinematics
from admittance.diagrams.grasp_scenario import FINGERS, GraspScenario
from admittance.diagrams.scenario import ScenarioError
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.contact_force_sensor import ContactForceSensor
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.optimal_admittance import OptimalAdmittance
from admittance.systems.planar_kinematics import PlanarKinematics

__all__ = [
    "BRICK_URL",
    "GRIPPER_URL",
    "BuildGrasp",
    "GraspLoop",
    "HandGeometry",
    "SetGraspInitialConditions",
]

GRIPPER_URL = "package://drake/examples/planar_gripper/planar_gripper.sdf"
BRICK_URL = "package://drake/examples/planar_gripper/planar_brick.sdf"
# Drake's finger layout (examples/planar_gripper, WeldGripperFrames): each finger's base is
# welded this far from the gripper's origin, rotated about world x from +z by these angles
# (finger1 and finger2 above the brick on either side, finger3 below it).
BASE_DISTANCE = 0.201  # m
BASE_ANGLES = (math.pi / 3.0, -math.pi / 3.0, math.pi)  # rad
# Elbow branch of each finger's inverse kinematics: the elbow bends away from the brick,
# so link 2 reaches its face along the normal and clears the brick's corners.
JOINT_SEEDS = ((-0.5, 1.0), (0.5, -1.0), (0.5, -1.0))
# The task coordinates of a finger: its tip's (normal, tangent) position in frame C.
FINGER_COORDINATES = ("x", "y")
# The force-controlled axis: the face normal, x of C.
NORMAL_AXIS = 0
GRAVITY = 9.81  # m/s^2, Drake's default, along world -z
# With time_step = 0: the sensor noise's sampling period and the logging period, s.
CONTINUOUS_NOISE_PERIOD = 1e-3


def tip_link(finger: str) -> str:
    return f"{finger}_tip_link"


def tip_centre_frame(finger: str) -> str:
    return f"{finger}_tip_centre"


def contact_frame(finger: str) -> str:
    return f"{finger}_contact_frame"


BRICK_BODY = "brick_link"
BRICK_JOINTS = ("brick_translate_y_joint", "brick_translate_z_joint", "brick_revolute_x_joint")


@dataclass
class HandGeometry:
    """What the builder reads from Drake's models and what the plan assumes."""

    # Radius of the fingertip spheres and their centre in the tip link, m.
    tip_radius: float
    tip_offset: np.ndarray
    # The real brick's edges in the hand's plane (world y, world z), m.
    brick_size: np.ndarray
    # The planned brick's edges (real minus brick.size_error), m.
    planned_size: np.ndarray
    # X_WC of each finger's face frame C (origin on the planned face, x its inward normal).
    face_frames: list[RigidTransform]
    # The brick's mass, kg.
    brick_mass: float


@dataclass
class FingerLoop:
    """One finger's systems."""

    name: str
    kinematics: PlanarKinematics
    pid: CartesianPid
    sensor: FlexiForceSensor
    admittance: OptimalAdmittance | None
    plan: TrajectorySource
    force_reference: TrajectorySource


@dataclass
class GraspLoop:
    """A built grasp and handles to its parts."""

    scenario: GraspScenario
    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    geometry: HandGeometry
    fingers: list[FingerLoop]
    contact_sensor: ContactForceSensor
    # The desired force of each finger at t = 0 (what it reads then), N.
    initial_forces: np.ndarray
    random_sources: list[RandomSource] = field(default_factory=list)
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)


def _contact_properties(scenario: GraspScenario) -> ProximityProperties:
    """The point-contact material of every fingertip and of the brick.

    Drake combines two geometries' point stiffnesses in series and their dissipations and
    friction coefficients as weighted means; giving both sides 2 k, d and mu makes the pair's
    stiffness k, dissipation d and friction mu.
    """
    properties = ProximityProperties()
    friction = scenario.contact.friction
    AddContactMaterial(
        dissipation=scenario.contact.dissipation,
        point_stiffness=2.0 * scenario.true_contact_stiffness,
        friction=CoulombFriction(friction, friction),
        properties=properties,
    )
    return properties


def _read_geometry(plant, scene_graph) -> tuple[float, np.ndarray, np.ndarray]:
    """(tip radius, tip sphere centre in the tip link, brick edges in y-z) from the models."""
    inspector = scene_graph.model_inspector()
    radius, offset, size = None, None, None
    tip_frame_id = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(tip_link(FINGERS[0])).index())
    brick_frame_id = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(BRICK_BODY).index())
    for geometry in inspector.GetGeometries(tip_frame_id, Role.kProximity):
        shape = inspector.GetShape(geometry)
        if isinstance(shape, Sphere):
            radius = shape.radius()
            offset = inspector.GetPoseInFrame(geometry).translation()
    for geometry in inspector.GetGeometries(brick_frame_id, Role.kProximity):
        shape = inspector.GetShape(geometry)
        if isinstance(shape, Box):
            size = np.array([shape.depth(), shape.height()])  # along y and z
    if radius is None or size is None:  # pragma: no cover (Drake's models have both)
        raise RuntimeError("the planar gripper model has no tip sphere or no brick box")
    return radius, offset, size


def _face_frames(scenario: GraspScenario, planned_size: np.ndarray) -> list[RigidTransform]:
    """X_WC per finger: origin on the planned face, x its inward normal, y along the face.

    The planned brick's centre is the world origin (where Drake's brick_base is welded).
    """
    half_width, half_height = 0.5 * planned_size
    height = scenario.plan.side_contact_height
    unit_x, unit_y, unit_z = np.eye(3)
    faces = (
        ([0.0, -half_width, height], unit_y, unit_z),  # finger1: left face, normal +y
        ([0.0, half_width, height], -unit_y, unit_z),  # finger2: right face, normal -y
        ([0.0, 0.0, -half_height], unit_z, unit_y),  # finger3: bottom face, normal +z
    )
    frames = []
    for origin, normal, tangent in faces:
        rotation = RotationMatrix(np.column_stack([normal, tangent, np.cross(normal, tangent)]))
        frames.append(RigidTransform(rotation, origin))
    return frames


def AddHand(builder: DiagramBuilder, scenario: GraspScenario):
    """Adds the gripper and the brick as a discrete plant with point contact.

    Returns:
        (plant, scene_graph, geometry), the plant finalized.
    """
    config = MultibodyPlantConfig(
        time_step=scenario.time_step,
        contact_model="point",
        discrete_contact_approximation="lagged" if scenario.time_step > 0 else "",
        stiction_tolerance=scenario.contact.stiction_tolerance,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    parser = Parser(plant)
    parser.AddModelsFromUrl(GRIPPER_URL)
    parser.AddModelsFromUrl(BRICK_URL)
    for finger, angle in zip(FINGERS, BASE_ANGLES, strict=True):
        X_WB = RigidTransform(RotationMatrix.MakeXRotation(angle)) @ RigidTransform(
            [0.0, 0.0, BASE_DISTANCE]
        )
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(f"{finger}_base"), X_WB)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("brick_base"))

    radius, offset, size = _read_geometry(plant, scene_graph)
    planned = size - scenario.brick.size_error
    frames = _face_frames(scenario, planned)
    for finger, X_WC in zip(FINGERS, frames, strict=True):
        plant.AddFrame(
            FixedOffsetFrame(
                tip_centre_frame(finger),
                plant.GetFrameByName(tip_link(finger)),
                RigidTransform(offset),
            )
        )
        plant.AddFrame(FixedOffsetFrame(contact_frame(finger), plant.world_frame(), X_WC))

    # One contact material for every collision geometry of the hand and the brick.
    properties = _contact_properties(scenario)
    inspector = scene_graph.model_inspector()
    for geometry in inspector.GetAllGeometryIds(Role.kProximity):
        scene_graph.AssignRole(plant.get_source_id(), geometry, properties, RoleAssign.kReplace)
    plant.Finalize()
    brick_mass = plant.GetBodyByName(BRICK_BODY).default_mass()
    geometry = HandGeometry(
        tip_radius=radius,
        tip_offset=offset,
        brick_size=size,
        planned_size=planned,
        face_frames=frames,
        brick_mass=brick_mass,
    )
    return plant, scene_graph, geometry


def _initial_forces(scenario: GraspScenario, geometry: HandGeometry) -> np.ndarray:
    """Each finger's normal force at t = 0: the brick's weight on finger3, none on the others."""
    forces = np.zeros(len(FINGERS))
    forces[2] = geometry.brick_mass * GRAVITY
    return forces


def _plan(scenario: GraspScenario, geometry: HandGeometry, index: int) -> PiecewisePolynomial:
    """Xd(t) of a finger in its face frame: close, then press by Fr / k_plan (eq. 6).

    A cubic with zero velocity at t = 0, at the end of closing and at the end of the press.
    """
    plan = scenario.plan
    touching = -geometry.tip_radius
    start = touching - (plan.open_distance if index < 2 else 0.0)
    # The paper's eq. 6 on the planned brick: the face plus Fr / Ke, where the contact as
    # planned presses with Fr (the PID's integral takes the tip there).
    pressed = touching + scenario.force_reference[index] / scenario.contact.stiffness
    breaks = [0.0, plan.close_time, scenario.force_ramp_end]
    samples = np.array([[start, touching, pressed], [0.0, 0.0, 0.0]])
    return PiecewisePolynomial.CubicHermite(breaks, samples, np.zeros_like(samples))


def _force_reference(scenario: GraspScenario, initial_force: float, index: int):
    """Fr_i(t): the force read at t = 0 until the fingers have closed, then a ramp to Fr."""
    breaks = [0.0, scenario.plan.close_time, scenario.force_ramp_end]
    values = [[initial_force, initial_force, scenario.force_reference[index]]]
    return PiecewisePolynomial.FirstOrderHold(breaks, values)


def _AddDisturbance(builder: DiagramBuilder, plant, scenario: GraspScenario) -> None:
    """A force pulse on the brick's centre, as generalized forces on its planar joints."""
    disturbance = scenario.disturbance
    if disturbance.kind != "force_pulse":
        return  # mass_step changes a parameter during the run (grasp_simulation)
    force = np.zeros(plant.num_velocities())
    for joint, value in zip(BRICK_JOINTS[:2], disturbance.force, strict=True):
        force[plant.GetJointByName(joint).velocity_start()] = value
    start, end = disturbance.start, disturbance.start + disturbance.duration
    values = np.column_stack([np.zeros_like(force), force, np.zeros_like(force)])
    pulse = builder.AddSystem(
        TrajectorySource(PiecewisePolynomial.ZeroOrderHold([0.0, start, end], values))
    )
    pulse.set_name("brick_disturbance")
    builder.Connect(pulse.get_output_port(), plant.get_applied_generalized_force_input_port())


def _AddFinger(
    builder: DiagramBuilder,
    scenario: GraspScenario,
    plant,
    geometry: HandGeometry,
    index: int,
    contact_force_port,
    initial_force: float,
    random_sources: list,
) -> FingerLoop:
    """One finger's Fig. 1: plan, FlexiForce, admittance (unless pid_only) and PID."""
    finger = FINGERS[index]
    period = scenario.time_step
    plan = builder.AddSystem(TrajectorySource(_plan(scenario, geometry, index), 1))
    plan.set_name(f"{finger}_plan")
    split = builder.AddSystem(Demultiplexer([2, 2]))
    split.set_name(f"{finger}_plan_split")
    builder.Connect(plan.get_output_port(), split.get_input_port())

    sensor_config = scenario.sensor
    sensor = builder.AddSystem(
        FlexiForceSensor(
            kind=sensor_config.kind, filter_cutoff_hz=sensor_config.filter_cutoff, period=period
        )
        if sensor_config.kind == "flexiforce"
        else FlexiForceSensor(kind="ideal")
    )
    noise_period = period or CONTINUOUS_NOISE_PERIOD
    sensor.set_name(f"{finger}_flexiforce")
    builder.Connect(contact_force_port, sensor.contact_force_input)
    if sensor_config.kind == "flexiforce" and sensor_config.noise_std > 0:
        source = builder.AddSystem(RandomSource(RandomDistribution.kGaussian, 1, noise_period))
        source.set_name(f"{finger}_sensor_noise")
        random_sources.append(source)
        gain = builder.AddSystem(Gain(sensor_config.noise_std, 1))
        gain.set_name(f"{finger}_noise_std")
        builder.Connect(source.get_output_port(0), gain.get_input_port())
        builder.Connect(gain.get_output_port(), sensor.noise_input)
    else:
        zero = builder.AddSystem(ConstantVectorSource([0.0]))
        zero.set_name(f"{finger}_no_noise")
        builder.Connect(zero.get_output_port(), sensor.noise_input)

    # The tip's (x, y) in its face's frame, its rate and Jacobian, once per evaluation.
    kinematics = builder.AddSystem(
        PlanarKinematics(
            plant,
            frame_name=tip_centre_frame(finger),
            coordinates=FINGER_COORDINATES,
            expressed_in=contact_frame(finger),
        )
    )
    kinematics.set_name(f"{finger}_tip_kinematics")
    builder.Connect(plant.get_state_output_port(), kinematics.estimated_state_input)

    pid_config = scenario.pid
    pid = builder.AddSystem(
        CartesianPid(
            plant,
            frame_name=tip_centre_frame(finger),
            kp=pid_config.kp,
            kd=pid_config.kd,
            ki=pid_config.ki,
            period=period,
            coordinates=FINGER_COORDINATES,
            expressed_in=contact_frame(finger),
        )
    )
    pid.set_name(f"{finger}_pid")
    builder.Connect(kinematics.kinematics_output, pid.kinematics_input)
    builder.Connect(split.get_output_port(1), pid.commanded_velocity_input)

    reference = builder.AddSystem(
        TrajectorySource(_force_reference(scenario, initial_force, index))
    )
    reference.set_name(f"{finger}_force_reference")
    admittance = None
    if scenario.controller.kind == "optimal_admittance":
        config = scenario.admittance
        admittance = builder.AddSystem(
            OptimalAdmittance(
                gamma=config.gamma,
                alpha=config.alpha,
                # K of eq. 10: the PID's stiffness on the normal axis (docs/paper-notes.md §4).
                stiffness=pid_config.kp[NORMAL_AXIS],
                force_axes=[NORMAL_AXIS],
                num_axes=len(FINGER_COORDINATES),
                period=period,
                max_push=config.max_push,
                max_retract=config.max_retract,
            )
        )
        admittance.set_name(f"{finger}_admittance")
        builder.Connect(reference.get_output_port(), admittance.desired_force_input)
        builder.Connect(sensor.measured_force_output, admittance.measured_force_input)
        commanded = builder.AddSystem(Adder(2, len(FINGER_COORDINATES)))
        commanded.set_name(f"{finger}_commanded_position")
        builder.Connect(split.get_output_port(0), commanded.get_input_port(0))
        builder.Connect(admittance.reference_offset_output, commanded.get_input_port(1))
        builder.Connect(commanded.get_output_port(), pid.commanded_position_input)
    else:
        builder.Connect(split.get_output_port(0), pid.commanded_position_input)
    return FingerLoop(
        name=finger,
        kinematics=kinematics,
        pid=pid,
        sensor=sensor,
        admittance=admittance,
        plan=plan,
        force_reference=reference,
    )


def BuildGrasp(scenario: GraspScenario) -> GraspLoop:
    """Wires the hand, the brick and one force loop per finger for `scenario`."""
    builder = DiagramBuilder()
    plant, scene_graph, geometry = AddHand(builder, scenario)
    contact_sensor = builder.AddSystem(
        ContactForceSensor(plant, body_pairs=[(tip_link(finger), BRICK_BODY) for finger in FINGERS])
    )
    contact_sensor.set_name("contact_force_sensor")
    builder.Connect(plant.get_contact_results_output_port(), contact_sensor.contact_results_input)
    forces = builder.AddSystem(Demultiplexer(len(FINGERS)))
    forces.set_name("normal_forces")
    builder.Connect(contact_sensor.normal_force_output, forces.get_input_port())

    initial_forces = _initial_forces(scenario, geometry)
    random_sources: list[RandomSource] = []
    fingers = [
        _AddFinger(
            builder,
            scenario,
            plant,
            geometry,
            index,
            forces.get_output_port(index),
            initial_forces[index],
            random_sources,
        )
        for index in range(len(FINGERS))
    ]
    actuation = builder.AddSystem(Adder(len(FINGERS), plant.num_actuated_dofs()))
    actuation.set_name("actuation")
    for index, finger in enumerate(fingers):
        builder.Connect(finger.pid.actuation_output, actuation.get_input_port(index))
    builder.Connect(actuation.get_output_port(), plant.get_actuation_input_port())
    _AddDisturbance(builder, plant, scenario)

    loggers = _AddLoggers(builder, scenario, plant, contact_sensor, fingers, actuation)
    diagram = builder.Build()
    diagram.set_name("grasp_loop")
    return GraspLoop(
        scenario=scenario,
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        geometry=geometry,
        fingers=fingers,
        contact_sensor=contact_sensor,
        initial_forces=initial_forces,
        random_sources=random_sources,
        loggers=loggers,
    )


def _AddLoggers(builder, scenario, plant, contact_sensor, fingers, actuation) -> dict:
    """Loggers of the plant state, the true and measured forces, Fr, Xd, Xr and tau."""
    period = scenario.logging.period or scenario.time_step or CONTINUOUS_NOISE_PERIOD

    def gathered(name: str, ports) -> object:
        mux = builder.AddSystem(Multiplexer([port.size() for port in ports]))
        mux.set_name(f"{name}_of_fingers")
        for index, port in enumerate(ports):
            builder.Connect(port, mux.get_input_port(index))
        return mux.get_output_port()

    ports = {
        "state": plant.get_state_output_port(),
        "contact_force": contact_sensor.normal_force_output,
        "measured_force": gathered(
            "measured_force", [f.sensor.measured_force_output for f in fingers]
        ),
        "force_reference": gathered(
            "force_reference", [f.force_reference.get_output_port() for f in fingers]
        ),
        "plan": gathered("plan", [f.plan.get_output_port() for f in fingers]),
        "actuation": actuation.get_output_port(),
    }
    if all(f.admittance is not None for f in fingers):
        ports["reference_offset"] = gathered(
            "reference_offset", [f.admittance.reference_offset_output for f in fingers]
        )
    loggers = {}
    for name, port in ports.items():
        logger = LogVectorOutput(port, builder, period)
        logger.set_name(f"log_{name}")
        loggers[name] = logger
    return loggers


def _finger_positions(loop: GraspLoop) -> np.ndarray:
    """Finger joint angles at t = 0: sides open by plan.open_distance, finger3 touching."""
    scenario, plant, geometry = loop.scenario, loop.plant, loop.geometry
    q = np.zeros(plant.num_positions())
    for index, finger in enumerate(FINGERS):
        seed = q.copy()
        for joint, angle in zip(("BaseJoint", "MidJoint"), JOINT_SEEDS[index], strict=True):
            seed[plant.GetJointByName(f"{finger}_{joint}").position_start()] = angle
        opening = scenario.plan.open_distance if index < 2 else 0.0
        target = [-geometry.tip_radius - opening, 0.0]
        try:
            q = SolvePlanarInverseKinematics(
                plant,
                tip_centre_frame(finger),
                target,
                seed,
                coordinates=FINGER_COORDINATES,
                expressed_in=contact_frame(finger),
            )
        except ValueError:
            raise ScenarioError(
                f"brick.size_error, plan: {finger} cannot reach its planned face "
                f"(tip at {target[0]:.4g} m from it)"
            ) from None
    return q


def SetGraspInitialConditions(loop: GraspLoop, context: Context) -> None:
    """The brick at rest on finger3, the side fingers open, every finger held by its PID.

    * every random source seeded from `scenario.seed`;
    * the brick on finger3's tip, pressing it by its weight / the real contact stiffness;
    * each PID's integral preloaded so that at zero error it holds its finger against
      gravity (and finger3 under the brick's weight);
    * each FlexiForce's filter at the reading of the force at t = 0, and each admittance
      block's E(0) = Fr(0) - F_measured(0), so that Xr(0) = 0.
    """
    scenario, plant, geometry = loop.scenario, loop.plant, loop.geometry
    loop.diagram.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = _finger_positions(loop)
    weight = geometry.brick_mass * GRAVITY
    resting_depth = weight / scenario.true_contact_stiffness
    half_error = 0.5 * (geometry.brick_size[1] - geometry.planned_size[1])
    brick = dict(zip(BRICK_JOINTS, (0.0, half_error - resting_depth, 0.0), strict=True))
    for name, value in brick.items():
        q[plant.GetJointByName(name).position_start()] = value
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    # Held at rest: tau_pid = -tau_gravity - J_tip^T f_on_tip, with the brick's weight on
    # finger3's tip (world -z). Other fingers' rows are left to their own PIDs.
    state = plant.GetPositionsAndVelocities(plant_context)
    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    holding = -gravity + _weight_on_finger3(plant, plant_context, weight)
    for finger in loop.fingers:
        pid_context = finger.pid.GetMyMutableContextFromRoot(context)
        finger.pid.set_integral(pid_context, finger.pid.holding_integral(state, holding))
    for finger, force in zip(loop.fingers, loop.initial_forces, strict=True):
        if finger.sensor.kind == "flexiforce":
            sensor_context = finger.sensor.GetMyMutableContextFromRoot(context)
            voltage = [finger.sensor.static_output_voltage(force)]
            if finger.sensor.period > 0:
                sensor_context.SetDiscreteState(voltage)
            else:
                sensor_context.SetContinuousState(voltage)
        if finger.admittance is not None:
            measured = finger.sensor.measured_force_output.Eval(
                finger.sensor.GetMyContextFromRoot(context)
            )
            admittance_context = finger.admittance.GetMyMutableContextFromRoot(context)
            finger.admittance.set_initial_force_error(admittance_context, force - measured)


def _weight_on_finger3(plant, plant_context, weight: float) -> np.ndarray:
    """Generalized force J_tip^T f that finger3 must supply to carry `weight` up (world +z)."""
    J_tip = plant.CalcJacobianTranslationalVelocity(
        plant_context,
        JacobianWrtVariable.kV,
        plant.GetFrameByName(tip_centre_frame(FINGERS[2])),
        np.zeros(3),
        plant.world_frame(),
        plant.world_frame(),
    )
    return J_tip.T @ np.array([0.0, 0.0, weight])
