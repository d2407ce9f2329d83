"""The controller process: the paper's admittance law around the Cartesian PID of the
spatial scenario, knowing the robot only through its LCM messages (Drake's hardware_sim
convention).

Each ``lcmt_panda_status`` starts one cycle: the clock is the status ``utime`` (never the
wall clock), the state is the status's joint positions and velocities, the force is the
newest ``lcmt_force_torque`` read along the control frame's z by the controller's own model
of the arm (a controller on hardware has the robot's model). The cycle is one sample of the
law and the PID (its robot's control law, ``SpatialControlLaw`` for a spatial arm) and publishes one
``lcmt_panda_command`` whose ``utime`` is the status's.

Watchdogs, each logged with its time:

* a wrench that is non-finite, or older than ``wrench_timeout`` by its timestamp against the
  status clock: the law holds its offset (the arm holds its reference, as the safety layer
  does for a failed sensor) until a valid wrench returns;
* no status for ``status_timeout_periods`` periods (wall clock: nothing else ticks): the
  hold command, the last torques repeated (they held the arm where it was) with the last
  status's ``utime``, once per period, so that the robot's own command watchdog, seeing no
  fresh command, holds the arm if the silence lasts; zero torque would drop the press and
  the law, seeing the force fall, would wind up;
* no status for ``station_timeout`` s: the station is gone (``StationGoneError``);
* the gains against the sampled loop (the robot's ``sampled_gains``: the PID's damping through
  the arm and the force loop along the normal, with the command one or more periods
  late): at the start at the nominal rate with the one-period delay of a controller that
  answers within the period (gains beyond its bounds: ``ScenarioError``, one line naming
  the keys and the fix); then once per second of the status clock at the period and the
  delay the cycles measured (p99 of the command's hold time, and of the statuses that came
  while a command was computed: ``timing.CycleTiming.measured``): beyond the bounds the
  law holds its offset, as for a failed sensor, until a check passes; a parameter message
  asking for a Gamma above the critical one is refused;
* SIGINT or SIGTERM (the caller's ``stop``): the hold command once more, then a clean stop;
  the run's end (the status clock at ``duration``, or a station that falls silent within
  ``END_SLACK`` of it) ends it the same way.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from admittance.diagrams.hardware.config import HardwareConfig, hardware_parts, scenario_of
from admittance.diagrams.hardware.interface import joint_gains
from admittance.diagrams.hardware.messages import CHANNELS, decode_parameters
from admittance.diagrams.hardware.timing import CycleTiming
from admittance.diagrams.scenario.schema import ScenarioError

__all__ = ["AdmittanceController", "ControllerEvent", "StationGoneError"]

NUM_JOINTS = 7
# How long the controller waits for the station's first status, s (a loaded machine takes
# tens of seconds to start a Python process with Drake).
START_TIMEOUT = 60.0
# A station that falls silent this close to the run's end has ended the run, s.
END_SLACK = 0.1
# The status clock's interval between two checks of the gains against the measured loop, s.
CHECK_INTERVAL = 1.0
# What timing.json's stability history keeps of each check.
HISTORY_KEYS = ("time", "period", "latency", "delay_periods", "damper_gain", "verdict")


class StationGoneError(RuntimeError):
    """No status from the station for longer than the controller's station timeout."""


@dataclass
class ControllerEvent:
    # The controller's clock (the last status utime, s) when the event happened.
    time: float
    # Wall (monotonic) time of the event, s.
    wall: float
    what: str


@dataclass
class _Trace:
    times: list = field(default_factory=list)
    force: list = field(default_factory=list)
    offset: list = field(default_factory=list)


