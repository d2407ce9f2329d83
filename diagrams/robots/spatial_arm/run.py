"""Simulating a spatial-arm scenario: the force along the planned normal, the tool's path
and orientation over the slide, and the metrics of a polishing task.

The SLIDE WINDOW runs from the end of the press (approach, force ramp and press_time: the
press has settled) to the slide's return, or to the end of the run without a slide; over
it:

* ``normal_force_rms_error``, ``normal_force_max_error`` (N): the true force of the tool on
  the table along the planned normal (the control frame's z: the contact engine's, friction
  included) against Fr;
* ``contact_losses``: how often that force drops below CONTACT_FRACTION Fr;
* ``path_error_max`` (m): the tool tip's distance from Xd in the planned table's plane (x
  and y of the control frame, the axes under position control);
* ``orientation_error_max`` (degrees): the angle between the tool's orientation and the
  plan's, |log(R_d R^T)| (the plan holds the tool along the planned normal).

With ``safety.enabled`` a ``safety`` section adds the layer's numbers at the start (the
apparent mass along the normal, the damper, the approach bound v_max, ...), the tool tip's
speed along the normal at the last sample before the first contact
(``first_contact_speed``, against ``approach_speed``), the largest force within
FIRST_CONTACT_WINDOW of the first contact (``first_contact_peak_force``, against
``max_force``), each detection of the sensor monitor (time, kind), the final stiffness
estimate and gain scale; the timeseries gains ``force_observed`` (the momentum observer's
force along the normal), ``force_trusted``, ``stiffness_estimate``, ``gain_scale`` and one
``fault_<kind>`` column per flag.

The metrics every robot shares (``peak_force``, ``steady_state_force_error`` over the last
second, ``rms_force_error`` from the end of the force ramp, ``first_contact_time``,
``settling_time`` from the end of the ramp) come from run.metrics.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import SimulatorConfig

from admittance.diagrams.robots.spatial_arm.loop import (
    BuildSpatialLoop,
    CheckSpatialPlan,
    SetSpatialInitialConditions,
    SpatialLoop,
)
from admittance.diagrams.robots.spatial_arm.plant import NORMAL_AXIS
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES, SpatialScenario
from admittance.diagrams.run.engine import RunResult, finish_run, simulate_loop
from admittance.diagrams.run.metrics import (
    contact_loss_indices,
    final_window,
    first_contact_time,
    in_contact,
    settled_from,
    time_mean,
    until_mask,
)
from admittance.diagrams.run.safety_metrics import rising_edges
from admittance.diagrams.views.formatting import number, seconds
from admittance.systems.fault_detector import FAULT_FLAGS
from admittance.systems.spatial_kinematics import orientation_error

__all__ = [
    "spatial_summary",
    "FIRST_CONTACT_WINDOW",
    "SpatialResult",
    "compute_spatial_metrics",
    "run_spatial",
    "spatial_safety_metrics",
    "spatial_verdict_line",
]

SIZE = len(SPATIAL_COORDINATES)
# The first contact's impact: its peak comes a half period of the contact mode after the
# touch (25 ms for 6.6 kg on 1e5 N/m), well inside this window, s.
FIRST_CONTACT_WINDOW = 0.1


@dataclass
class SpatialResult(RunResult):
    """Time series of one spatial-arm run (SI units) and its metrics."""

    scenario: SpatialScenario
    time: np.ndarray
    force: np.ndarray  # (N,): the true force along the planned normal
    force_measured: np.ndarray  # (N,): what the force law read
    force_reference: np.ndarray  # (N,): Fr(t)
    plan: np.ndarray  # (N, 6): Xd in the control frame
    pose: np.ndarray  # (N, 6): X of the tool tip in the control frame
    reference_offset: np.ndarray  # (N,): Xr along z (zeros for pid_only)
    joint_positions: np.ndarray  # (N, nq)
    wall_time: float
    steps: int
    metrics: dict = field(default_factory=dict)
    # (N,): the tool tip's speed along the normal (the control frame's z), m/s.
    normal_speed: np.ndarray | None = None
    # With safety.enabled: the layer's logs ("observed_force", "gain_scale") and its
    # numbers at the start ("numbers"); empty otherwise.
    safety: dict = field(default_factory=dict)

    @property
    def path_error(self) -> np.ndarray:
        """|X - Xd| in the planned table's plane (x, y of the control frame), m."""
        error = self.pose[:, :2] - self.plan[:, :2]
        return np.hypot(error[:, 0], error[:, 1])

    @property
    def orientation_error(self) -> np.ndarray:
        """The angle between the tool's orientation and the plan's, |log(R_d R^T)|, degrees."""
        errors = [
            orientation_error(desired, actual)
            for desired, actual in zip(
                self.plan[:, 3:6].tolist(), self.pose[:, 3:6].tolist(), strict=True
            )
        ]
        return np.degrees(np.linalg.norm(np.array(errors).reshape(-1, 3), axis=1))

    def columns(self) -> dict[str, np.ndarray]:
        """The timeseries.csv columns, in order."""
        columns = {
            "time": self.time,
            "force": self.force,
            "force_measured": self.force_measured,
            "force_reference": self.force_reference,
        }
        for index, name in enumerate(SPATIAL_COORDINATES):
            columns[name] = self.pose[:, index]
        for index, name in enumerate(SPATIAL_COORDINATES[:3]):
            columns[f"{name}d"] = self.plan[:, index]
        columns["zr"] = self.reference_offset
        columns["path_error"] = self.path_error
        columns["orientation_error"] = self.orientation_error
        if self.safety:
            for name in ("observed", "trusted"):
                columns[f"force_{name}"] = self.safety[f"{name}_force"][:, 0]
            for name in ("stiffness_estimate", "gain_scale"):
                columns[name] = self.safety[name][:, 0]
            for column, kind in enumerate(FAULT_FLAGS):
                columns[f"fault_{kind}"] = self.safety["fault_flags"][:, column]
            columns["collision"] = self.safety["collision"][:, 0]
        return columns


