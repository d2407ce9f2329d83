"""The paper's Fig. 1 as a Drake Diagram: arm, wall, sensor, optimal admittance and PID.

Xd --(+)--> Xc --> CartesianPid --tau--> plant --state--> PlanarKinematics
      ^ Xr              ^ X, dX/dt, J      ^ -F J_x^T           | X, dX/dt, J
      |                 +------------------|--------------------+
      |                                CompliantWall <----------+
      +------- OptimalAdmittance <-- Fm -- sensor <-- F --+
                      ^ Fr

The fingertip's kinematics are computed once per evaluation and read by the PID and the
wall; the wall's force reaches the plant as generalized forces (the force at the fingertip
through the Jacobian's x row); with the ideal sensor (the paper's simulation) Fm is the
wall's F itself. The arm is one force-controlled point (robots.planar_arm.fingertip_point),
wired by the steps every robot shares (loop.point); what is the arm's own here is the plan
of eq. 19, the wall, the safety layer, and the checks that the arm can start.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    RandomSource,
    VectorLogSink,
)

from admittance.diagrams.loop.point import (
    AddCommandedPosition,
    AddForceController,
    AddLoggers,
    AddPointKinematics,
    AddPointPid,
    AddSensorChain,
)
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.plant import (
    WALL_NORMAL_AXIS,
    AddScenarioArm,
    fingertip_point,
)
from admittance.diagrams.robots.planar_arm.safety_layer import AddSafetyLayer, SafetyLayer
from admittance.diagrams.robots.planar_arm.scenario import Scenario, TrajectoryConfig, WallConfig
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.diagrams.scenario.sections import FaultConfig
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.compliant_wall import CompliantWall
from admittance.systems.desired_trajectory import DesiredTrajectory
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.joint_torque_fault import JointTorqueFault
from admittance.systems.planar_kinematics import (
    PLANAR_COORDINATES,
    PlanarFrameKinematics,
    PlanarKinematics,
)

__all__ = [
    "BuildClosedLoop",
    "CheckScenarioStarts",
    "CheckTrajectoryReachable",
    "ClosedLoop",
    "SetInitialConditions",
]


@dataclass
class ClosedLoop:
    """A built closed loop and handles to its parts."""

    scenario: Scenario
    diagram: Diagram
    plant: MultibodyPlant
    trajectory: DesiredTrajectory
    pid: CartesianPid
    wall: CompliantWall
    # The FlexiForce chain (None for the ideal sensor, whose reading is the true force).
    sensor: FlexiForceSensor | None
    # X, dX/dt and J of the fingertip, read by the PID and the wall.
    kinematics: PlanarKinematics
    # The force controller of scenario.controller_kind (None for pid_only).
    admittance: object | None
    random_sources: list[RandomSource] = field(default_factory=list)
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)
    scene_graph: object | None = None


def _stiffness_schedule(wall: WallConfig, faults: list[FaultConfig]) -> list[tuple[float, float]]:
    """Ke steps of the wall, with each stiffness_jump fault as a step and a step back."""
    steps = sorted((s.time, s.stiffness) for s in wall.stiffness_steps)

    def scheduled(time: float) -> float:
        value = wall.stiffness
        for step_time, stiffness in steps:
            if step_time <= time:
                value = stiffness
        return value

    for fault in (f for f in faults if f.kind == "stiffness_jump"):
        after = scheduled(fault.end)
        steps = [step for step in steps if not fault.start <= step[0] < fault.end]
        steps = sorted(steps + [(fault.start, fault.value), (fault.end, after)])
    return steps


def _AddDesiredTrajectory(builder: DiagramBuilder, trajectory: TrajectoryConfig):
    """Xd of eq. 19."""
    system = builder.AddSystem(
        DesiredTrajectory(
            center=trajectory.center,
            amplitude=trajectory.amplitude,
            frequency=trajectory.frequency,
        )
    )
    system.set_name("desired_trajectory")
    return system


def _AddWall(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    kinematics: PlanarKinematics,
    wall: WallConfig,
    faults: list[FaultConfig],
) -> CompliantWall:
    """The wall of eq. 4, pushing on the fingertip; with its faults (a retract, a jump of Ke),
    and the joint_torque faults' torques summed with its generalized force."""
    system = builder.AddSystem(
        CompliantWall(
            plant,
            frame_name=kinematics.frame_name,
            coordinates=kinematics.coordinates,
            position=wall.position,
            stiffness=wall.stiffness,
            stiffness_steps=_stiffness_schedule(wall, faults),
            velocity=wall.velocity,
            motion_start=wall.motion_start,
            motion_end=wall.motion_end,
            position_offsets=[
                (f.start, f.end, f.value) for f in faults if f.kind == "wall_retract"
            ],
        )
    )
    system.set_name("compliant_wall")
    builder.Connect(kinematics.kinematics_output, system.kinematics_input)
    generalized_force = system.generalized_force_output
    collisions = [(f.start, f.end, f.value, f.joint) for f in faults if f.kind == "joint_torque"]
    if collisions:
        # A link hitting something: its torque summed with the wall's.
        collision = builder.AddSystem(JointTorqueFault(plant.num_velocities(), collisions))
        collision.set_name("joint_torque_fault")
        builder.Connect(generalized_force, collision.generalized_force_input)
        generalized_force = collision.generalized_force_output
    builder.Connect(generalized_force, plant.get_applied_generalized_force_input_port())
    return system


