"""The station: the Panda simulated in real time, speaking only the messages the robot
and its wrist sensor would (Drake's hardware_sim convention).

    PANDA_STATUS   lcmt_panda_status   PandaStatusSender, every period
    PANDA_FT       lcmt_force_torque   the wrist sensor's tared wrench, every period
    PANDA_COMMAND  lcmt_panda_command  PandaCommandReceiver -> the command watchdog

The plant is the scenario's robot's (its record's ``hardware.add_plant``: the arm, its
tool welded at ``tool_weld``, the table with the scenario's height error, tilts and contact
parameters, through Drake's contact engine), started where the simulated loop starts it;
the wrist sensor is at ``tool_weld`` (the tool body's frame). The station's clock is its
simulated time; the status ``utime`` is that time in microseconds, so a controller that
keeps its clock from the status gives the same answer whether the station runs at real
time or slower.
"""

from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass, field

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from pydrake.common import RandomGenerator
from pydrake.geometry import MeshcatVisualizer
from pydrake.manipulation import PandaCommandReceiver, PandaControlMode, PandaStatusSender
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput

from admittance.diagrams.hardware.config import HardwareConfig, hardware_parts, scenario_of
from admittance.diagrams.hardware.interface import (
    CommandWatchdog,
    WrenchMessage,
    WristWrenchSensor,
    joint_gains,
)
from admittance.diagrams.hardware.messages import CHANNELS
from admittance.diagrams.loop.point import AddSensorChain
from admittance.diagrams.robots.record import HardwareParts
from admittance.diagrams.run.metrics import (
    final_window,
    first_contact_time,
    in_contact,
    settled_from,
    time_mean,
)
from admittance.systems.wrench_sensor import WrenchSensor

__all__ = [
    "InitializeStation",
    "Station",
    "BuildStation",
    "StationRun",
    "run_station",
    "station_metrics",
]


# The station reads its Meshcat sliders once per this many periods.
SLIDER_POLL_STEPS = 10


@dataclass
class Station:
    """The station's diagram and the systems a run reads."""

    diagram: Diagram
    plant: MultibodyPlant
    watchdog: CommandWatchdog
    loggers: dict
    # The arm's joints at t = 0, rad.
    initial_positions: np.ndarray
    # What the station knows of its robot (its record's): frames, the normal axis.
    parts: HardwareParts
    # The scenario's wrist sensor (sensor.kind wrench), None for the ideal one.
    wrist_sensor: WrenchSensor | None = None
    # The scenario's seed, for the sensor's noise.
    seed: int = 0


def BuildStation(config: HardwareConfig, lcm, meshcat=None) -> Station:
    """The station of `config` on the LCM instance `lcm` (a DrakeLcm); with `meshcat`, the
    arm drawn there."""
    period = 1.0 / config.rate
    scenario = scenario_of(config)
    parts = hardware_parts(scenario)
    builder = DiagramBuilder()
    plant, scene_graph, _ = parts.add_plant(builder, scenario)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    plant.set_name("panda_plant")
    initial = parts.start_positions(scenario)
    plant.SetDefaultPositions(initial)
    # Pumps the LCM instance once per step (its subscribers' messages reach the diagram).
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    watchdog, split = _AddCommandInterface(builder, config, plant, lcm, initial, period)
    _AddStatusPublisher(builder, plant, watchdog, split, lcm, period)
    sensor, wrist = _AddWrenchPublisher(builder, scenario, parts, plant, initial, lcm, period)
    loggers = {
        "state": LogVectorOutput(plant.get_state_output_port(), builder, period),
        "wrench": LogVectorOutput(sensor.GetOutputPort("wrench"), builder, period),
        "hold": LogVectorOutput(watchdog.GetOutputPort("hold"), builder, period),
    }
    diagram = builder.Build()
    diagram.set_name("station")
    return Station(
        diagram=diagram,
        plant=plant,
        watchdog=watchdog,
        loggers=loggers,
        initial_positions=initial,
        parts=parts,
        wrist_sensor=wrist,
        seed=int(scenario.seed),
    )


