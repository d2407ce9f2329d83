"""Headless simulation of a scenario, its time series and its force metrics."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import Simulator

from admittance.diagrams.robots.planar_arm.loop import (
    BuildClosedLoop,
    ClosedLoop,
    SetInitialConditions,
)
from admittance.diagrams.robots.planar_arm.safety_layer import (
    CapStepForSampledMonitor,
    SafetyLayer,
    collision_reaction,
    first_contact_approach,
    reach_limit,
    safety_metrics,
    tip_speed,
)
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.run.engine import RunResult, finish_run, simulate_loop
from admittance.diagrams.run.metrics import (
    SETTLE_AVERAGE_SAMPLES,
    SETTLE_BAND,
    STEADY_WINDOW,
    contact_loss_indices,
    final_window,
    first_contact_time,
    in_contact,
    settling_time,
    time_mean,
    trailing_average,
    until_mask,
    window_mask,
)
from admittance.diagrams.run.safety_metrics import fault_detection, safety_columns
from admittance.diagrams.views.formatting import number, seconds
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

__all__ = [
    "arm_summary",
    "SimulationResult",
    "compute_metrics",
    "run_scenario",
]


@dataclass
class SimulationResult(RunResult):
    """Time series of one run, as plain arrays (SI units), and its metrics."""

    scenario: Scenario
    time: np.ndarray
    pose: np.ndarray  # (N, 3): x, y, theta of the fingertip
    desired_position: np.ndarray  # (N, 3): Xd
    reference_offset: np.ndarray  # (N, 3): Xr (zeros without the admittance block)
    force: np.ndarray  # (N,): true contact force
    force_measured: np.ndarray  # (N,)
    wall_position: np.ndarray  # (N,): Xe(t)
    wall_stiffness: np.ndarray  # (N,): Ke(t)
    joint_positions: np.ndarray  # (N, nq)
    joint_velocities: np.ndarray  # (N, nv)
    actuation: np.ndarray  # (N, nu): the PID's joint torques
    wall_time: float
    integrator_steps: int
    derivative_evaluations: int
    metrics: dict = field(default_factory=dict)
    # The safety layer's logs (safety.enabled): time, fault_flags, trusted_force,
    # observed_force, stiffness_estimate, gain_scale and its numbers at the start.
    safety: dict | None = None

    @property
    def force_reference(self) -> float:
        return self.scenario.force_reference

    def columns(self) -> dict[str, np.ndarray]:
        """The timeseries.csv columns, in order."""
        cartesian_error = self.desired_position + self.reference_offset - self.pose
        return {
            "time": self.time,
            "x": self.pose[:, 0],
            "y": self.pose[:, 1],
            "theta": self.pose[:, 2],
            "xd": self.desired_position[:, 0],
            "yd": self.desired_position[:, 1],
            "thetad": self.desired_position[:, 2],
            "xr": self.reference_offset[:, 0],
            "ex": cartesian_error[:, 0],
            "ey": cartesian_error[:, 1],
            "etheta": cartesian_error[:, 2],
            "force": self.force,
            "force_measured": self.force_measured,
            "force_reference": np.full_like(self.time, self.force_reference),
            "wall_position": self.wall_position,
            "wall_stiffness": self.wall_stiffness,
        } | (safety_columns(self.safety) if self.safety is not None else {})


def compute_metrics(result: SimulationResult) -> dict:
    """The force metrics of metrics.json, plus per-event settling and contact losses."""
    series = _ForceSeries.of(result)
    contact = in_contact(series.force, series.reference)
    first_contact = first_contact_time(series.time, contact)
    metrics = _run_metrics(result, series, first_contact)
    if first_contact is None:
        # A run that never touches: the layer's section still says what it was held to.
        _add_safety_metrics(metrics, result)
        return metrics
    after = _add_contact_metrics(metrics, series, contact, first_contact)
    scenario = result.scenario
    events = _events(scenario, first_contact, series.duration)
    averaged_force = _averaged_force(series, scenario)
    # Settled: at least one window after every event, and outside every fault.
    settled = after & _add_event_metrics(metrics, series, averaged_force, events)
    for fault in scenario.faults:
        settled &= ~window_mask(series.time, fault.start, fault.end)
    if settled.sum() > 1:
        metrics["mean_abs_force_error_settled"] = time_mean(
            series.time[settled], series.error[settled]
        )
    metrics["finite_actuation"] = bool(np.all(np.isfinite(result.actuation)))
    metrics["faults"] = _fault_metrics(result, series, averaged_force, events)
    _add_safety_metrics(metrics, result)
    _add_wall_motion_metrics(metrics, result, series)
    return metrics


@dataclass
class _ForceSeries:
    """The run's force against Fr: time, force, Fr, |F - Fr| and the simulated duration."""

    time: np.ndarray
    force: np.ndarray
    reference: float
    error: np.ndarray
    duration: float

    @classmethod
    def of(cls, result: SimulationResult) -> _ForceSeries:
        time, force, reference = result.time, result.force, result.force_reference
        return cls(time, force, reference, np.abs(force - reference), float(time[-1]))


