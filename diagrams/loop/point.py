"""The loop of Fig. 1 at one force-controlled point, for every robot.

Each step below wires one part of the loop at a :class:`ForcePoint` of the robot's
description: the point's kinematics (X, dX/dt and J, from the plant), its sensor chain
(the FlexiForce with its faults and noise, or the true force), its force controller (the
paper's law or a baseline), Xc = Xd + Xr, and its Cartesian PID (eq. 14-16). Each robot's
builder (each robot package's ``loop``) composes them with what is its own:
its plant, its contact (the analytic wall of eq. 4, or Drake's contact engine), its plan,
and how its points' torques reach the actuators. A sensor, a fault or a law added here
reaches every robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pydrake.common import RandomDistribution
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    ConstantVectorSource,
    DiscreteTimeDelay,
    Gain,
    LogVectorOutput,
    RandomSource,
    ZeroOrderHold,
)

from admittance.diagrams.robots.description import ForcePoint
from admittance.systems.adaptive_impedance import AdaptiveImpedance
from admittance.systems.cartesian_pid import CartesianPid
from admittance.systems.classical_admittance import ClassicalAdmittance
from admittance.systems.fixed_reference import FixedReference
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.optimal_admittance import OptimalAdmittance
from admittance.systems.planar_kinematics import PlanarKinematics
from admittance.systems.sensor_fault import SensorFault
from admittance.systems.spatial_kinematics import SpatialKinematics
from admittance.systems.task_kinematics import TaskKinematics, has_rotation_vector
from admittance.systems.wrench_in_control_frame import WrenchInControlFrame
from admittance.systems.wrench_sensor import WrenchSensor

__all__ = [
    "AddCommandedPosition",
    "AddForceController",
    "AddForceLoop",
    "AddLatency",
    "AddLoggers",
    "AddPointKinematics",
    "AddPointPid",
    "AddSensorChain",
    "SensorReading",
    "latency_period",
]


def AddPointKinematics(
    builder: DiagramBuilder, plant: MultibodyPlant, point: ForcePoint
) -> TaskKinematics:
    """X, dX/dt and J of the point's frame, once per evaluation, for its PID and contact:
    ``SpatialKinematics`` when its coordinates hold the rotation vector (rx, ry, rz),
    ``PlanarKinematics`` otherwise (same ``kinematics`` output layout)."""
    kind = SpatialKinematics if has_rotation_vector(point.coordinates) else PlanarKinematics
    system = builder.AddSystem(
        kind(
            plant,
            frame_name=point.frame,
            coordinates=point.coordinates,
            expressed_in=point.expressed_in,
        )
    )
    system.set_name(point.system_name("fingertip_kinematics"))
    builder.Connect(plant.get_state_output_port(), system.estimated_state_input)
    return system


@dataclass
class SensorReading:
    """A point's sensor chain as built: the FlexiForce or the wrist force/torque sensor
    (None for the ideal sensor, whose reading is the true force itself), the port of the
    force it reports (one value per force axis), its noise, and for the wrist sensor the
    system that reads its wrench in the point's frame."""

    sensor: FlexiForceSensor | WrenchSensor | None
    measured_force_output: object
    random_sources: list[RandomSource] = field(default_factory=list)
    control_frame: WrenchInControlFrame | None = None


def _AddNoise(builder, point: ForcePoint, size: int, std: float, period: float, noise: bool):
    """A RandomSource of `size` standard normals at `period` (None when there is no noise:
    an analysis diagram or a zero std), or a zero source; returns (source, output)."""
    if noise and std > 0:
        source = builder.AddSystem(RandomSource(RandomDistribution.kGaussian, size, period))
        source.set_name(point.system_name("sensor_noise"))
        return source, source.get_output_port(0)
    zero = builder.AddSystem(ConstantVectorSource([0.0] * size))
    zero.set_name(point.system_name("no_noise"))
    return None, zero.get_output_port()


def _AddFaults(builder: DiagramBuilder, point: ForcePoint, reading_output):
    """The point's injected sensor faults on `reading_output`: (the SensorFault or None,
    the reading they leave)."""
    if not point.sensor.faults:
        return None, reading_output
    fault = builder.AddSystem(SensorFault(list(point.sensor.faults)))
    fault.set_name(point.system_name("sensor_fault"))
    builder.Connect(reading_output, fault.measured_force_input)
    return fault, fault.reported_force_output