def _AddCommandInterface(builder, config, plant, lcm, initial, period):
    """The robot's command interface: the command channel through Drake's receiver into
    the watchdog, which drives the arm with the robot's gravity compensation; returns the
    watchdog and the state's split into joint positions and velocities."""
    gravity = builder.AddNamedSystem(
        "gravity_compensation",
        InverseDynamics(plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation),
    )
    builder.Connect(plant.get_state_output_port(), gravity.get_input_port_estimated_state())
    subscriber = builder.AddNamedSystem(
        "command_subscriber",
        LcmSubscriberSystem.Make(
            CHANNELS.command, lcmt_panda_command, lcm, use_cpp_serializer=True
        ),
    )
    mode = PandaControlMode.kTorque if config.mode == "torque" else PandaControlMode.kPosition
    receiver = builder.AddNamedSystem("command_receiver", PandaCommandReceiver(7, mode))
    split = builder.AddNamedSystem("state_split", Demultiplexer([7, 7]))
    builder.Connect(plant.get_state_output_port(), split.get_input_port())
    builder.Connect(subscriber.get_output_port(), receiver.get_message_input_port())
    builder.Connect(split.get_output_port(0), receiver.get_position_measured_input_port())
    watchdog = builder.AddNamedSystem(
        "command_watchdog",
        CommandWatchdog(
            mode=config.mode,
            period=period,
            command_timeout=config.command_timeout,
            **joint_gains(plant, initial, config, period),
            effort_limits=plant.GetEffortUpperLimits(),
            initial_position=initial,
        ),
    )
    # The watchdog reads the same channel decoded in Python (the receiver's is C++'s).
    watched = builder.AddNamedSystem(
        "command_watch_subscriber",
        LcmSubscriberSystem.Make(CHANNELS.command, lcmt_panda_command, lcm),
    )
    builder.Connect(watched.get_output_port(), watchdog.GetInputPort("lcmt_panda_command"))
    builder.Connect(receiver.get_output_port(0), watchdog.GetInputPort("commanded"))
    builder.Connect(plant.get_state_output_port(), watchdog.GetInputPort("state"))
    builder.Connect(
        gravity.get_output_port_generalized_force(),
        watchdog.GetInputPort("gravity_compensation"),
    )
    builder.Connect(watchdog.GetOutputPort("actuation"), plant.get_actuation_input_port())
    return watchdog, split


def _AddStatusPublisher(builder, plant, watchdog, split, lcm, period) -> None:
    """Drake's status sender on the arm's joints and torques, published every period."""
    status = builder.AddNamedSystem("status_sender", PandaStatusSender(7))
    builder.Connect(split.get_output_port(0), status.GetInputPort("position_measured"))
    builder.Connect(split.get_output_port(1), status.GetInputPort("velocity_measured"))
    builder.Connect(watchdog.GetOutputPort("actuation"), status.GetInputPort("torque_commanded"))
    builder.Connect(watchdog.GetOutputPort("actuation"), status.GetInputPort("torque_measured"))
    status_publisher = builder.AddNamedSystem(
        "status_publisher",
        LcmPublisherSystem.Make(
            CHANNELS.status, lcmt_panda_status, lcm, period, use_cpp_serializer=True
        ),
    )
    builder.Connect(status.get_output_port(), status_publisher.get_input_port())


def _AddWrenchPublisher(builder, scenario, parts, plant, initial, lcm, period):
    """The wrist wrench published every period: the scenario's sensor (bias, noise,
    low-pass) or the ideal one (the tool's contact wrench); returns (the ideal sensor,
    which the log reads, the scenario's wrench sensor or None)."""
    sensor = builder.AddNamedSystem(
        "wrist_sensor", WristWrenchSensor(plant, plant.GetBodyByName(parts.tool_body))
    )
    builder.Connect(plant.get_contact_results_output_port(), sensor.GetInputPort("contact_results"))
    builder.Connect(plant.get_body_poses_output_port(), sensor.GetInputPort("body_poses"))
    wrench_publisher = builder.AddNamedSystem(
        "wrench_publisher",
        LcmPublisherSystem.Make(CHANNELS.wrench, lcmt_force_torque, lcm, period),
    )
    wrist = None
    if scenario.sensor.kind == "wrench":  # the scenario's sensor: bias, noise, low-pass
        wrist = _AddWristSensor(builder, scenario, parts.point(scenario, plant, initial), plant)
        message = builder.AddNamedSystem("wrench_message", WrenchMessage())
        builder.Connect(wrist.compensated_wrench_output, message.get_input_port())
        builder.Connect(message.get_output_port(), wrench_publisher.get_input_port())
    else:  # the ideal sensor: the tool's contact wrench
        builder.Connect(
            sensor.GetOutputPort("lcmt_force_torque"), wrench_publisher.get_input_port()
        )
    return sensor, wrist