def _run_metrics(result: SimulationResult, series: _ForceSeries, first_contact) -> dict:
    """The metrics of every run, in contact or not: the peak and the final window, the
    run's cost, the tracking of y and theta; the contact metrics still None."""
    time, force, error = series.time, series.force, series.error
    last = final_window(time)
    metrics: dict = {
        "peak_force": float(np.max(force)),
        "steady_state_force_error": time_mean(time[last], error[last]),
        # Signed: above or below Fr at the end (steady_state_force_error is its magnitude).
        "final_mean_force": time_mean(time[last], force[last]),
        "rms_force_error": None,
        "first_contact_time": first_contact,
        "contact_losses": 0,
        "last_contact_loss_time": None,
        "mean_abs_force_error_settled": None,
        "events": [],
        "wall_time": result.wall_time,
        "real_time_factor": series.duration / result.wall_time if result.wall_time > 0 else None,
        "integrator_steps": result.integrator_steps,
        "derivative_evaluations": result.derivative_evaluations,
        "samples": int(time.size),
    }
    tracking_error = np.abs(result.desired_position - result.pose)
    metrics["max_y_tracking_error"] = float(np.nanmax(tracking_error[:, 1]))
    metrics["max_theta_tracking_error"] = float(np.nanmax(tracking_error[:, 2]))
    metrics["first_contact_transient_end"] = None
    metrics["peak_force_after_first_contact_transient"] = None
    return metrics


def _add_contact_metrics(
    metrics: dict, series: _ForceSeries, contact: np.ndarray, first_contact: float
) -> np.ndarray:
    """The first contact's transient, the RMS error after it and the contact losses;
    returns the samples from first contact on."""
    time, force, error = series.time, series.force, series.error
    # The first contact transient (an impact, or the pre-load of a plan behind the wall)
    # ends when the force first enters the 5 % band around Fr; what follows is the
    # controller's to bound.
    reached = np.nonzero((time >= first_contact) & (error <= SETTLE_BAND * series.reference))[0]
    if reached.size:
        metrics["first_contact_transient_end"] = float(time[reached[0]])
        metrics["peak_force_after_first_contact_transient"] = float(np.max(force[reached[0] :]))
    after = time >= first_contact
    metrics["rms_force_error"] = math.sqrt(time_mean(time[after], error[after] ** 2))
    # Contact losses: transitions from contact to no contact after first contact.
    lost = contact_loss_indices(contact)
    metrics["contact_losses"] = int(lost.size)
    if lost.size:
        metrics["last_contact_loss_time"] = float(time[lost[-1] + 1])
    return after


def _events(scenario: Scenario, first_contact: float, duration: float) -> list[tuple]:
    """(kind, time) of the run's events, in time order: first contact, stiffness steps,
    the wall's motion starting and stopping, each fault's start and end."""
    events = [("first_contact", first_contact)]
    events += [
        ("stiffness_step", s.time) for s in scenario.wall.stiffness_steps if s.time < duration
    ]
    if scenario.wall.velocity != 0.0:
        events.append(("wall_starts", scenario.wall.motion_start))
        if scenario.wall.motion_end < duration:
            events.append(("wall_stops", scenario.wall.motion_end))
    for fault in scenario.faults:
        events += [(f"{fault.kind}_starts", fault.start), (f"{fault.kind}_ends", fault.end)]
    events = [event for event in events if event[1] < duration]
    events.sort(key=lambda e: e[1])
    return events


def _averaged_force(series: _ForceSeries, scenario: Scenario) -> np.ndarray:
    """The force that settling is read on: a noisy sensor's reading averaged over
    SETTLE_AVERAGE_SAMPLES of its noise periods, else the force itself."""
    sensor = scenario.sensor
    if sensor.kind != "ideal" and sensor.noise_std > 0:
        window = SETTLE_AVERAGE_SAMPLES * sensor.noise_period
        return trailing_average(series.time, series.force, window)
    return series.force