def _AddWrenchChain(
    builder: DiagramBuilder, point: ForcePoint, plant: MultibodyPlant, noise: bool
) -> SensorReading:
    """The wrist sensor at the chain's weld and its reading in the point's frame."""
    chain = point.sensor
    if plant is None:
        raise ValueError("sensor.kind wrench: AddSensorChain needs the plant")
    sensor = builder.AddSystem(
        WrenchSensor(
            plant,
            chain.weld_joint,
            bias=chain.bias,
            force_noise_std=chain.noise_std,
            torque_noise_std=chain.torque_noise_std,
            filter_cutoff_hz=chain.filter_cutoff,
            period=chain.period,
            tool_mass=chain.tool_mass,
            tool_com=chain.tool_com,
        )
    )
    sensor.set_name(point.system_name("wrench_sensor"))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.reaction_forces_input)
    builder.Connect(plant.get_body_poses_output_port(), sensor.body_poses_input)
    frame = builder.AddSystem(
        WrenchInControlFrame(
            plant,
            chain.weld_joint,
            point.expressed_in,
            contact_offset=chain.contact_offset,
            axes=chain.wrench_axes or point.force_axes,
        )
    )
    frame.set_name(point.system_name("wrench_in_control_frame"))
    builder.Connect(sensor.compensated_wrench_output, frame.wrench_input)
    builder.Connect(plant.get_body_poses_output_port(), frame.body_poses_input)
    std = max(chain.noise_std, chain.torque_noise_std)
    source, noise_output = _AddNoise(
        builder, point, 6, std, chain.period or chain.noise_period, noise
    )
    builder.Connect(noise_output, sensor.noise_input)
    sources = [] if source is None else [source]
    # The faults replace the reading along the force axis (without noise: validated).
    _, reading = _AddFaults(builder, point, frame.force_output)
    return SensorReading(sensor, AddLatency(builder, point, reading), sources, frame)


def AddSensorChain(
    builder: DiagramBuilder,
    point: ForcePoint,
    contact_force_output,
    *,
    noise: bool = True,
    plant: MultibodyPlant | None = None,
) -> SensorReading:
    """The point's force sensor on the true contact force, its faults, its noise and its
    latency (:func:`AddLatency`).

    The ideal sensor is a wire: its reading is the contact force, with no system to
    evaluate. Without `noise` (an analysis diagram) the noise input is held at zero. The
    wrist force/torque sensor (kind "wrench") reads the `plant`'s reaction force at the
    chain's weld instead of `contact_force_output` (None there), removes the tool's
    weight and reports the force the tool applies along the point's force axes, in the
    point's frame (``expressed_in``), positive pushing.
    """
    chain = point.sensor
    if chain.kind == "wrench":
        return _AddWrenchChain(builder, point, plant, noise)
    system = None
    if chain.kind == "ideal":
        measured_force_output = contact_force_output
    else:
        system = builder.AddSystem(
            FlexiForceSensor(
                kind=chain.kind,
                filter_cutoff_hz=chain.filter_cutoff,
                period=chain.period,
                hysteresis=chain.hysteresis,
                drift=chain.drift,
            )
        )
        system.set_name(point.system_name("flexiforce_sensor"))
        builder.Connect(contact_force_output, system.contact_force_input)
        measured_force_output = system.measured_force_output
    fault, measured_force_output = _AddFaults(builder, point, measured_force_output)
    random_sources = []
    if system is None:
        return SensorReading(
            system, AddLatency(builder, point, measured_force_output), random_sources
        )
    source, noise_output = _AddNoise(builder, point, 1, chain.noise_std, chain.noise_period, noise)
    if source is not None:
        random_sources.append(source)
        gain = builder.AddSystem(Gain(chain.noise_std, 1))
        gain.set_name(point.system_name("noise_std"))
        builder.Connect(noise_output, gain.get_input_port())
        noise_output = gain.get_output_port()
    builder.Connect(noise_output, system.noise_input)
    if fault is not None and fault.noise_input is not None:
        # A noisy fault keeps the same ADC noise the reading had.
        builder.Connect(noise_output, fault.noise_input)
    return SensorReading(system, AddLatency(builder, point, measured_force_output), random_sources)


def latency_period(point: ForcePoint) -> float:
    """The period at which a delayed reading is sampled: the force law's when it is
    sampled (the ADC runs with the controller), otherwise the ADC's noise period, s."""
    return point.law.period if point.law.period > 0 else point.sensor.noise_period


def AddLatency(builder: DiagramBuilder, point: ForcePoint, reading_output):
    """The reading `latency` L late, as a controller sampled at the period h sees it.

    With L = n h + r (0 <= r < h), a ZeroOrderHold of period h and offset h - r samples
    the reading at t_k - r; n more periods come from a ZeroOrderHold at offset 0 (n = 1)
    or a DiscreteTimeDelay of n - 1 steps (n >= 2: a discrete system read by another's
    update at the same instant shows its value before the update, one period more).
    A controller updated at t_k = k h then reads the reading of t_k - L exactly
    (tests/test_safety_sampled.py); a continuous one reads that sample held over
    [t_k, t_k+1). L = 0 adds nothing: the reading's port is returned as it is.
    """
    latency = point.sensor.latency
    if latency <= 0.0:
        return reading_output
    period = latency_period(point)
    periods = math.floor(latency / period + 1e-9)
    remainder = latency - periods * period
    stages = []
    if remainder > 1e-9 * period:
        stages.append(("latency_sample", ZeroOrderHold(period, 1, period - remainder)))
    if periods == 1:
        stages.append(("latency_hold", ZeroOrderHold(period, 1)))
    elif periods >= 2:
        stages.append(("latency_delay", DiscreteTimeDelay(period, periods - 1, 1)))
    for role, system in stages:
        builder.AddSystem(system)
        system.set_name(point.system_name(role))
        builder.Connect(reading_output, system.get_input_port())
        reading_output = system.get_output_port()
    return reading_output