def _AddWristSensor(builder, scenario, point, plant) -> WrenchSensor:
    """The scenario's wrist force/torque sensor at ``tool_weld`` (``sensor.kind: wrench``),
    built by the simulated loop's own step (``loop.point.AddSensorChain`` on the robot's
    force-controlled `point`), its noise from a RandomSource at its readout period."""
    return AddSensorChain(builder, point, None, plant=plant).sensor


def InitializeStation(station: Station, context) -> None:
    """The noise seeded from the scenario's seed, and a wrist sensor's held or filtered
    reading at what it reads at rest in the air, the tool's weight (as the simulated loop
    starts it), which its compensation removes."""
    station.diagram.SetRandomContext(context, RandomGenerator(station.seed))
    sensor = station.wrist_sensor
    if sensor is not None:  # read at the step at least (spatial_point): a held reading
        sensor_context = sensor.GetMyMutableContextFromRoot(context)
        sensor_context.SetDiscreteState(sensor.weight_wrench(sensor_context))


@dataclass
class StationRun:
    """What a station run measured."""

    times: np.ndarray
    # The tool's contact force on the table along the control frame's z (the press), N.
    force: np.ndarray
    hold: np.ndarray
    # The tool tip's depth along the control frame's z (0: the planned surface), m.
    tip_height: np.ndarray
    wall_time: float
    real_time_rate: float
    events: list = field(default_factory=list)
    interrupted: bool = False
    # Statuses the controller did not answer within command_wait.
    late_commands: int = 0


class _CommandClock:
    """The utime of the newest command the station received, read from the raw message
    (an LCM message's utime follows its 8-byte fingerprint), and the count of late ones."""

    def __init__(self, lcm) -> None:
        self.command = -1
        self.late = 0
        lcm.Subscribe(CHANNELS.command, self._on_command)

    def _on_command(self, data: bytes) -> None:
        self.command = max(self.command, struct.unpack(">q", data[8:16])[0])

    def wait_for_answer(self, lcm, status_utime: int, budget: float, timeout: float) -> None:
        """Waits up to `budget` s (wall) for the command answering the status of
        `status_utime`; a controller that has not spoken yet, or whose newest command is
        more than `timeout` s (the watchdog's) behind, is not waited for."""
        lcm.HandleSubscriptions(0)
        if self.command < 0 or budget <= 0 or status_utime - self.command > timeout * 1e6:
            return
        deadline = time.monotonic() + budget
        while self.command < status_utime:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self.late += 1
                return
            lcm.HandleSubscriptions(max(1, int(remaining * 1e3)))