def _add_event_metrics(
    metrics: dict, series: _ForceSeries, averaged_force: np.ndarray, events: list[tuple]
) -> np.ndarray:
    """metrics["events"]: per event, the error before it, the force after it until the
    next and the settling time; returns the samples outside every event's first window."""
    time, force, error = series.time, series.force, series.error
    outside = np.ones(time.shape, dtype=bool)
    for index, (kind, event_time) in enumerate(events):
        next_time = events[index + 1][1] if index + 1 < len(events) else series.duration
        before = until_mask(time, event_time - STEADY_WINDOW, event_time)
        window = until_mask(time, event_time, next_time)
        outside &= ~window_mask(time, event_time, event_time + STEADY_WINDOW)
        metrics["events"].append(
            {
                "kind": kind,
                "time": float(event_time),
                "mean_abs_force_error_before": (
                    time_mean(time[before], error[before])
                    if kind != "first_contact" and before.sum() > 1
                    else None
                ),
                "peak_force_after": float(np.max(force[window])) if window.any() else None,
                "min_force_after": float(np.min(force[window])) if window.any() else None,
                "settling_time": settling_time(
                    time, averaged_force, series.reference, event_time, next_time
                ),
            }
        )
    return outside


def _fault_metrics(
    result: SimulationResult,
    series: _ForceSeries,
    averaged_force: np.ndarray,
    events: list[tuple],
) -> list[dict]:
    """metrics["faults"]: per fault, the worst force during it, the peak after it, the
    recovery time, and (with the safety layer) its detection and collision reaction."""
    time, force, duration = series.time, series.force, series.duration
    faults = []
    for fault in result.scenario.faults:
        during = until_mask(time, fault.start, min(fault.end, duration))
        recovery_end = min([e[1] for e in events if e[1] > fault.end] + [duration])
        after = until_mask(time, fault.end, recovery_end)
        faults.append(
            {
                "kind": fault.kind,
                "start": fault.start,
                "end": fault.end,
                "worst_force_during": float(np.max(force[during])) if during.any() else None,
                # The danger of some faults comes when they end (a wall snapping back).
                "peak_force_after": float(np.max(force[after])) if after.any() else None,
                "recovery_time": settling_time(
                    time, averaged_force, series.reference, fault.end, recovery_end
                ),
            }
        )
        if result.safety is not None:
            detections = safety_metrics(result)["detections"]
            faults[-1].update(fault_detection(detections, fault.start, fault.end))
            if fault.kind == "joint_torque":
                faults[-1].update(
                    collision_reaction(result, fault.start, faults[-1]["detected_time"])
                )
    return faults


def _add_wall_motion_metrics(metrics: dict, result: SimulationResult, series: _ForceSeries) -> None:
    """The least and the largest force while the wall moves (a moving wall only)."""
    wall = result.scenario.wall
    if wall.velocity != 0.0:
        moving = window_mask(series.time, wall.motion_start, min(wall.motion_end, series.duration))
        if moving.any():
            metrics["force_min_while_wall_moves"] = float(np.min(series.force[moving]))
            metrics["force_max_while_wall_moves"] = float(np.max(series.force[moving]))


def _add_safety_metrics(metrics: dict, result: SimulationResult) -> None:
    """metrics.json's ``safety`` section and its scalars (safety.enabled only)."""
    if result.safety is None:
        return
    metrics["safety"] = safety_metrics(result)
    # Scalars for the sweep's table (it keeps the top-level scalars).
    metrics["safety_detections"] = len(metrics["safety"]["detections"])
    metrics["safety_final_stiffness_estimate"] = metrics["safety"]["final_stiffness_estimate"]
    metrics["safety_reach_limited"] = metrics["safety"]["reach_limited"]
    stiffer = metrics["safety"]["stiffer_than_stated"]
    if stiffer is not None:
        # What the layer held after it backed off (docs/evidence/safety-beyond-bounds.md, section
        # 7).
        after = result.time >= stiffer["time"]
        contact = in_contact(result.force[after], result.scenario.force_reference)
        stiffer["peak_force_after"] = float(np.max(result.force[after]))
        stiffer["contact_losses_after"] = int(contact_loss_indices(contact).size)


def _log_data(loop: ClosedLoop, root_context, name: str):
    logger = loop.loggers[name]
    log = logger.FindLog(root_context)
    return log.sample_times(), log.data().T


