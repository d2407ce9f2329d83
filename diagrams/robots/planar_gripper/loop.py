"""The grasp's loop: one force loop per finger of Drake's planar gripper, as a Diagram.

For each finger: its plan (Xd and Fr over time, in a frame at its planned face), the
contact engine's normal force read by a (sampled) FlexiForce, the paper's admittance law
(eq. 10) and a task-space PID on the tip's 2-D position (eq. 14-16). The hand itself
(plant, brick, contact properties, face frames) is the package's :mod:`.plant`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.multibody.plant import (
    MultibodyPlant,
)
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    Demultiplexer,
    Multiplexer,
    RandomSource,
    TrajectorySource,
    VectorLogSink,
)
from pydrake.trajectories import PiecewisePolynomial

from admittance.diagrams.loop.point import (
    AddForceLoop,
    AddLoggers,
    AddPointKinematics,
    AddPointPid,
    AddSensorChain,
)
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_gripper.plant import (
    BRICK_BODY,
    BRICK_JOINTS,
    CONTINUOUS_NOISE_PERIOD,
    FINGER_COORDINATES,
    GRAVITY,
    JOINT_SEEDS,
    AddHand,
    HandGeometry,
    contact_frame,
    finger_points,
    tip_centre_frame,
    tip_link,
)
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GraspScenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.contact_force_sensor import ContactForceSensor
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.optimal_admittance import OptimalAdmittance
from admittance.systems.planar_kinematics import PlanarKinematics

__all__ = [
    "BuildGrasp",
    "FingerLoop",
    "GraspLoop",
    "SetGraspInitialConditions",
]


@dataclass
class FingerLoop:
    """One finger's systems."""

    name: str
    kinematics: PlanarKinematics
    pid: CartesianPid
    # The FlexiForce (None for the ideal sensor, whose reading is the contact force).
    sensor: FlexiForceSensor | None
    measured_force_output: object
    admittance: OptimalAdmittance | None
    plan: TrajectorySource
    force_reference: TrajectorySource
    random_sources: list[RandomSource] = field(default_factory=list)


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
        return  # mass_step changes a parameter during the run (robots.planar_gripper.run)
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
    point: ForcePoint,
    index: int,
    contact_force_port,
    initial_force: float,
) -> FingerLoop:
    """One finger's Fig. 1: its plan, then the steps every point shares (sensor chain,
    kinematics, PID, the paper's law unless pid_only)."""
    plan = builder.AddSystem(TrajectorySource(_plan(scenario, geometry, index), 1))
    plan.set_name(point.system_name("plan"))
    split = builder.AddSystem(Demultiplexer([2, 2]))
    split.set_name(point.system_name("plan_split"))
    builder.Connect(plan.get_output_port(), split.get_input_port())
    reading = AddSensorChain(builder, point, contact_force_port)
    kinematics = AddPointKinematics(builder, plant, point)
    pid = AddPointPid(builder, plant, point, kinematics, split.get_output_port(1))
    reference = builder.AddSystem(
        TrajectorySource(_force_reference(scenario, initial_force, index))
    )
    reference.set_name(point.system_name("force_reference"))
    admittance = AddForceLoop(
        builder,
        point,
        pid,
        desired_position_output=split.get_output_port(0),
        desired_force_output=reference.get_output_port(),
        measured_force_output=reading.measured_force_output,
    )
    return FingerLoop(
        name=point.name,
        kinematics=kinematics,
        pid=pid,
        sensor=reading.sensor,
        measured_force_output=reading.measured_force_output,
        admittance=admittance,
        plan=plan,
        force_reference=reference,
        random_sources=reading.random_sources,
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
    fingers = [
        _AddFinger(
            builder,
            scenario,
            plant,
            geometry,
            point,
            index,
            forces.get_output_port(index),
            initial_forces[index],
        )
        for index, point in enumerate(finger_points(scenario))
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
        random_sources=[source for f in fingers for source in f.random_sources],
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
        "measured_force": gathered("measured_force", [f.measured_force_output for f in fingers]),
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
    return AddLoggers(builder, ports, period)


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
        if finger.sensor is not None:
            sensor_context = finger.sensor.GetMyMutableContextFromRoot(context)
            voltage = [finger.sensor.static_output_voltage(force)]
            if finger.sensor.period > 0:
                sensor_context.SetDiscreteState(voltage)
            else:
                sensor_context.SetContinuousState(voltage)
        if finger.admittance is not None:
            port = finger.measured_force_output
            measured = port.Eval(port.get_system().GetMyContextFromRoot(context))
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