def run_station(
    config: HardwareConfig, lcm, *, progress=None, stop=None, sliders=None
) -> StationRun:
    """Runs the station for ``config.duration`` of simulated time, paced to
    ``config.realtime_rate`` where the machine can; `stop()` returning True ends it early.

    One period at a time: after each status it gives the controller up to
    ``command_wait`` s of wall time to answer (the robot gives it one cycle; a simulated
    station on a loaded machine gives it more, so that the plant sees the one-period delay
    of a controller that meets its deadline, and the station's slowness shows only in its
    real-time rate). A later command is counted late (``late_commands``) and the station
    goes on with the newest command it has; once the commands are older than the
    watchdog's timeout it stops waiting. The controller's own timing (timing.json) says
    whether it meets the deadline.

    `sliders` (``sliders.ParameterSliders``): polled every SLIDER_POLL_STEPS periods, the
    arm drawn on their Meshcat.
    """
    station = BuildStation(config, lcm, None if sliders is None else sliders.meshcat)
    simulator = Simulator(station.diagram)
    simulator.set_target_realtime_rate(config.realtime_rate)
    InitializeStation(station, simulator.get_mutable_context())
    clock = _CommandClock(lcm)
    simulator.Initialize()
    start = time.monotonic()
    period = 1.0 / config.rate
    steps = int(round(config.duration * config.rate))
    interrupted = False
    for step in range(1, steps + 1):
        if stop is not None and stop():
            interrupted = True
            break
        # The status of the previous step's end (utime (step - 1) period) is out.
        status_utime = int(round((step - 1) * period * 1e6))
        if sliders is not None and (step - 1) % SLIDER_POLL_STEPS == 0:
            sliders.poll()
        clock.wait_for_answer(lcm, status_utime, config.command_wait, config.command_timeout)
        simulator.AdvanceTo(step * period)
        if progress is not None and step % 100 == 0:
            progress(step * period)
    wall = time.monotonic() - start
    context = simulator.get_context()
    logs = {name: logger.FindLog(context) for name, logger in station.loggers.items()}
    simulated = context.get_time()
    wrench = logs["wrench"].data()
    plant, parts = station.plant, station.parts
    normal_W = (
        plant.GetFrameByName(parts.control_frame)
        .CalcPoseInWorld(plant.CreateDefaultContext())
        .rotation()
        .matrix()[:, parts.normal_axis]
    )
    return StationRun(
        times=logs["wrench"].sample_times().copy(),
        force=-(normal_W @ wrench[:3]),
        hold=np.interp(
            logs["wrench"].sample_times(), logs["hold"].sample_times(), logs["hold"].data()[0]
        ),
        tip_height=_tip_heights(station, logs["state"]),
        wall_time=wall,
        real_time_rate=simulated / wall if wall > 0 else float("inf"),
        events=list(station.watchdog.events),
        interrupted=interrupted,
        late_commands=clock.late,
    )


def _tip_heights(station: Station, log) -> np.ndarray:
    """The tool tip's depth along the control frame's z (into the planned table) at each
    logged state, m (0 on the planned surface, negative above it)."""
    plant, parts = station.plant, station.parts
    context = plant.CreateDefaultContext()
    tip = plant.GetFrameByName(parts.tip_frame)
    frame = plant.GetFrameByName(parts.control_frame)
    depths = []
    for x in log.data().T:
        plant.SetPositionsAndVelocities(context, x)
        depths.append(
            plant.CalcRelativeTransform(context, frame, tip).translation()[parts.normal_axis]
        )
    return np.asarray(depths)


def station_metrics(run: StationRun, config: HardwareConfig) -> dict:
    """The station's metrics: the press force's settling and steady state (the shared
    rules of ``run.metrics``), the real-time rate, and what followed a command loss.

    ``command_loss_time`` is the first time the watchdog held the arm after commands had
    flowed (None: never); ``peak_force_after_command_loss`` the largest force from then on.
    """
    times, force, hold = run.times, run.force, run.hold > 0.5
    commanded = np.nonzero(~hold)[0]
    loss_time = None
    if commanded.size:
        later = np.nonzero(hold[commanded[0] :])[0]
        if later.size:
            loss_time = float(times[commanded[0] + later[0]])
    end = loss_time if loss_time is not None else math.inf
    reference = config.force_reference
    settled = settled_from(times, force, reference, 0.0, end)
    steady = final_window(times) & (times < end)
    mean = time_mean(times[steady], force[steady]) if steady.any() else math.nan
    after = times >= loss_time if loss_time is not None else np.zeros_like(hold)
    return {
        "force_reference": reference,
        "settling_time": settled,
        "steady_state_force": mean,
        "steady_state_error": abs(mean - reference) / reference if math.isfinite(mean) else None,
        "peak_force": float(np.max(force)) if force.size else None,
        "first_contact_time": first_contact_time(times, in_contact(force, reference)),
        "simulated_time": float(times[-1]) if times.size else 0.0,
        "wall_time": run.wall_time,
        "real_time_rate": run.real_time_rate,
        "target_realtime_rate": config.realtime_rate,
        "command_loss_time": loss_time,
        "peak_force_after_command_loss": float(np.max(force[after])) if after.any() else None,
        "watchdog_events": [{"time": t, "event": what} for t, what in run.events],
        "late_commands": run.late_commands,
        "interrupted": run.interrupted,
    }