def run_scenario(
    scenario: Scenario,
    *,
    loop: ClosedLoop | None = None,
    progress: Callable[[float], None] | None = None,
) -> SimulationResult:
    """Builds (unless given), initializes and simulates `scenario`; returns its time series.

    Args:
        progress: called with the simulated time (s) after every integrator step.

    Raises:
        SimulationDivergedError: the run blew up; the exception carries the partial result.
    """
    loop = loop or BuildClosedLoop(scenario)
    layer = loop.admittance if isinstance(loop.admittance, SafetyLayer) else None
    numbers: list[dict] = []
    run = simulate_loop(
        loop.diagram,
        loop.plant,
        scenario.simulator,
        scenario.duration,
        initialize=lambda context: SetInitialConditions(loop, context),
        configure=(
            (lambda simulator: CapStepForSampledMonitor(scenario, simulator))
            if scenario.safety.enabled
            else None
        ),
        initialized=(lambda context: numbers.append(layer.numbers(context))) if layer else None,
        progress=progress,
    )
    safety_numbers = numbers[0] if numbers else None
    return finish_run(_collect(loop, run.simulator, run.wall_time, safety_numbers), run.divergence)


def _collect(
    loop: ClosedLoop, simulator: Simulator, wall_time: float, safety_numbers: dict | None = None
) -> SimulationResult:
    """The logged time series as plain arrays, with their metrics."""
    scenario = loop.scenario
    context = simulator.get_context()
    sample_times, states = _log_data(loop, context, "state")
    _, contact_force = _log_data(loop, context, "contact_force")
    _, measured = _log_data(loop, context, "measured_force")
    _, desired = _log_data(loop, context, "desired_position")
    _, actuation = _log_data(loop, context, "actuation")
    if "reference_offset" in loop.loggers:
        _, offset = _log_data(loop, context, "reference_offset")
    else:
        offset = np.zeros_like(desired)

    # Fingertip pose from the logged plant state, once, at the end.
    kinematics = PlanarFrameKinematics(
        loop.plant, scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    pose = np.full((sample_times.size, 3), np.nan)
    for row, state in enumerate(states):
        if np.all(np.isfinite(state)):
            kinematics.set_state(state)
            pose[row] = kinematics.pose()
    integrator = simulator.get_integrator()
    result = SimulationResult(
        scenario=scenario,
        time=sample_times,
        pose=pose,
        desired_position=desired,
        reference_offset=offset,
        force=contact_force[:, 0],
        force_measured=measured[:, 0],
        wall_position=np.array([loop.wall.position_at(t) for t in sample_times]),
        wall_stiffness=np.array([loop.wall.stiffness_at(t) for t in sample_times]),
        joint_positions=states[:, : loop.plant.num_positions()],
        joint_velocities=states[:, loop.plant.num_positions() :],
        actuation=actuation,
        wall_time=wall_time,
        integrator_steps=int(integrator.get_num_steps_taken()),
        derivative_evaluations=int(integrator.get_num_derivative_evaluations()),
    )
    if safety_numbers is not None:
        result.safety = {"time": sample_times, "numbers": safety_numbers}
        for name in loop.admittance.log_ports():
            result.safety[name] = _log_data(loop, context, name)[1]
        result.safety["first_contact"] = first_contact_approach(result, loop.admittance.law)
        if any(fault.kind == "joint_torque" for fault in scenario.faults):
            result.safety["tip_speed"] = tip_speed(result, loop.plant)
        result.safety["reach_limited_time"] = reach_limit(
            result, loop.plant, loop.pid.effort_limits
        )
    result.metrics = compute_metrics(result)
    return result


def arm_summary(result: SimulationResult) -> str:
    """A few lines for the terminal."""
    m = result.metrics
    lines = [
        f"scenario {result.scenario.name}: {number(float(result.time[-1]), ' s')} simulated in "
        f"{seconds(m['wall_time'])} (real-time factor {number(m['real_time_factor'])}), "
        f"{number(m['integrator_steps'])} steps",
        f"  first contact {number(m['first_contact_time'], ' s')}, peak force "
        f"{number(m['peak_force'], ' N')} (Fr = {number(result.force_reference, ' N')}), "
        f"contact losses {number(m['contact_losses'])}",
        f"  force error: steady state {number(m['steady_state_force_error'], ' N')}, rms "
        f"{number(m['rms_force_error'], ' N')}, settled mean "
        f"{number(m['mean_abs_force_error_settled'], ' N')}",
    ]
    for event in m["events"]:
        lines.append(
            f"  {event['kind']} at {number(event['time'], ' s')}: settles (5 %) in "
            f"{number(event['settling_time'], ' s')}, "
            f"peak after {number(event['peak_force_after'], ' N')}"
        )
    if m.get("safety", {}).get("reach_limited"):
        lines.append(
            f"  safety: reach limited at {number(m['safety']['reach_limited_time'], ' s')}: "
            "the force passed Fmax where the arm could not follow the layer's command"
        )
    return "\n".join(lines)
