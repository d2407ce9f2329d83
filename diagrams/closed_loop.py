"""The paper's Fig. 1 as a Drake Diagram: arm, wall, sensor, optimal admittance and PID.

Xd --(+)--> Xc --> CartesianPid --tau--> plant --state--> CompliantWall --F--> sensor
      ^ Xr                                  ^  spatial force |                    |
      +------- OptimalAdmittance <-- Fm ----+----------------+--------------------+
                      ^ Fr
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    ConstantVectorSource,
    Gain,
    LogVectorOutput,
    RandomSource,
    VectorLogSink,
)

from admittance.diagrams.force_controllers import WALL_NORMAL_AXIS, AddForceController
from admittance.diagrams.safety import AddSafetyLayer, SafetyLayer
from admittance.diagrams.scenario import Scenario, ScenarioError
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.compliant_wall import CompliantWall
from admittance.systems.desired_trajectory import DesiredTrajectory
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.planar_kinematics import PlanarFrameKinematics
from admittance.systems.sensor_fault import SensorFault

__all__ = [
    "ClosedLoop",
    "AddPlanarArm",
    "BuildClosedLoop",
    "SetInitialConditions",
    "SolvePlanarInverseKinematics",
]

GRAVITY_W = np.array([0.0, -9.81, 0.0])


@dataclass
class ClosedLoop:
    """A built closed loop and handles to its parts."""

    scenario: Scenario
    diagram: Diagram
    plant: MultibodyPlant
    trajectory: DesiredTrajectory
    pid: CartesianPid
    wall: CompliantWall
    sensor: FlexiForceSensor
    # The force controller of scenario.controller_kind (None for pid_only).
    admittance: object | None
    random_sources: list[RandomSource] = field(default_factory=list)
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)
    scene_graph: object | None = None


def AddPlanarArm(builder: DiagramBuilder, scenario: Scenario):
    """Adds the arm of `scenario.arm` as a continuous MultibodyPlant, gravity along -y.

    Returns:
        (plant, scene_graph), the plant finalized.
    """
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    Parser(plant).AddModels(str(scenario.urdf_path()))
    plant.mutable_gravity_field().set_gravity_vector(GRAVITY_W)
    if not scenario.arm.reflected_inertia:
        for index in plant.GetJointActuatorIndices():
            plant.get_mutable_joint_actuator(index).set_default_rotor_inertia(0.0)
    plant.Finalize()
    if not plant.HasFrameNamed(scenario.arm.fingertip_frame):
        raise ScenarioError(
            f"arm.fingertip_frame: the URDF has no frame named '{scenario.arm.fingertip_frame}'"
        )
    return plant, scene_graph


def _stiffness_schedule(scenario: Scenario) -> list[tuple[float, float]]:
    """Ke steps of the scenario, with each stiffness_jump fault as a step and a step back."""
    steps = sorted((s.time, s.stiffness) for s in scenario.wall.stiffness_steps)

    def scheduled(time: float) -> float:
        value = scenario.wall.stiffness
        for step_time, stiffness in steps:
            if step_time <= time:
                value = stiffness
        return value

    for fault in (f for f in scenario.faults if f.kind == "stiffness_jump"):
        after = scheduled(fault.end)
        steps = [step for step in steps if not fault.start <= step[0] < fault.end]
        steps = sorted(steps + [(fault.start, fault.value), (fault.end, after)])
    return steps


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
    plant, scene_graph = AddPlanarArm(builder, scenario)
    frame = scenario.arm.fingertip_frame

    trajectory = builder.AddSystem(
        DesiredTrajectory(
            center=scenario.trajectory.center,
            amplitude=scenario.trajectory.amplitude,
            frequency=scenario.trajectory.frequency,
        )
    )
    trajectory.set_name("desired_trajectory")

    wall_config = scenario.wall
    wall = builder.AddSystem(
        CompliantWall(
            plant,
            frame_name=frame,
            position=wall_config.position,
            stiffness=wall_config.stiffness,
            stiffness_steps=_stiffness_schedule(scenario),
            velocity=wall_config.velocity,
            motion_start=wall_config.motion_start,
            motion_end=wall_config.motion_end,
            position_offsets=[
                (f.start, f.end, f.value) for f in scenario.faults if f.kind == "wall_retract"
            ],
        )
    )
    wall.set_name("compliant_wall")
    builder.Connect(plant.get_state_output_port(), wall.estimated_state_input)
    builder.Connect(wall.applied_spatial_force_output, plant.get_applied_spatial_force_input_port())

    sensor_config = scenario.sensor
    sensor = builder.AddSystem(
        FlexiForceSensor(kind=sensor_config.kind, filter_cutoff_hz=sensor_config.filter_cutoff)
    )
    sensor.set_name("flexiforce_sensor")
    builder.Connect(wall.contact_force_output, sensor.contact_force_input)
    measured_force_output = sensor.measured_force_output
    sensor_faults = [
        (f.kind, f.start, f.end, f.value) for f in scenario.faults if f.kind.startswith("sensor_")
    ]
    if sensor_faults:
        fault = builder.AddSystem(SensorFault(sensor_faults))
        fault.set_name("sensor_fault")
        builder.Connect(sensor.measured_force_output, fault.measured_force_input)
        measured_force_output = fault.reported_force_output
    random_sources = []
    noisy = sensor_config.kind != "ideal" and sensor_config.noise_std > 0 and not analysis
    if noisy:
        source = builder.AddSystem(
            RandomSource(RandomDistribution.kGaussian, 1, sensor_config.noise_period)
        )
        source.set_name("sensor_noise")
        random_sources.append(source)
        gain = builder.AddSystem(Gain(sensor_config.noise_std, 1))
        gain.set_name("noise_std")
        builder.Connect(source.get_output_port(0), gain.get_input_port())
        builder.Connect(gain.get_output_port(), sensor.noise_input)
    else:
        zero = builder.AddSystem(ConstantVectorSource([0.0]))
        zero.set_name("no_noise")
        builder.Connect(zero.get_output_port(), sensor.noise_input)

    pid_config = scenario.pid
    pid = builder.AddSystem(
        CartesianPid(
            plant,
            frame_name=frame,
            kp=pid_config.kp,
            kd=pid_config.kd,
            ki=pid_config.ki,
            period=pid_config.period,
        )
    )
    pid.set_name("cartesian_pid")
    builder.Connect(plant.get_state_output_port(), pid.estimated_state_input)
    builder.Connect(pid.actuation_output, plant.get_actuation_input_port())
    builder.Connect(trajectory.desired_velocity_output, pid.commanded_velocity_input)

    admittance = None
    if open_admittance_loop:
        if not analysis:
            raise ValueError("open_admittance_loop is for analysis diagrams only")
        commanded = builder.AddSystem(Adder(2, 3))
        commanded.set_name("commanded_position")
        builder.Connect(trajectory.desired_position_output, commanded.get_input_port(0))
        builder.ExportInput(commanded.get_input_port(1), "reference_offset")
        builder.Connect(commanded.get_output_port(), pid.commanded_position_input)
    elif scenario.safety.enabled:
        admittance = AddSafetyLayer(
            builder, scenario, plant=plant, pid=pid, trajectory=trajectory, analysis=analysis
        )
    else:
        admittance = AddForceController(builder, scenario)
    if admittance is not None:
        if analysis:
            # Fr is an input of the analysis diagram (fix it in the context), so that the
            # linear model has Fr -> contact force.
            builder.ExportInput(admittance.desired_force_input, "force_reference")
        else:
            force_reference = builder.AddSystem(ConstantVectorSource([scenario.force_reference]))
            force_reference.set_name("force_reference")
            builder.Connect(force_reference.get_output_port(), admittance.desired_force_input)
        builder.Connect(measured_force_output, admittance.measured_force_input)
        if hasattr(admittance, "desired_position_input"):  # eq. 6 subtracts Xd
            builder.Connect(trajectory.desired_position_output, admittance.desired_position_input)
        commanded = builder.AddSystem(Adder(2, 3))
        commanded.set_name("commanded_position")
        builder.Connect(trajectory.desired_position_output, commanded.get_input_port(0))
        builder.Connect(admittance.reference_offset_output, commanded.get_input_port(1))
        builder.Connect(commanded.get_output_port(), pid.commanded_position_input)
    elif not open_admittance_loop:
        builder.Connect(trajectory.desired_position_output, pid.commanded_position_input)

    loggers = {}
    if analysis:
        builder.ExportOutput(wall.contact_force_output, "contact_force")
        builder.ExportOutput(measured_force_output, "measured_force")
    else:
        period = scenario.logging.period
        ports = {
            "state": plant.get_state_output_port(),
            "contact_force": wall.contact_force_output,
            "measured_force": measured_force_output,
            "actuation": pid.actuation_output,
            "desired_position": trajectory.desired_position_output,
        }
        if admittance is not None:
            ports["reference_offset"] = admittance.reference_offset_output
        if isinstance(admittance, SafetyLayer):
            ports.update(admittance.log_ports())
        for name, port in ports.items():
            logger = LogVectorOutput(port, builder, period)
            logger.set_name(f"log_{name}")
            loggers[name] = logger

    diagram = builder.Build()
    diagram.set_name("optimal_admittance_loop")
    return ClosedLoop(
        scenario=scenario,
        diagram=diagram,
        plant=plant,
        trajectory=trajectory,
        pid=pid,
        wall=wall,
        sensor=sensor,
        admittance=admittance,
        random_sources=random_sources,
        loggers=loggers,
        scene_graph=scene_graph,
    )


def SolvePlanarInverseKinematics(
    plant: MultibodyPlant,
    frame_name: str,
    target,
    joint_guess,
    *,
    tolerance: float = 1e-10,
    max_iterations: int = 100,
) -> np.ndarray:
    """Joint positions that put `frame_name` at X = target, by Newton steps from a seed.

    Uses the plant's own kinematics (so any planar URDF works); the seed picks the branch.

    Raises:
        ValueError: the target is not reached (out of the workspace, or singular).
    """
    kinematics = PlanarFrameKinematics(plant, frame_name)
    target = np.asarray(target, dtype=float)
    q = np.zeros(plant.num_positions())
    guess = np.asarray(joint_guess, dtype=float)
    q[: min(q.size, guess.size)] = guess[: q.size]
    v = np.zeros(plant.num_velocities())
    for _ in range(max_iterations):
        kinematics.set_state(np.concatenate([q, v]))
        error = target - kinematics.pose()
        error[2] = np.arctan2(np.sin(error[2]), np.cos(error[2]))
        if np.linalg.norm(error) < tolerance:
            return q
        step = np.linalg.lstsq(kinematics.jacobian(), error, rcond=None)[0]
        # Limit each Newton step so that a far seed does not jump branches.
        q = q + step * min(1.0, 0.5 / max(np.max(np.abs(step)), 1e-12))
    raise ValueError(f"the pose {target.tolist()} is not reachable from the seed {guess.tolist()}")


def CheckTrajectoryReachable(loop: ClosedLoop, samples: int = 16) -> None:
    """Rejects a desired trajectory the arm cannot reach, naming the point.

    Samples Xd over one period of eq. 19 (and the pose pushed to the wall surface, which
    the admittance block may ask for) and solves the inverse kinematics of each.

    Raises:
        ScenarioError: `trajectory.center` / `trajectory.amplitude` with the first point
            out of reach.
    """
    scenario = loop.scenario
    frequency = scenario.trajectory.frequency
    period = 1.0 / frequency if frequency > 0 else 0.0
    seed = scenario.arm.joint_guess
    for k in range(samples if period > 0 else 1):
        point = loop.trajectory.position_at(k * period / samples)
        try:
            seed = SolvePlanarInverseKinematics(
                loop.plant, scenario.arm.fingertip_frame, point, seed
            )
        except ValueError:
            where = ", ".join(f"{v:.4g}" for v in point)
            raise ScenarioError(
                f"trajectory.center, trajectory.amplitude: the desired point ({where}) is out "
                "of the arm's reach"
            ) from None


def _check_force_within_effort_limits(loop: ClosedLoop, plant_context, gravity) -> None:
    """Rejects a force reference the arm's actuators cannot hold at the initial pose.

    Static balance at rest: tau = J^T [Fr, 0, 0] - tau_gravity must stay within the URDF's
    effort limits, or the PID saturates and Fr is never reached.
    """
    scenario = loop.scenario
    kinematics = PlanarFrameKinematics(loop.plant, scenario.arm.fingertip_frame)
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
            plant, scenario.arm.fingertip_frame, target, scenario.arm.joint_guess
        )
    except ValueError as error:
        key = "arm.initial_position" if scenario.arm.initial_position else "trajectory.center"
        raise ScenarioError(f"{key}: {error}") from None
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, q0)
    plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    _check_force_within_effort_limits(loop, plant_context, gravity)
    state = plant.GetPositionsAndVelocities(plant_context)
    pid_context = loop.pid.GetMyMutableContextFromRoot(context)
    if np.all(loop.pid.gains["ki"] > 0):
        loop.pid.set_integral(pid_context, loop.pid.holding_integral(state, -gravity))

    if isinstance(loop.admittance, SafetyLayer):
        loop.admittance.initialize(context)
    elif hasattr(loop.admittance, "set_initial_force_error"):
        measured = loop.sensor.measured_force_output.Eval(loop.sensor.GetMyContextFromRoot(context))
        admittance_context = loop.admittance.GetMyMutableContextFromRoot(context)
        loop.admittance.set_initial_force_error(
            admittance_context, np.array([scenario.force_reference]) - measured
        )