def compute_spatial_metrics(result: SpatialResult) -> dict:
    """metrics.json of a spatial-arm run (see the module's docstring)."""
    scenario = result.scenario
    time, force = result.time, result.force
    reference = scenario.force_reference
    duration = float(time[-1])
    ramp_end = scenario.press_start + scenario.trajectory.force_ramp_time
    start, end = scenario.slide_start, min(scenario.slide_end, duration)
    if end <= start:
        end = duration
    window = until_mask(time, start, end)
    error = force - reference
    contact = in_contact(force, reference)
    after_ramp = time >= ramp_end
    last = final_window(time)
    settled = settled_from(time, force, reference, ramp_end)
    metrics = {
        "kind": "spatial",
        "controller": scenario.controller.kind,
        "force_reference": reference,
        "slide_window": [start, end],
        "normal_force_rms_error": math.sqrt(time_mean(time[window], error[window] ** 2)),
        "normal_force_max_error": float(np.max(np.abs(error[window]))),
        "contact_losses": int(contact_loss_indices(contact[window]).size),
        "in_contact_over_slide": bool(np.all(contact[window])),
        "path_error_max": float(np.max(result.path_error[window])),
        "orientation_error_max": float(np.max(result.orientation_error[window])),
        "peak_force": float(np.max(force)),
        "min_force_over_slide": float(np.min(force[window])),
        "steady_state_force_error": time_mean(time[last], np.abs(error[last])),
        "rms_force_error": math.sqrt(time_mean(time[after_ramp], error[after_ramp] ** 2)),
        "first_contact_time": first_contact_time(time, contact),
        "settling_time": None if settled is None else settled - ramp_end,
        "max_reference_offset": float(np.max(np.abs(result.reference_offset))),
        "wall_time": result.wall_time,
        "real_time_factor": duration / result.wall_time if result.wall_time > 0 else None,
        "steps": result.steps,
        "samples": int(time.size),
    }
    if result.safety:
        metrics["safety"] = spatial_safety_metrics(result)
    return metrics


def spatial_safety_metrics(result: SpatialResult) -> dict:
    """metrics.json's ``safety`` section (see the module's docstring)."""
    logs, force = result.safety, result.force
    metrics = {key: float(value) for key, value in logs["numbers"].items() if key != "in_contact"}
    metrics["max_force"] = result.scenario.safety.max_force
    touching = np.nonzero(force > 0.0)[0]
    if touching.size and touching[0] > 0:
        touch = result.time[touching[0]]
        window = (result.time >= touch) & (result.time <= touch + FIRST_CONTACT_WINDOW)
        metrics["first_contact_speed"] = float(result.normal_speed[touching[0] - 1])
        metrics["first_contact_peak_force"] = float(np.max(force[window]))
    metrics.update(logs.get("first_contact", {}))
    metrics["detections"] = rising_edges(
        result.time, np.hstack([logs["fault_flags"], logs["collision"]])
    )
    metrics["final_stiffness_estimate"] = float(logs["stiffness_estimate"][-1, 0])
    metrics["final_gain_scale"] = float(logs["gain_scale"][-1, 0])
    return metrics


