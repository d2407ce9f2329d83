"""The spatial arm's loop: a real arm's tool pressing and sliding on a table, as a Diagram.

    Xd --(+)--> Xc --> CartesianPid (6-D, + g(q), + posture) --tau--> plant --state--+
          ^ Xr            ^ X, dX/dt, J (tool tip in E)                            |
          |               +-------------- kinematics <---------------------------+
          +---- force law <-- Fm -- sensor <-- F (along E's z) <-- contact results
                    ^ Fr(t)

One force-controlled point (robots.spatial_arm.spatial_point): the tool tip, X = (x, y, z,
rx, ry, rz) in the control frame E at the planned surface point, the force along z (into
the table), wired by the steps every robot shares (loop.point). What is the arm's own here:
the plan (approach, force ramp, press, slide and back), the true force along E's z read
from the contact engine, and the initial posture from inverse kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Demultiplexer,
    RandomSource,
    TrajectorySource,
    VectorLogSink,
)
from pydrake.trajectories import PiecewisePolynomial

from admittance.diagrams.loop.point import (
    AddLoggers,
    AddPointKinematics,
    AddPointPid,
    AddSensorChain,
)
from admittance.diagrams.robots.spatial_arm.plant import (
    CONTROL_FRAME,
    NORMAL_AXIS,
    TABLE_BODY,
    TOOL_BODY,
    TOOL_TIP_FRAME,
    AddSpatialArm,
    SolveSpatialInverseKinematics,
    SpatialGeometry,
    spatial_point,
)
from admittance.diagrams.robots.spatial_arm.safety_layer import (
    AddSpatialForceLoop,
    SpatialSafetyLayer,
)
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES, SpatialScenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.directional_contact_force import DirectionalContactForce
from admittance.systems.joint_torque_fault import JointTorqueFault
from admittance.systems.spatial_kinematics import SpatialFrameKinematics

__all__ = [
    "BuildSpatialLoop",
    "CheckSpatialPlan",
    "SetSpatialInitialConditions",
    "SpatialLoop",
    "spatial_force_reference",
    "spatial_plan",
]

SIZE = len(SPATIAL_COORDINATES)


@dataclass
class SpatialLoop:
    """A built spatial-arm loop and handles to its parts."""

    scenario: SpatialScenario
    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    geometry: SpatialGeometry
    kinematics: object
    pid: object
    # The force law (None for pid_only).
    admittance: object
    plan: TrajectorySource
    force_reference: TrajectorySource
    table_force: DirectionalContactForce
    # The wrist force/torque sensor (None for the ideal sensor).
    sensor: object
    measured_force_output: object
    # q at t = 0 (the inverse kinematics of the plan's start), rad.
    initial_positions: np.ndarray
    random_sources: list[RandomSource] = field(default_factory=list)
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)
    # The safety layer at the tool tip (None unless safety.enabled).
    safety: SpatialSafetyLayer | None = None


def _hermite_row(breaks, positions, velocities) -> PiecewisePolynomial:
    samples = np.array([positions], dtype=float)
    return PiecewisePolynomial.CubicHermite(breaks, samples, np.array([velocities], dtype=float))


def _slide_row(scenario: SpatialScenario) -> PiecewisePolynomial | None:
    """x of Xd: out by slide_distance at slide_speed and back, cubic blends at each end."""
    t = scenario.trajectory
    if t.slide_distance == 0:
        return None
    d, v, b, start = t.slide_distance, t.slide_speed, t.blend_time, scenario.slide_start
    leg = d / v + b
    breaks = [start, start + b, start + d / v, start + leg]
    out = ([0.0, 0.5 * v * b, d - 0.5 * v * b, d], [0.0, v, v, 0.0])
    back = ([d, d - 0.5 * v * b, 0.5 * v * b, 0.0], [0.0, -v, -v, 0.0])
    return _hermite_row(
        breaks + [time + leg for time in breaks[1:]],
        out[0] + back[0][1:],
        out[1] + back[1][1:],
    )


def spatial_plan(scenario: SpatialScenario) -> PiecewisePolynomial:
    """Xd(t) of the tool tip in the control frame: (x, y, z, rx, ry, rz).

    z goes from approach_height above the planned surface down to Fr / surface.stiffness
    into it (the paper's eq. 6 on the planned table, where position control alone would
    press with Fr) over approach_time (a cubic, at rest at both ends); x slides out and back
    after the press; the orientation stays the planned one (the tool along E's z: a zero
    rotation vector).
    """
    t = scenario.trajectory
    press = scenario.force_reference / scenario.surface.stiffness
    rows = {
        2: _hermite_row([0.0, t.approach_time], [-t.approach_height, press], [0.0, 0.0]),
    }
    slide = _slide_row(scenario)
    if slide is not None:
        rows[0] = slide
    end = scenario.duration
    breaks = sorted({0.0, end, *(b for row in rows.values() for b in row.get_segment_times())})
    breaks = [b for b in breaks if b <= end]
    positions = np.zeros((SIZE, len(breaks)))
    velocities = np.zeros((SIZE, len(breaks)))
    for axis, row in rows.items():
        first, last = row.start_time(), row.end_time()
        for column, time in enumerate(breaks):
            clamped = min(max(time, first), last)
            positions[axis, column] = row.value(clamped)[0, 0]
            inside = first <= time <= last
            velocities[axis, column] = row.EvalDerivative(clamped, 1)[0, 0] if inside else 0.0
    return PiecewisePolynomial.CubicHermite(breaks, positions, velocities)


def spatial_force_reference(scenario: SpatialScenario) -> PiecewisePolynomial:
    """Fr(t): 0 during the approach, then a ramp to force_reference over force_ramp_time."""
    start = scenario.press_start
    breaks = [0.0, start, start + scenario.trajectory.force_ramp_time]
    return PiecewisePolynomial.FirstOrderHold(breaks, [[0.0, 0.0, scenario.force_reference]])


def _AddJointTorqueFaults(builder: DiagramBuilder, scenario: SpatialScenario, plant) -> None:
    """The scenario's joint_torque faults on the plant's applied generalized force: a link
    hitting something (the contact engine's table is not part of it)."""
    collisions = [
        (f.start, f.end, f.value, f.joint) for f in scenario.faults if f.kind == "joint_torque"
    ]
    if not collisions:
        return
    nv = plant.num_velocities()
    for index, fault in enumerate(scenario.faults):
        if fault.kind == "joint_torque" and not 0 <= fault.joint < nv:
            raise ScenarioError(
                f"faults[{index}].joint: must be in [0, {nv - 1}] (the arm's moving joints "
                f"from the base), got {fault.joint}"
            )
    none = builder.AddSystem(ConstantVectorSource(np.zeros(nv)))
    none.set_name("no_applied_force")
    fault = builder.AddSystem(JointTorqueFault(nv, collisions))
    fault.set_name("joint_torque_fault")
    builder.Connect(none.get_output_port(), fault.generalized_force_input)
    builder.Connect(
        fault.generalized_force_output, plant.get_applied_generalized_force_input_port()
    )


def _AddTableForce(builder, plant, geometry: SpatialGeometry) -> DirectionalContactForce:
    """The true force of the tool on the table along E's z, from the contact results."""
    table_force = builder.AddSystem(
        DirectionalContactForce(
            plant.GetBodyByName(TOOL_BODY).index(),
            plant.GetBodyByName(TABLE_BODY).index(),
            geometry.X_WE.rotation().matrix()[:, NORMAL_AXIS],
        )
    )
    table_force.set_name("table_force")
    builder.Connect(plant.get_contact_results_output_port(), table_force.contact_results_input)
    return table_force


def _AddPlan(builder, scenario: SpatialScenario):
    """The plan [Xd; dXd/dt] and its split: (plan, split), Xd on the split's output 0 and
    dXd/dt on its output 1."""
    plan = builder.AddSystem(TrajectorySource(spatial_plan(scenario), 1))
    plan.set_name("plan")
    split = builder.AddSystem(Demultiplexer([SIZE, SIZE]))
    split.set_name("plan_split")
    builder.Connect(plan.get_output_port(), split.get_input_port())
    return plan, split


def BuildSpatialLoop(scenario: SpatialScenario, *, analysis: bool = False) -> SpatialLoop:
    """Wires the arm, its tool, the table and the tool tip's force loop for `scenario`.

    With `analysis`, the loop the linearization steps: the same loop, its noise held at
    zero and without loggers.

    Raises:
        ScenarioError: the model cannot be loaded or a frame is missing (one line).
    """
    builder = DiagramBuilder()
    plant, scene_graph, geometry = AddSpatialArm(builder, scenario)
    initial_positions = _initial_positions(scenario, plant, geometry)
    point = spatial_point(scenario, plant, initial_positions)

    table_force = _AddTableForce(builder, plant, geometry)
    plan, split = _AddPlan(builder, scenario)
    reading = AddSensorChain(
        builder, point, table_force.contact_force_output, plant=plant, noise=not analysis
    )
    kinematics = AddPointKinematics(builder, plant, point)
    pid = AddPointPid(builder, plant, point, kinematics, split.get_output_port(1))
    builder.Connect(pid.actuation_output, plant.get_actuation_input_port())
    _AddJointTorqueFaults(builder, scenario, plant)
    reference = builder.AddSystem(TrajectorySource(spatial_force_reference(scenario)))
    reference.set_name("force_reference")
    admittance, safety = AddSpatialForceLoop(
        builder,
        scenario,
        point,
        pid,
        plant=plant,
        desired_position_output=split.get_output_port(0),
        desired_velocity_output=split.get_output_port(1),
        desired_force_output=reference.get_output_port(),
        measured_force_output=reading.measured_force_output,
    )

    ports = {
        "state": plant.get_state_output_port(),
        "contact_force": table_force.contact_force_output,
        "measured_force": reading.measured_force_output,
        "force_reference": reference.get_output_port(),
        "plan": plan.get_output_port(),
        "kinematics": kinematics.kinematics_output,
        "actuation": pid.actuation_output,
    }
    if admittance is not None:
        ports["reference_offset"] = admittance.reference_offset_output
    if safety is not None:
        ports.update(safety.log_ports())
    loggers = (
        {}
        if analysis
        else AddLoggers(builder, ports, scenario.logging.period or scenario.time_step)
    )
    diagram = builder.Build()
    diagram.set_name("spatial_loop")
    return SpatialLoop(
        scenario=scenario,
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        geometry=geometry,
        kinematics=kinematics,
        pid=pid,
        admittance=admittance,
        plan=plan,
        force_reference=reference,
        table_force=table_force,
        sensor=reading.sensor,
        measured_force_output=reading.measured_force_output,
        initial_positions=initial_positions,
        random_sources=reading.random_sources,
        loggers=loggers,
        safety=safety,
    )


def _joint_guess(
    scenario: SpatialScenario, plant: MultibodyPlant, geometry: SpatialGeometry
) -> np.ndarray:
    """arm.joint_guess on the actuated joints, as the plant's positions (0 elsewhere)."""
    guess = np.zeros(plant.num_positions())
    for name, angle in zip(geometry.actuated_joints, scenario.arm.joint_guess, strict=False):
        guess[plant.GetJointByName(name).position_start()] = angle
    return guess


def _initial_positions(
    scenario: SpatialScenario, plant: MultibodyPlant, geometry: SpatialGeometry
) -> np.ndarray:
    """q at t = 0: arm.initial_joints, or the inverse kinematics of Xd(0) from joint_guess
    (the tool tip approach_height above the planned point, along E's z)."""
    arm = scenario.arm
    actuated = [plant.GetJointByName(name) for name in geometry.actuated_joints]
    q = np.zeros(plant.num_positions())
    if arm.initial_joints:
        if len(arm.initial_joints) != len(actuated):
            raise ScenarioError(
                f"arm.initial_joints: must be {len(actuated)} angles (the actuated joints "
                f"{', '.join(geometry.actuated_joints)}), got {arm.initial_joints!r}"
            )
        for joint, angle in zip(actuated, arm.initial_joints, strict=True):
            q[joint.position_start()] = angle
        return q
    guess = _joint_guess(scenario, plant, geometry)
    start = geometry.X_WE @ RigidTransform([0.0, 0.0, -scenario.trajectory.approach_height])
    try:
        return SolveSpatialInverseKinematics(plant, TOOL_TIP_FRAME, start, guess)
    except ValueError as error:
        raise ScenarioError(
            f"arm.joint_guess, surface.position, surface.height: the tool cannot reach the "
            f"plan's start from this guess ({error})"
        ) from None


def CheckSpatialPlan(loop: SpatialLoop, step: float = 0.05) -> None:
    """Rejects a plan the arm cannot reach, follow or press with, naming the keys, as the
    planar arm's CheckTrajectoryReachable does.

    Samples Xd(t) every `step` s (and at 9 points of each of the plan's pieces) and
    solves the inverse kinematics of each point from the previous one: each must lie
    within the joint limits, the joint speeds that follow dXd/dt within the model's
    velocity limits, and the torques that hold the arm against gravity and, from the
    press on, Fr along E's z, J^T F - tau_g, within its effort limits.

    Raises:
        ScenarioError: one line naming the keys and the first point that fails.
    """
    scenario, plant, geometry = loop.scenario, loop.plant, loop.geometry
    plan = spatial_plan(scenario)
    kinematics = SpatialFrameKinematics(
        plant, TOOL_TIP_FRAME, coordinates=SPATIAL_COORDINATES, expressed_in=CONTROL_FRAME
    )
    speed_limits = plant.GetVelocityUpperLimits()
    # Every `step`, and 8 points inside each of the plan's pieces: a short approach's
    # fastest point is inside it, between two grid points.
    breaks = plan.get_segment_times()
    inside = (np.linspace(a, b, 9) for a, b in zip(breaks[:-1], breaks[1:], strict=True))
    times = sorted(
        {*np.arange(0.0, scenario.duration, step), *breaks, *np.concatenate(list(inside))}
    )
    q = np.asarray(loop.initial_positions, dtype=float)
    guess = _joint_guess(scenario, plant, geometry)
    for time in (t for t in times if t <= scenario.duration):
        point = plan.value(time)[:, 0]
        where = f"({', '.join(f'{1e3 * v:.1f}' for v in point[:3])}) mm in the control frame"
        pose = geometry.X_WE @ RigidTransform(point[:3])
        q = _solve_from(plant, pose, (q, guess))
        if q is None:
            raise ScenarioError(
                f"surface.position, trajectory.slide_distance, trajectory.slide_direction, "
                f"arm.joint_guess: the plan's point at t = {time:.2f} s, {where}, is out of the "
                "arm's reach or beyond its joint limits"
            )
        # At q, at rest: the Jacobian for the speeds and the press, the context for gravity.
        kinematics.set_state(np.concatenate([q, np.zeros(q.size)]))
        jacobian = np.asarray(kinematics.jacobian(), dtype=float)
        # The least-norm joint speeds that move the tip at dXd/dt (a redundant arm's).
        velocity = plan.EvalDerivative(time, 1)[:, 0]
        speeds = np.linalg.lstsq(jacobian, velocity, rcond=None)[0]
        if np.any(np.abs(speeds) > speed_limits):
            needed = ", ".join(f"{abs(v):.3g}" for v in speeds)
            allowed = ", ".join(f"{v:.3g}" for v in speed_limits)
            keys = (
                "trajectory.approach_time, trajectory.approach_height"
                if time < scenario.press_start
                else "trajectory.slide_speed, trajectory.slide_distance, trajectory.blend_time"
            )
            raise ScenarioError(
                f"{keys}: following the plan at t = {time:.2f} s, {where}, needs joint speeds "
                f"({needed}) rad/s, beyond the model's velocity limits ({allowed}) rad/s"
            )
        pressing = time >= scenario.press_start
        _check_within_effort_limits(loop, kinematics.context, jacobian, where, pressing)


def _solve_from(plant, pose: RigidTransform, seeds) -> np.ndarray | None:
    """The inverse kinematics of the tool tip's `pose` from the first seed it converges
    from (the previous point's joints, then the scenario's guess), None if none does."""
    for seed in seeds:
        try:
            return SolveSpatialInverseKinematics(plant, TOOL_TIP_FRAME, pose, seed)
        except ValueError:
            continue
    return None


def _check_within_effort_limits(
    loop: SpatialLoop, plant_context, jacobian, where: str, pressing: bool
) -> None:
    """At rest at `plant_context`'s q, holding the arm against gravity and, `pressing`, Fr
    along E's z: tau = J^T F - tau_g within the PID's effort limits."""
    scenario = loop.scenario
    torque = -loop.plant.CalcGravityGeneralizedForces(plant_context)
    limits = loop.pid.effort_limits
    # The press is checked once the arm can hold itself: a failure then is Fr's.
    pressed = pressing and bool(np.all(np.abs(torque) <= limits))
    if pressed:
        force = np.zeros(SIZE)
        force[NORMAL_AXIS] = scenario.force_reference
        torque = torque + jacobian.T @ force
    if np.any(np.abs(torque) > limits):
        needed = ", ".join(f"{abs(t):.3g}" for t in torque)
        allowed = ", ".join(f"{limit:.3g}" for limit in limits)
        if pressed:
            keys, what = "force_reference", f"pressing {scenario.force_reference:g} N"
        else:
            keys, what = "arm.urdf, tool.mass", "the arm's own weight"
        raise ScenarioError(
            f"{keys}: {what} at {where} needs joint torques ({needed}) N m, beyond the "
            f"model's effort limits ({allowed}) N m"
        )


def SetSpatialInitialConditions(loop: SpatialLoop, context: Context) -> None:
    """The arm at rest at the plan's start, the noise sources seeded.

    With gravity compensation the PID holds the arm at zero error with a zero integral,
    and the force law starts at E(0) = Fr(0) - F(0) = 0 (Xr(0) = 0). A wrist sensor's
    held (or filtered) reading starts at what it reads at rest in the air: the tool's
    weight, which its compensation removes.
    """
    scenario, plant = loop.scenario, loop.plant
    loop.diagram.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, loop.initial_positions)
    plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))
    sensor = loop.sensor
    if sensor is not None:
        sensor_context = sensor.GetMyMutableContextFromRoot(context)
        weight = sensor.weight_wrench(sensor_context)
        if sensor.period > 0:
            sensor_context.SetDiscreteState(weight)
        elif sensor.filter_time_constant > 0:
            sensor_context.SetContinuousState(weight)