def _AddForceLoop(
    builder: DiagramBuilder,
    scenario: Scenario,
    point: ForcePoint,
    trajectory: DesiredTrajectory,
    pid: CartesianPid,
    measured_force_output,
    *,
    analysis: bool,
    open_admittance_loop: bool,
    plant: MultibodyPlant,
):
    """The force controller of scenario.controller_kind (its gains come from several
    sections: the admittance, the controller, the PID's Kp, the wall), closing Xr into Xc.

    Returns:
        the force controller, or None (pid_only, or the admittance loop left open).
    """
    if open_admittance_loop:
        if not analysis:
            raise ValueError("open_admittance_loop is for analysis diagrams only")
        commanded = AddCommandedPosition(builder, point, trajectory.desired_position_output, pid)
        builder.ExportInput(commanded.get_input_port(1), "reference_offset")
        return None
    if scenario.safety.enabled:
        controller = AddSafetyLayer(
            builder, scenario, plant=plant, pid=pid, trajectory=trajectory, analysis=analysis
        )
    else:
        controller = AddForceController(builder, point)
    if controller is None:
        builder.Connect(trajectory.desired_position_output, pid.commanded_position_input)
        return None
    if analysis:
        # Fr is an input of the analysis diagram (fix it in the context), so that the
        # linear model has Fr -> contact force.
        builder.ExportInput(controller.desired_force_input, "force_reference")
    else:
        force_reference = builder.AddSystem(ConstantVectorSource([scenario.force_reference]))
        force_reference.set_name("force_reference")
        builder.Connect(force_reference.get_output_port(), controller.desired_force_input)
    builder.Connect(measured_force_output, controller.measured_force_input)
    if hasattr(controller, "desired_position_input"):  # eq. 6 subtracts Xd
        builder.Connect(trajectory.desired_position_output, controller.desired_position_input)
    commanded = AddCommandedPosition(builder, point, trajectory.desired_position_output, pid)
    builder.Connect(controller.reference_offset_output, commanded.get_input_port(1))
    return controller


def BuildClosedLoop(
    scenario: Scenario, *, analysis: bool = False, open_admittance_loop: bool = False
) -> ClosedLoop:
    """Wires the paper's Fig. 1 for `scenario`.

    Args:
        scenario: a validated scenario.
        analysis: build for Linearize: no random source (the noise input is held at zero)
            and no loggers, so that every system converts to AutoDiffXd; Fr is the
            diagram's input `force_reference` and the true and measured forces are its
            outputs `contact_force` and `measured_force`.
        open_admittance_loop: (analysis only) leave the admittance block out and export the
            commanded position's offset input as `reference_offset`: the loop the
            admittance block closes, for the analysis of a sampled admittance block.
    """
    builder = DiagramBuilder()
    point = fingertip_point(scenario)
    plant, scene_graph = AddScenarioArm(builder, scenario.arm)
    trajectory = _AddDesiredTrajectory(builder, scenario.trajectory)
    kinematics = AddPointKinematics(builder, plant, point)
    wall = _AddWall(builder, plant, kinematics, scenario.wall, scenario.faults)
    reading = AddSensorChain(builder, point, wall.contact_force_output, noise=not analysis)
    measured_force_output = reading.measured_force_output
    pid = AddPointPid(builder, plant, point, kinematics, trajectory.desired_velocity_output)
    builder.Connect(pid.actuation_output, plant.get_actuation_input_port())
    controller = _AddForceLoop(
        builder,
        scenario,
        point,
        trajectory,
        pid,
        measured_force_output,
        analysis=analysis,
        open_admittance_loop=open_admittance_loop,
        plant=plant,
    )
    loggers = {}
    if analysis:
        builder.ExportOutput(wall.contact_force_output, "contact_force")
        builder.ExportOutput(measured_force_output, "measured_force")
    else:
        ports = {
            "state": plant.get_state_output_port(),
            "contact_force": wall.contact_force_output,
            "measured_force": measured_force_output,
            "actuation": pid.actuation_output,
            "desired_position": trajectory.desired_position_output,
        }
        if controller is not None:
            ports["reference_offset"] = controller.reference_offset_output
        if isinstance(controller, SafetyLayer):
            ports.update(controller.log_ports())
        loggers = AddLoggers(builder, ports, scenario.logging.period)

    diagram = builder.Build()
    diagram.set_name("optimal_admittance_loop")
    return ClosedLoop(
        scenario=scenario,
        diagram=diagram,
        plant=plant,
        trajectory=trajectory,
        pid=pid,
        wall=wall,
        sensor=reading.sensor,
        kinematics=kinematics,
        admittance=controller,
        random_sources=reading.random_sources,
        loggers=loggers,
        scene_graph=scene_graph,
    )