class AdmittanceController:
    """The controller of module docstring on the LCM instance `lcm`.

    Args:
        clock: the wall clock of the watchdogs (monotonic seconds); tests pass their own.
        cpu_clock: the CPU clock of the timing figures.
        newest_only: a process's mode: statuses are only stored as they arrive, and
            :meth:`poll` runs one cycle on the newest (a controller that falls behind
            answers the newest status and skips the older ones, counted in
            ``timing.skipped``). Otherwise each status runs its cycle as it is handled (one
            process sharing a memq:// instance with the station, where the station's own
            LCM pump delivers it).
    """

    def __init__(
        self,
        config: HardwareConfig,
        lcm,
        *,
        clock: Callable[[], float] = time.monotonic,
        cpu_clock: Callable[[], float] = time.thread_time,
        newest_only: bool = False,
    ) -> None:
        self.config = config
        self.period = 1.0 / config.rate
        self._lcm = lcm
        self._clock = clock
        self._cpu_clock = cpu_clock
        self.position_mode = config.mode == "position"
        scenario = scenario_of(config)
        gains = None
        if self.position_mode:  # the robot's joint controller, as the station runs it

            def gains(plant, positions):
                return joint_gains(plant, positions, config, self.period)

        self.law = hardware_parts(scenario).control_law(
            scenario,
            max_force=config.max_force,
            force_bound_gain=config.force_bound_gain,
            joint_gains=gains,
        )
        self.start_check = self.law.check_gains(self.period, 1, self.law.initial_positions)
        problem = self.start_check.problem()
        if problem is not None and config.gain_check:
            raise ScenarioError(problem + " (docs/evidence/hardware.md, the sampled loop)")
        self.last_check = self.start_check
        self.gain_checks: list[dict] = []
        self._checked_from = 0
        self._next_check = CHECK_INTERVAL
        self._gains_fault = False
        self.timing = CycleTiming(self.period)
        self.events: list[ControllerEvent] = []
        if problem is not None:
            self.events.append(ControllerEvent(0.0, clock(), f"gain check (off): {problem}"))
        self.trace = _Trace()
        self.time: float | None = None  # the status clock, s
        self.last_command: lcmt_panda_command | None = None
        self._last_utime = 0
        self._last_status_wall: float | None = None
        self._started_wall = clock()
        self._wrench: lcmt_force_torque | None = None
        self._wrench_payload: bytes | None = None
        self._newest_only = newest_only
        self._pending: tuple[bytes, float] | None = None
        self._wrench_fault = False
        self._status_lost = False
        self.finished = False
        lcm.Subscribe(CHANNELS.status, self._on_status)
        lcm.Subscribe(CHANNELS.wrench, self._on_wrench)
        lcm.Subscribe(CHANNELS.parameters, self._on_parameters)

    # --- events --------------------------------------------------------------------------

    def log(self, what: str) -> None:
        self.events.append(ControllerEvent(self.time or 0.0, self._clock(), what))

    def _on_wrench(self, payload: bytes) -> None:
        self._wrench_payload = payload  # decoded by the cycle that reads it

    def _on_parameters(self, payload: bytes) -> None:
        try:
            values = decode_parameters(payload)
        except ValueError as error:
            self.log(f"parameters rejected: {error}")
            return
        merged = {
            "force_reference": self.law.force_reference,
            "max_force": self.law.max_force,
            **values,
        }
        if not merged["max_force"] > merged["force_reference"]:
            self.log(f"parameters rejected: max_force must be above force_reference ({merged})")
            return
        critical = self.last_check.critical_gamma
        if "gamma" in values and critical is not None and values["gamma"] >= critical:
            self.log(
                f"parameters rejected: gamma={values['gamma']:g} is above the sampled loop's "
                f"critical Gamma {critical:.3g} at the measured rate"
            )
            return
        self.law.set_parameters(**values)
        changes = ", ".join(f"{k}={v:g}" for k, v in sorted(values.items()))
        self.log(f"parameters: {changes} (offset {self.law.offset * 1e3:.3f} mm continues)")

    # --- the cycle -----------------------------------------------------------------------

    def _measured_force(self) -> float | None:
        """The force along the control frame's z (into the table), or None if the wrench
        is invalid."""
        if self._wrench_payload is not None:
            self._wrench = lcmt_force_torque.decode(self._wrench_payload)
            self._wrench_payload = None
        wrench = self._wrench
        reason = None
        if wrench is None:
            reason = "no wrench received"
        else:
            values = (wrench.fx, wrench.fy, wrench.fz, wrench.tx, wrench.ty, wrench.tz)
            age = self.time - wrench.timestamp * 1e-6
            if not all(math.isfinite(x) for x in values):
                reason = "non-finite wrench"
            elif age > self.config.wrench_timeout:
                reason = f"stale wrench ({age:.4f} s old)"
        if reason is not None:
            if not self._wrench_fault:
                self._wrench_fault = True
                self.log(f"hold: {reason}; the law holds its offset")
            return None
        if self._wrench_fault:
            self._wrench_fault = False
            self.log("resume: valid wrench")
        return self.law.force_along_normal([wrench.fx, wrench.fy, wrench.fz])

    def _on_status(self, payload: bytes) -> None:
        arrival = self._clock()
        if not self._newest_only:
            self._cycle(payload, arrival)
            return
        if self._pending is not None:
            self.timing.skipped += 1
        self._pending = (payload, arrival)

    def _cycle(self, payload: bytes, arrival: float) -> None:
        cpu = self._cpu_clock()
        status = lcmt_panda_status.decode(payload)
        dt = (status.utime - self._last_utime) * 1e-6 if self._last_status_wall else 0.0
        if self._last_status_wall is not None and status.utime <= self._last_utime:
            return  # a repeated or older status: nothing new to act on
        if dt > 1.5 * self.period:  # statuses that never arrived (or were skipped)
            self.timing.gaps += int(round(dt / self.period)) - 1
        self._last_utime = status.utime
        self._last_status_wall = arrival
        self.time = status.utime * 1e-6
        if self._status_lost:
            self._status_lost = False
            self.log("resume: status received")
        q = np.asarray(status.joint_position)
        v = np.asarray(status.joint_velocity)
        if not self.trace.times:
            self.log("start: first status")
        self.law.set_state(self.time, q, v)
        force = self._measured_force()
        if self._gains_fault:
            force = None  # the law holds its offset
        # One sample per period since the last status answered (a lost status's period
        # is the next one's), at most the status watchdog's count.
        samples = min(max(1, int(round(dt / self.period))), self.config.status_timeout_periods)
        command = self.law.step(self.time, q, v, math.nan if force is None else force, samples)
        offset = self.law.offset
        self._publish(status.utime, command)
        self.timing.record(arrival, self._clock(), self._cpu_clock() - cpu, self.time)
        self.trace.times.append(self.time)
        self.trace.force.append(float("nan") if force is None else force)
        self.trace.offset.append(offset)
        if self.time >= self._next_check:
            self._next_check = self.time + CHECK_INTERVAL
            self.check_measured_loop()
        if self.time >= self.config.duration - 1.5 * self.period:  # the station's last
            self.finished = True

    def check_measured_loop(self) -> dict | None:
        """The gains against the sampled loop at the period and delay the cycles since the
        last check measured (see the module docstring); logs a change of verdict; returns
        the check's figures (None: too few cycles)."""
        measured = self.timing.measured(self._checked_from)
        if measured is None:
            return None
        self._checked_from = self.timing.cycles
        nominal = measured["delay_periods"]
        # Delay in periods of the command's hold time (a skipped status holds it longer).
        period = max(measured["period"], self.period)
        delay = max(1, math.ceil(nominal * self.period / period - 1e-9))
        check = self.law.check_gains(period, delay)
        self.last_check = check
        figures = {"time": self.time, **measured, **check.as_dict()}
        self.gain_checks.append(figures)
        problem = check.problem()
        if not self.config.gain_check:
            if problem is not None:
                self.log(f"gain check (off): {problem}")
            return figures
        if problem is not None and not self._gains_fault:
            self._gains_fault = True
            self.log(f"hold: gains beyond the sampled loop's bounds: {problem}")
        elif problem is None and self._gains_fault:
            self._gains_fault = False
            self.log(
                f"resume: gains within the sampled loop's bounds at {1.0 / period:.4g} Hz, "
                f"command {delay} period(s) late"
            )
        return figures

    def stability_summary(self) -> dict:
        """timing.json's ``stability``: the start check and the checks while running."""
        unstable = [c for c in self.gain_checks if c["verdict"] != "stable"]
        return {
            "start": self.start_check.as_dict(),
            "checks": len(self.gain_checks),
            "unstable_checks": len(unstable),
            "last": self.gain_checks[-1] if self.gain_checks else None,
            "worst": max(
                self.gain_checks, key=lambda c: c["damper_gain"] / c["damper_limit"], default=None
            ),
            "history": [{key: check[key] for key in HISTORY_KEYS} for check in self.gain_checks],
        }

    def _publish(self, utime: int, values: np.ndarray) -> None:
        """The command: joint torques (torque mode) or joint positions (position mode)."""
        command = lcmt_panda_command()
        command.utime = int(utime)
        values = [float(x) for x in values]
        positions, torques = ([], values) if not self.position_mode else (values, [])
        command.num_joint_position = len(positions)
        command.joint_position = positions
        command.num_joint_velocity = 0
        command.joint_velocity = []
        command.num_joint_torque = len(torques)
        command.joint_torque = torques
        # PandaControlMode.kPosition (1) or kTorque (4).
        command.control_mode_expected = 1 if self.position_mode else 4
        self._lcm.Publish(CHANNELS.command, command.encode())
        self.last_command = command

    def _hold(self) -> None:
        """Publishes the last command's torques or positions again, with the last status's
        utime (before any command: zero torque; in position mode nothing, the robot holds
        the arm until its first command)."""
        if self.last_command is None:
            if not self.position_mode:
                self._publish(self._last_utime, np.zeros(NUM_JOINTS))
            return
        command = self.last_command
        values = command.joint_position if self.position_mode else command.joint_torque
        self._publish(self._last_utime, np.asarray(values))

    def safe_command(self, why: str) -> None:
        """Publishes the hold command (:meth:`_hold`); logs why."""
        self._hold()
        self.log(f"hold command: {why}")

    # --- the loop ------------------------------------------------------------------------

    def check_watchdogs(self) -> None:
        """The status watchdogs, on the wall clock.

        Raises:
            StationGoneError: no status for ``station_timeout`` s (or none at all within
                START_TIMEOUT s of starting).
        """
        now = self._clock()
        if self._last_status_wall is None:
            if now - self._started_wall > START_TIMEOUT:
                raise StationGoneError(
                    f"no status from the station on {CHANNELS.status} within {START_TIMEOUT:g} s"
                )
            return
        silent = now - self._last_status_wall
        if silent > self.config.station_timeout and self.time >= self.config.duration - END_SLACK:
            self.finished = True  # the station ended with the run (its last statuses lost)
            return
        if silent > self.config.station_timeout:
            self.safe_command("station gone")
            raise StationGoneError(
                f"no status from the station on {CHANNELS.status} for {silent:.2f} s "
                f"(last utime {self._last_utime * 1e-6:.3f} s)"
            )
        if silent > self.config.status_timeout_periods * self.period:
            if not self._status_lost:
                self._status_lost = True
                self.log(f"hold: no status for {silent / self.period:.1f} periods")
            self._hold()

    def poll(self, timeout: float) -> None:
        """Handles the messages that arrive within `timeout` s, then the watchdogs."""
        self._lcm.HandleSubscriptions(max(0, int(round(timeout * 1e3))))
        if self._pending is not None:
            payload, arrival = self._pending
            self._pending = None
            self._cycle(payload, arrival)
        self.check_watchdogs()

    def run(self, stop: Callable[[], bool] = lambda: False, report=None) -> str:
        """Runs until the status clock reaches ``duration`` ("done") or `stop()` ("stopped");
        `report(time, force, offset)` is called once per second of the status clock.

        Raises:
            StationGoneError: as check_watchdogs.
        """
        next_report = 1.0
        while not self.finished:
            if stop():
                self.safe_command("stop requested")
                return "stopped"
            self.poll(self.period)
            if report is not None and self.time is not None and self.time >= next_report:
                report(self.time, self.trace.force[-1], self.law.offset)
                next_report += 1.0
        self.safe_command("duration reached")
        return "done"