def run_spatial(
    scenario: SpatialScenario,
    *,
    loop: SpatialLoop | None = None,
    progress: Callable[[float], None] | None = None,
) -> SpatialResult:
    """Builds (unless given), initializes and simulates a spatial-arm scenario.

    Raises:
        ScenarioError: the model cannot be loaded, or the arm cannot reach, follow or press
            with the plan (robots.spatial_arm.loop.CheckSpatialPlan).
        SimulationDivergedError: the run blew up (the exception carries the partial result).
    """
    loop = loop or BuildSpatialLoop(scenario)
    CheckSpatialPlan(loop)
    numbers = {}

    def initialize(context) -> None:
        SetSpatialInitialConditions(loop, context)
        if loop.safety is not None:
            loop.safety.initialize(context)
            numbers.update(loop.safety.numbers(context))

    run = simulate_loop(
        loop.diagram,
        loop.plant,
        # The plant and the controllers are discrete; only a classical admittance's state
        # is continuous, integrated between the steps.
        SimulatorConfig(),
        scenario.duration,
        initialize=initialize,
        progress=progress,
        solver="simulation",
    )
    steps = int(round(run.context.get_time() / scenario.time_step))
    result = _collect(loop, run.context, run.wall_time, steps, numbers)
    return finish_run(result, run.divergence)


def _collect(loop: SpatialLoop, context, wall_time: float, steps: int, numbers) -> SpatialResult:
    def logged(name: str) -> np.ndarray:
        return loop.loggers[name].FindLog(context).data().T

    sample_times = loop.loggers["state"].FindLog(context).sample_times()
    count = sample_times.size
    states = logged("state")
    kinematics = logged("kinematics")
    if "reference_offset" in loop.loggers:
        offset = logged("reference_offset")[:, 2]
    else:
        offset = np.zeros(count)
    result = SpatialResult(
        scenario=loop.scenario,
        time=sample_times,
        force=logged("contact_force")[:, 0],
        force_measured=logged("measured_force")[:, 0],
        force_reference=logged("force_reference")[:, 0],
        plan=logged("plan")[:, :SIZE],
        pose=kinematics[:, :SIZE],
        reference_offset=offset,
        joint_positions=states[:, : loop.plant.num_positions()],
        wall_time=wall_time,
        steps=steps,
        normal_speed=kinematics[:, SIZE + NORMAL_AXIS],
    )
    if loop.safety is not None:
        result.safety = {name: logged(name) for name in loop.safety.log_ports()}
        result.safety["numbers"] = numbers
        result.safety["first_contact"] = _first_contact_bound(loop, result, states)
    result.metrics = compute_spatial_metrics(result)
    return result


def _first_contact_bound(loop: SpatialLoop, result: SpatialResult, states) -> dict:
    """The approach bound v_max and the apparent mass the layer derives at the last sample
    before the first contact (empty if the run never touches the table)."""
    touching = np.nonzero(result.force > 0.0)[0]
    if touching.size == 0 or touching[0] == 0:
        return {}
    numbers = loop.safety.law.numbers_at(states[touching[0] - 1], result.scenario.force_reference)
    return {
        "first_contact_approach_bound": float(numbers["approach_speed"]),
        "first_contact_apparent_mass": float(numbers["apparent_mass"]),
    }


def spatial_verdict_line(result: SpatialResult) -> str:
    """One line: the force error, contact, path and orientation over the slide."""
    m = result.metrics
    return (
        f"over the slide: normal force rms error {m['normal_force_rms_error']:.3g} N, max "
        f"{m['normal_force_max_error']:.3g} N (Fr = {m['force_reference']:g} N), contact "
        f"losses {m['contact_losses']}, path error max {1e3 * m['path_error_max']:.3g} mm, "
        f"orientation error max {m['orientation_error_max']:.3g} deg"
    )


def spatial_summary(result: SpatialResult) -> str:
    """A few lines for the terminal."""
    m = result.metrics
    return "\n".join(
        [
            f"scenario {result.scenario.name}: {number(float(result.time[-1]), ' s')} simulated "
            f"in {seconds(m['wall_time'])} (real-time factor {number(m['real_time_factor'])}), "
            f"{m['steps']} steps",
            f"  first contact {number(m['first_contact_time'], ' s')}, peak force "
            f"{number(m['peak_force'], ' N')}, steady-state force error "
            f"{number(m['steady_state_force_error'], ' N')}",
            f"  {spatial_verdict_line(result)}",
        ]
    )