def _joint_speeds(loop: ClosedLoop, positions: np.ndarray, cartesian_velocity) -> np.ndarray:
    """Joint speeds that move the fingertip at `cartesian_velocity` (x, y, theta) from q."""
    kinematics = PlanarFrameKinematics(
        loop.plant, loop.scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    kinematics.set_state(np.concatenate([positions, np.zeros(loop.plant.num_velocities())]))
    return np.linalg.lstsq(kinematics.jacobian(), np.asarray(cartesian_velocity), rcond=None)[0]


def _beyond_velocity_limits(loop: ClosedLoop, speeds: np.ndarray) -> str | None:
    """None, or the words of a message naming the speeds and the URDF's limits."""
    limits = loop.plant.GetVelocityUpperLimits()
    if np.all(np.abs(speeds) <= limits):
        return None
    needed = ", ".join(f"{abs(v):.3g}" for v in speeds)
    allowed = ", ".join(f"{v:.3g}" for v in limits)
    return f"joint speeds ({needed}) rad/s, beyond the URDF's velocity limits ({allowed}) rad/s"


def CheckTrajectoryReachable(loop: ClosedLoop, samples: int = 16) -> None:
    """Rejects a desired trajectory the arm cannot reach or cannot follow, naming the point.

    Samples Xd over one period of eq. 19 and solves the inverse kinematics of each point;
    at each, the joint speeds that follow dXd/dt must stay within the URDF's velocity
    limits (an arm cannot follow a faster plan, and the integrator would crawl after it).

    Raises:
        ScenarioError: `trajectory.center` / `trajectory.amplitude` with the first point
            out of reach; `trajectory.frequency` / `trajectory.amplitude` with the first
            point too fast.
    """
    scenario = loop.scenario
    frequency = scenario.trajectory.frequency
    period = 1.0 / frequency if frequency > 0 else 0.0
    seed = scenario.arm.joint_guess
    for k in range(samples if period > 0 else 1):
        time = k * period / samples
        point = loop.trajectory.position_at(time)
        where = ", ".join(f"{v:.4g}" for v in point)
        try:
            seed = SolvePlanarInverseKinematics(
                loop.plant,
                scenario.arm.fingertip_frame,
                point,
                seed,
                coordinates=PLANAR_COORDINATES,
            )
        except ValueError:
            raise ScenarioError(
                f"trajectory.center, trajectory.amplitude: the desired point ({where}) is out "
                "of the arm's reach"
            ) from None
        too_fast = _beyond_velocity_limits(
            loop, _joint_speeds(loop, seed, loop.trajectory.velocity_at(time))
        )
        if too_fast:
            raise ScenarioError(
                f"trajectory.frequency, trajectory.amplitude: following the desired motion "
                f"at ({where}) needs {too_fast}"
            )


def _check_wall_speed_within_velocity_limits(loop: ClosedLoop, plant_context) -> None:
    """Rejects a wall that moves faster than the arm can follow from its initial pose."""
    wall = loop.scenario.wall
    if wall.velocity == 0.0 or wall.motion_start >= loop.scenario.duration:
        return
    push = np.zeros(3)
    push[WALL_NORMAL_AXIS] = wall.velocity
    positions = loop.plant.GetPositions(plant_context)
    too_fast = _beyond_velocity_limits(loop, _joint_speeds(loop, positions, push))
    if too_fast:
        raise ScenarioError(
            f"wall.velocity: following the wall at {wall.velocity:g} m/s from the initial pose "
            f"needs {too_fast}"
        )


def _check_force_within_effort_limits(loop: ClosedLoop, plant_context, gravity) -> None:
    """Rejects a force reference the arm's actuators cannot hold at the initial pose.

    Static balance at rest: tau = J^T [Fr, 0, 0] - tau_gravity must stay within the URDF's
    effort limits, or the PID saturates and Fr is never reached.
    """
    scenario = loop.scenario
    kinematics = PlanarFrameKinematics(
        loop.plant, scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    kinematics.set_state(loop.plant.GetPositionsAndVelocities(plant_context))
    push = np.zeros(3)
    push[WALL_NORMAL_AXIS] = scenario.force_reference
    torque = kinematics.jacobian().T @ push - gravity
    limits = loop.pid.effort_limits
    if np.any(np.abs(torque) > limits):
        needed = ", ".join(f"{abs(t):.3g}" for t in torque)
        allowed = ", ".join(f"{limit:.3g}" for limit in limits)
        raise ScenarioError(
            f"force_reference: {scenario.force_reference:g} N needs joint torques ({needed}) N m "
            f"at the initial pose, beyond the URDF's effort limits ({allowed}) N m"
        )


def SetInitialConditions(loop: ClosedLoop, context: Context) -> None:
    """The arm at rest at the scenario's initial pose, held against gravity by its PID.

    * every random source seeded from `scenario.seed` (the rest of the context is reset to
      its defaults);
    * q from the inverse kinematics of `arm.initial_position` (default Xd(0)), v = 0;
    * the PID integral preloaded so that, at zero error, it cancels gravity (a robot that
      was holding its pose before the run starts);
    * the admittance block's E(0) set to Fr - F_measured(0), so that Xr(0) = 0.
    """
    scenario = loop.scenario
    plant = loop.plant
    CheckTrajectoryReachable(loop)
    loop.diagram.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
    if loop.diagram.num_input_ports() > 0:  # the analysis diagram: Fr is an input
        loop.diagram.get_input_port(0).FixValue(context, [scenario.force_reference])
    target = list(scenario.arm.initial_position)
    if not target:
        # Xd(0), but never inside the wall: a desired point behind the wall surface starts
        # the tip touching the undeformed wall, with zero force.
        target = list(loop.trajectory.position_at(0.0))
        target[WALL_NORMAL_AXIS] = min(target[WALL_NORMAL_AXIS], loop.wall.position_at(0.0))
    try:
        q0 = SolvePlanarInverseKinematics(
            plant,
            scenario.arm.fingertip_frame,
            target,
            scenario.arm.joint_guess,
            coordinates=PLANAR_COORDINATES,
        )
    except ValueError as error:
        key = "arm.initial_position" if scenario.arm.initial_position else "trajectory.center"
        raise ScenarioError(f"{key}: {error}") from None
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, q0)
    plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    _check_force_within_effort_limits(loop, plant_context, gravity)
    _check_wall_speed_within_velocity_limits(loop, plant_context)
    state = plant.GetPositionsAndVelocities(plant_context)
    pid_context = loop.pid.GetMyMutableContextFromRoot(context)
    if np.all(loop.pid.gains["ki"] > 0):
        loop.pid.set_integral(pid_context, loop.pid.holding_integral(state, -gravity))

    if isinstance(loop.admittance, SafetyLayer):
        loop.admittance.initialize(context)
    elif hasattr(loop.admittance, "set_initial_force_error"):
        # The reading before any injected sensor fault: the sensor's, or the true force.
        reading = (
            loop.wall.contact_force_output
            if loop.sensor is None
            else loop.sensor.measured_force_output
        )
        measured = reading.Eval(reading.get_system().GetMyContextFromRoot(context))
        admittance_context = loop.admittance.GetMyMutableContextFromRoot(context)
        loop.admittance.set_initial_force_error(
            admittance_context, np.array([scenario.force_reference]) - measured
        )


def CheckScenarioStarts(scenario: Scenario) -> None:
    """Raises ScenarioError if `scenario` cannot start: a pose or a plan out of reach, a
    plan or a wall faster than the joints' velocity limits, a force beyond their efforts.

    The checks of SetInitialConditions, on a loop built for them alone: for commands that
    would otherwise find out only after their first stage.
    """
    loop = BuildClosedLoop(scenario)
    SetInitialConditions(loop, loop.diagram.CreateDefaultContext())