def AddPointPid(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    point: ForcePoint,
    kinematics: TaskKinematics,
    desired_velocity_output,
) -> CartesianPid:
    """The Cartesian PID of eq. 14-16 at the point (its Xc and its torques are wired by the
    caller: through :func:`AddCommandedPosition`, and to the plant's actuation). With the
    point's gravity compensation or posture task, its ``state`` input reads the plant's
    state output."""
    system = builder.AddSystem(
        CartesianPid(
            plant,
            frame_name=point.frame,
            kp=point.kp,
            kd=point.kd,
            ki=point.ki,
            period=point.pid_period,
            coordinates=point.coordinates,
            expressed_in=point.expressed_in,
            gravity_compensation=point.gravity_compensation,
            posture=point.posture,
        )
    )
    system.set_name(point.system_name("cartesian_pid"))
    builder.Connect(kinematics.kinematics_output, system.kinematics_input)
    if system.state_input is not None:
        builder.Connect(plant.get_state_output_port(), system.state_input)
    builder.Connect(desired_velocity_output, system.commanded_velocity_input)
    return system


def AddForceController(builder: DiagramBuilder, point: ForcePoint):
    """Adds the point's force controller (``point.law.kind``), named after its kind.

    Returns:
        the system, or None for pid_only (the PID then runs on Xd alone).
    """
    law, kind = point.law, point.law.kind
    if kind == "pid_only":
        return None
    axes, size = list(point.force_axes), point.num_axes
    if kind == "optimal_admittance":
        system = OptimalAdmittance(
            gamma=law.gamma,
            alpha=law.alpha,
            # K of eq. 10 is the PID's stiffness on the force axis (docs/evidence/paper-notes.md,
            # section 4).
            stiffness=point.force_axis_stiffness,
            force_axes=axes,
            num_axes=size,
            period=law.period,
            max_push=law.max_push,
            max_retract=law.max_retract,
            max_force=law.max_force,
            force_bound_gain=law.force_bound_gain,
        )
    elif kind == "fixed_reference":
        position, stiffness = law.surface_estimate
        system = FixedReference(
            wall_position=position, wall_stiffness=stiffness, force_axes=axes, num_axes=size
        )
    elif kind == "classical_admittance":
        gains = law.baseline
        system = ClassicalAdmittance(
            mass=gains["mass"],
            damping=gains["damping"],
            stiffness=gains["stiffness"],
            force_axes=axes,
            num_axes=size,
        )
    elif kind == "adaptive_impedance":
        gains = law.baseline
        system = AdaptiveImpedance(
            mass=gains["mass"],
            damping=gains["damping"],
            adaptation_rate=gains["adaptation_rate"],
            force_axes=axes,
            num_axes=size,
        )
    else:  # each robot's validation admits only its kinds
        raise ValueError(f"controller.kind: unknown kind {kind!r}")
    builder.AddSystem(system)
    system.set_name(point.system_name(kind))
    return system


def AddCommandedPosition(
    builder: DiagramBuilder, point: ForcePoint, desired_position_output, pid: CartesianPid
):
    """Xc = Xd + Xr into the point's PID; returns the adder, whose input 1 takes Xr."""
    commanded = builder.AddSystem(Adder(2, point.num_axes))
    commanded.set_name(point.system_name("commanded_position"))
    builder.Connect(desired_position_output, commanded.get_input_port(0))
    builder.Connect(commanded.get_output_port(), pid.commanded_position_input)
    return commanded


def AddForceLoop(
    builder: DiagramBuilder,
    point: ForcePoint,
    pid: CartesianPid,
    *,
    desired_position_output,
    desired_force_output,
    measured_force_output,
):
    """The point's force controller between its sensor and its PID: Xc = Xd + Xr into the
    PID (Xd alone for pid_only).

    Returns:
        the force controller, or None for pid_only.
    """
    controller = AddForceController(builder, point)
    if controller is None:
        builder.Connect(desired_position_output, pid.commanded_position_input)
        return None
    builder.Connect(desired_force_output, controller.desired_force_input)
    builder.Connect(measured_force_output, controller.measured_force_input)
    commanded = AddCommandedPosition(builder, point, desired_position_output, pid)
    builder.Connect(controller.reference_offset_output, commanded.get_input_port(1))
    return controller


def AddLoggers(builder: DiagramBuilder, ports: dict, period: float) -> dict:
    """A VectorLogSink on each port, named log_<name> (period 0 = every step)."""
    loggers = {}
    for name, port in ports.items():
        logger = LogVectorOutput(port, builder, period)
        logger.set_name(f"log_{name}")
        loggers[name] = logger
    return loggers
