"""Headless simulation of a scenario, its time series and its force metrics."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import EventStatus

from admittance.diagrams.closed_loop import BuildClosedLoop, ClosedLoop, SetInitialConditions
from admittance.diagrams.safety import (
    CapStepForSampledMonitor,
    SafetyLayer,
    fault_detection,
    safety_columns,
    safety_metrics,
)
from admittance.diagrams.scenario import Scenario
from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = [
    "SimulationDivergedError",
    "SimulationResult",
    "compute_metrics",
    "run_scenario",
    "settling_columns",
]

# Window over which "steady state" and "before an event" errors are averaged, s.
STEADY_WINDOW = 1.0
# Band around Fr that counts as settled (relative).
SETTLE_BAND = 0.05
# With sensor noise, settling is judged on the force averaged over this many noise samples,
# so that the ripple the noise leaves on the force (which no controller removes) does not
# hide that the loop has settled. Without noise the raw force is used.
SETTLE_AVERAGE_SAMPLES = 4
# A force above this fraction of Fr counts as contact (the tip may start touching the wall
# with zero force, which is not yet a contact).
CONTACT_FRACTION = 0.01


@dataclass
class SimulationResult:
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


def _time_mean(time: np.ndarray, values: np.ndarray) -> float:
    """Time-weighted mean (trapezoid) of samples at irregular times."""
    if time.size < 2 or time[-1] <= time[0]:
        return float(np.mean(values)) if values.size else math.nan
    return float(np.trapezoid(values, time) / (time[-1] - time[0]))


def _window(time: np.ndarray, start: float, end: float) -> np.ndarray:
    return (time >= start) & (time <= end)


def _until(time: np.ndarray, start: float, end: float) -> np.ndarray:
    """Samples in [start, end): at `end` the next event has happened (a sample logged at
    that very instant, as a sampled controller's step gives, already shows it). The run's
    last sample is kept when `end` is the end of the run."""
    if time.size and end >= time[-1]:
        return _window(time, start, end)
    return (time >= start) & (time < end)


def _trailing_average(time: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """Mean of `values` over [t - window, t] at each sample (trapezoid, irregular times)."""
    integral = np.concatenate([[0.0], np.cumsum(np.diff(time) * 0.5 * (values[1:] + values[:-1]))])
    start = np.maximum(time - window, time[0])
    span = time - start
    averaged = values.astype(float).copy()
    ok = span > 0
    averaged[ok] = (integral[ok] - np.interp(start[ok], time, integral)) / span[ok]
    return averaged


def _settling_time(time, force, reference, event_time, end_time) -> float | None:
    """Time after `event_time` from which |F - Fr| <= 5 % Fr until `end_time` (exclusive).

    `force` may be averaged first to ignore noise ripple (see compute_metrics).
    """
    mask = _until(time, event_time, end_time)
    t = time[mask]
    outside = np.abs(force[mask] - reference) > SETTLE_BAND * reference
    if t.size == 0 or outside[-1]:
        return None
    if not outside.any():
        return 0.0
    last_outside = np.nonzero(outside)[0][-1]
    return float(t[last_outside + 1] - event_time)


def compute_metrics(result: SimulationResult) -> dict:
    """The force metrics of metrics.json, plus per-event settling and contact losses."""
    time = result.time
    force = result.force
    reference = result.force_reference
    scenario = result.scenario
    duration = float(time[-1])
    error = np.abs(force - reference)
    in_contact = force > CONTACT_FRACTION * reference
    contact_indices = np.nonzero(in_contact)[0]
    first_contact = float(time[contact_indices[0]]) if contact_indices.size else None

    last = _window(time, duration - STEADY_WINDOW, duration)
    metrics: dict = {
        "peak_force": float(np.max(force)),
        "steady_state_force_error": _time_mean(time[last], error[last]),
        # Signed: above or below Fr at the end (steady_state_force_error is its magnitude).
        "final_mean_force": _time_mean(time[last], force[last]),
        "rms_force_error": None,
        "first_contact_time": first_contact,
        "contact_losses": 0,
        "last_contact_loss_time": None,
        "mean_abs_force_error_settled": None,
        "events": [],
        "wall_time": result.wall_time,
        "real_time_factor": duration / result.wall_time if result.wall_time > 0 else None,
        "integrator_steps": result.integrator_steps,
        "derivative_evaluations": result.derivative_evaluations,
        "samples": int(time.size),
    }
    tracking_error = np.abs(result.desired_position - result.pose)
    metrics["max_y_tracking_error"] = float(np.nanmax(tracking_error[:, 1]))
    metrics["max_theta_tracking_error"] = float(np.nanmax(tracking_error[:, 2]))
    metrics["first_contact_transient_end"] = None
    metrics["peak_force_after_first_contact_transient"] = None
    if first_contact is None:
        return metrics

    # The first contact transient (an impact, or the pre-load of a plan behind the wall)
    # ends when the force first enters the 5 % band around Fr; what follows is the
    # controller's to bound.
    reached = np.nonzero((time >= first_contact) & (error <= SETTLE_BAND * reference))[0]
    if reached.size:
        metrics["first_contact_transient_end"] = float(time[reached[0]])
        metrics["peak_force_after_first_contact_transient"] = float(np.max(force[reached[0] :]))
    after = time >= first_contact
    metrics["rms_force_error"] = math.sqrt(_time_mean(time[after], error[after] ** 2))
    # Contact losses: transitions from contact to no contact after first contact.
    lost = np.nonzero(in_contact[:-1] & ~in_contact[1:])[0]
    metrics["contact_losses"] = int(lost.size)
    if lost.size:
        metrics["last_contact_loss_time"] = float(time[lost[-1] + 1])

    # Events: stiffness steps and wall motion start/stop, plus first contact.
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
    sensor = scenario.sensor
    if sensor.kind != "ideal" and sensor.noise_std > 0:
        window = SETTLE_AVERAGE_SAMPLES * sensor.noise_period
        averaged_force = _trailing_average(time, force, window)
    else:
        averaged_force = force
    # Settled: at least one window after every event.
    settled = after.copy()
    for index, (kind, event_time) in enumerate(events):
        next_time = events[index + 1][1] if index + 1 < len(events) else duration
        before = _until(time, event_time - STEADY_WINDOW, event_time)
        window = _until(time, event_time, next_time)
        settled &= ~_window(time, event_time, event_time + STEADY_WINDOW)
        metrics["events"].append(
            {
                "kind": kind,
                "time": float(event_time),
                "mean_abs_force_error_before": (
                    _time_mean(time[before], error[before])
                    if kind != "first_contact" and before.sum() > 1
                    else None
                ),
                "peak_force_after": float(np.max(force[window])) if window.any() else None,
                "min_force_after": float(np.min(force[window])) if window.any() else None,
                "settling_time": _settling_time(
                    time, averaged_force, reference, event_time, next_time
                ),
            }
        )
    for fault in scenario.faults:
        settled &= ~_window(time, fault.start, fault.end)
    if settled.sum() > 1:
        metrics["mean_abs_force_error_settled"] = _time_mean(time[settled], error[settled])
    metrics["finite_actuation"] = bool(np.all(np.isfinite(result.actuation)))
    metrics["faults"] = []
    for fault in scenario.faults:
        during = _until(time, fault.start, min(fault.end, duration))
        recovery_end = min([e[1] for e in events if e[1] > fault.end] + [duration])
        after = _until(time, fault.end, recovery_end)
        metrics["faults"].append(
            {
                "kind": fault.kind,
                "start": fault.start,
                "end": fault.end,
                "worst_force_during": float(np.max(force[during])) if during.any() else None,
                # The danger of some faults comes when they end (a wall snapping back).
                "peak_force_after": float(np.max(force[after])) if after.any() else None,
                "recovery_time": _settling_time(
                    time, averaged_force, reference, fault.end, recovery_end
                ),
            }
        )
        if result.safety is not None:
            detections = safety_metrics(result)["detections"]
            metrics["faults"][-1].update(fault_detection(detections, fault.start, fault.end))
    if result.safety is not None:
        metrics["safety"] = safety_metrics(result)
        # Scalars for the sweep's table (it keeps the top-level scalars).
        metrics["safety_detections"] = len(metrics["safety"]["detections"])
        metrics["safety_final_stiffness_estimate"] = metrics["safety"]["final_stiffness_estimate"]
    if scenario.wall.velocity != 0.0:
        moving = _window(time, scenario.wall.motion_start, min(scenario.wall.motion_end, duration))
        if moving.any():
            metrics["force_min_while_wall_moves"] = float(np.min(force[moving]))
            metrics["force_max_while_wall_moves"] = float(np.max(force[moving]))
    return metrics


def settling_columns(metrics: dict) -> dict[str, float | None]:
    """The settling time after each event of `metrics` as flat columns.

    ``settling_<kind>_<i>`` (s; None = not settled before the next event), ``i`` counting
    the events of that kind from 0: the names of the sweep's and the comparison's tables.
    """
    columns: dict[str, float | None] = {}
    counts: dict[str, int] = {}
    for event in metrics.get("events", []):
        kind = event["kind"]
        columns[f"settling_{kind}_{counts.get(kind, 0)}"] = event["settling_time"]
        counts[kind] = counts.get(kind, 0) + 1
    return columns


def _log_data(loop: ClosedLoop, root_context, name: str):
    logger = loop.loggers[name]
    log = logger.FindLog(root_context)
    return log.sample_times(), log.data().T


# A run whose joint speed exceeds this is diverging (the arm's motors reach a few rad/s).
DIVERGED_JOINT_SPEED = 1e3  # rad/s


class SimulationDivergedError(RuntimeError):
    """The simulation blew up; `result` holds what was logged until then (failed=True)."""

    def __init__(self, message: str, result: SimulationResult) -> None:
        super().__init__(message)
        self.result = result


def _divergence_monitor(
    loop: ClosedLoop, found: list, progress: Callable[[float], None] | None = None
):
    """A Simulator monitor that stops at the first non-finite or runaway plant state, and
    tells `progress` the simulated time after each step."""
    plant = loop.plant
    num_positions = plant.num_positions()

    def monitor(root_context):
        if progress is not None:
            progress(root_context.get_time())
        state = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(root_context))
        if not np.all(np.isfinite(state)):
            found.append(f"the plant state is not finite at t = {root_context.get_time():.6g} s")
        elif np.max(np.abs(state[num_positions:])) > DIVERGED_JOINT_SPEED:
            found.append(
                f"a joint speed exceeds {DIVERGED_JOINT_SPEED:g} rad/s at "
                f"t = {root_context.get_time():.6g} s"
            )
        else:
            return EventStatus.Succeeded()
        return EventStatus.ReachedTermination(None, found[-1])

    return monitor


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
    simulator = Simulator(loop.diagram)
    ApplySimulatorConfig(scenario.simulator, simulator)
    if scenario.safety.enabled:
        CapStepForSampledMonitor(scenario, simulator)
    context = simulator.get_mutable_context()
    SetInitialConditions(loop, context)
    divergence: list[str] = []
    simulator.set_monitor(_divergence_monitor(loop, divergence, progress))
    simulator.Initialize()
    layer = loop.admittance if isinstance(loop.admittance, SafetyLayer) else None
    safety_numbers = layer.numbers(context) if layer is not None else None
    start = time.perf_counter()
    try:
        simulator.AdvanceTo(scenario.duration)
    except RuntimeError as error:  # e.g. the integrator cannot reach the accuracy
        divergence.append(
            f"the integrator failed at t = {context.get_time():.6g} s: {str(error).splitlines()[0]}"
        )
    wall_time = time.perf_counter() - start
    return _finished(_collect(loop, simulator, wall_time, safety_numbers), divergence)


def _finished(result, divergence: list[str]):
    """`result` marked failed or not in its metrics; raises SimulationDivergedError with it
    if `divergence` holds a reason (the last one is reported)."""
    if divergence:
        result.metrics["failed"] = True
        result.metrics["failure"] = divergence[-1]
        raise SimulationDivergedError(f"simulation diverged: {divergence[-1]}", result)
    result.metrics["failed"] = False
    return result


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
    kinematics = PlanarFrameKinematics(loop.plant, scenario.arm.fingertip_frame)
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
    result.metrics = compute_metrics(result)
    return result
