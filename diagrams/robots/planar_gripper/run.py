"""Simulating a grasp scenario: per-finger forces, the brick's pose and slip, and the verdict.

A grasp HOLDS when, after every desired force has reached its Fr (the end of the plan's
force ramp), every finger is in contact with the brick, no normal force exceeds
CRUSH_FACTOR Fr and the brick drops by less than DROP_LIMIT. It CRUSHES the brick when a
finger's force exceeds CRUSH_FACTOR Fr, and otherwise LOSES it: a finger is off the brick
(it never reached it, or let go) or the brick sank DROP_LIMIT or more.

The grasp SETTLES when every finger's true normal force is within SETTLE_BAND of its Fr
from then to the end of the run (or, with a disturbance, to its start); the brick's drop
and each finger's slip are measured from that moment (from the end of the ramp if it never
settles), and so are the brick's displacement in each direction (y, z both ways, theta)
and each finger's slip rate (a least-squares slope over the hold). A disturbance is
reported on its own: the peak forces after it, whether every finger kept contact, and its
RECOVERY TIME, from its start until every force is back within SETTLE_BAND of Fr to the
end of the run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from admittance.diagrams.robots.planar_gripper.loop import (
    BuildGrasp,
    GraspLoop,
    SetGraspInitialConditions,
)
from admittance.diagrams.robots.planar_gripper.plant import (
    BRICK_BODY,
    BRICK_JOINTS,
    FINGER_COORDINATES,
    contact_frame,
    tip_centre_frame,
)
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GraspScenario
from admittance.diagrams.run.engine import RunResult, finish_run, simulate_loop
from admittance.diagrams.run.metrics import (
    contact_loss_indices,
    final_window,
    first_contact_time,
    in_contact,
    least_squares_slope,
    settled_from,
    time_mean,
)
from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = [
    "grasp_summary",
    "CRUSH_FACTOR",
    "DROP_LIMIT",
    "GraspResult",
    "compute_grasp_metrics",
    "grasp_verdict_line",
    "run_grasp",
]

# A normal force above this many times Fr crushes the brick.
CRUSH_FACTOR = 10.0
# A brick that sinks this far after the grasp settles is lost, m.
DROP_LIMIT = 1e-3


@dataclass
class GraspResult(RunResult):
    """Time series of one grasp (SI units) and its metrics."""

    scenario: GraspScenario
    time: np.ndarray
    force: np.ndarray  # (N, 3): the contact engine's normal force on each fingertip
    force_measured: np.ndarray  # (N, 3)
    force_reference: np.ndarray  # (N, 3): Fr_i(t)
    plan: np.ndarray  # (N, 3, 2): Xd of each finger in its face frame (normal, tangent)
    reference_offset: np.ndarray  # (N, 3, 2): Xr (zeros for pid_only)
    tip: np.ndarray  # (N, 3, 2): each tip centre in its face frame
    slip: np.ndarray  # (N, 3): tip centre along the brick's face, from the hold start
    brick_pose: np.ndarray  # (N, 3): brick y, z (m) and theta (rad)
    joint_positions: np.ndarray  # (N, nq)
    wall_time: float
    steps: int
    metrics: dict = field(default_factory=dict)

    def columns(self) -> dict[str, np.ndarray]:
        """The timeseries.csv columns, in order."""
        hold_start = self.metrics.get("hold_start", 0.0)
        reference_z = np.interp(hold_start, self.time, self.brick_pose[:, 1])
        columns = {"time": self.time}
        for index, finger in enumerate(FINGERS):
            columns[f"{finger}_force"] = self.force[:, index]
            columns[f"{finger}_force_measured"] = self.force_measured[:, index]
            columns[f"{finger}_force_reference"] = self.force_reference[:, index]
            columns[f"{finger}_xd"] = self.plan[:, index, 0]
            columns[f"{finger}_xr"] = self.reference_offset[:, index, 0]
            columns[f"{finger}_x"] = self.tip[:, index, 0]
            columns[f"{finger}_y"] = self.tip[:, index, 1]
            columns[f"{finger}_slip"] = self.slip[:, index]
        columns["brick_y"] = self.brick_pose[:, 0]
        columns["brick_z"] = self.brick_pose[:, 1]
        columns["brick_theta"] = self.brick_pose[:, 2]
        columns["brick_drop"] = reference_z - self.brick_pose[:, 1]
        return columns


def _brick_displacement(time, pose, hold_start, holding) -> dict:
    """The brick's pose from the hold's start, over the hold: each direction, both signs.

    y and z in m, theta in rad; `final` is (y, z, theta) at the hold's last sample.
    """
    start = np.array([np.interp(hold_start, time, pose[:, i]) for i in range(3)])
    moved = pose[holding] - start
    y, z, theta = moved.T
    return {
        "max_rise": max(0.0, float(np.max(z))),
        "max_drop": max(0.0, float(-np.min(z))),
        "max_abs_y": float(np.max(np.abs(y))),
        "max_abs_rotation": float(np.max(np.abs(theta))),
        "final": moved[-1].tolist(),
        "rate": [least_squares_slope(time[holding], values) for values in (y, z, theta)],
    }


def compute_grasp_metrics(result: GraspResult) -> dict:
    """metrics.json of a grasp: the verdict, the brick, and every finger's forces."""
    scenario = result.scenario
    time = result.time
    duration = float(time[-1])
    ramp_end = scenario.force_ramp_end
    references = np.asarray(scenario.force_reference)
    disturbance = scenario.disturbance
    # The undisturbed hold ends where a disturbance starts.
    hold_end = disturbance.start if disturbance.kind != "none" else np.inf
    settle_times = [
        settled_from(time, result.force[:, i], references[i], ramp_end, hold_end) for i in range(3)
    ]
    settled = None if None in settle_times else max(settle_times)
    hold_start = settled if settled is not None else ramp_end
    holding = (time >= hold_start) & (time < hold_end)
    z = result.brick_pose[:, 1]
    z_start = float(np.interp(hold_start, time, z))
    brick_drop = max(0.0, float(np.max(z_start - z[holding])))
    fingers = [
        _finger_metrics(result, index, settle_times[index], holding)
        for index in range(len(FINGERS))
    ]
    metrics: dict = {
        "kind": "grasp",
        "controller": scenario.controller.kind,
        "outcome": _outcome(fingers, brick_drop),
        "force_ramp_end": ramp_end,
        "settling_time": settled,
        "hold_start": hold_start,
        "hold_duration": min(duration, hold_end) - hold_start,
        "brick_drop": brick_drop,
        "brick_rise": max(0.0, float(np.max(z[holding] - z_start))),
        "brick_final_displacement": (
            result.brick_pose[-1] - result.brick_pose[holding][0]
        ).tolist(),
        # From the hold's start: max rise and drop in z, max |y|, max |theta|, the final
        # (y, z, theta) and the least-squares rate of each over the hold (m, rad, per s).
        "brick_displacement": _brick_displacement(time, result.brick_pose, hold_start, holding),
        "max_relative_force_error_held": max(f["max_relative_force_error_held"] for f in fingers),
        "max_slip": max(f["slip"] for f in fingers),
        "max_slip_rate": max(abs(f["slip_rate"]) for f in fingers),
        "peak_force_ratio": max(f["peak_force_after_ramp"] / f["force_reference"] for f in fingers),
        "fingers": fingers,
        "wall_time": result.wall_time,
        "real_time_factor": duration / result.wall_time if result.wall_time > 0 else None,
        "steps": result.steps,
        "samples": int(time.size),
    }
    if disturbance.kind != "none":
        metrics["disturbance"] = _disturbance_metrics(result)
    return metrics


def _finger_metrics(
    result: GraspResult, index: int, settle_time: float | None, holding: np.ndarray
) -> dict:
    """One finger's forces after the ramp and over the hold, its settling and its slip."""
    time = result.time
    ramp_end = result.scenario.force_ramp_end
    after_ramp = time >= ramp_end
    force = result.force[:, index]
    reference = np.asarray(result.scenario.force_reference)[index]
    contact = in_contact(force, reference)
    contact_after = contact[after_ramp]
    losses = int(contact_loss_indices(contact_after).size)
    error_held = np.abs(force[holding] - reference) / reference
    last = final_window(time)
    return {
        "finger": FINGERS[index],
        "force_reference": float(reference),
        "first_contact_time": first_contact_time(time, contact),
        "peak_force": float(np.max(force)),
        "peak_force_after_ramp": float(np.max(force[after_ramp])),
        "min_force_after_ramp": float(np.min(force[after_ramp])),
        "in_contact_after_ramp": bool(np.all(contact_after)),
        "contact_losses_after_ramp": losses,
        "settling_time": None if settle_time is None else settle_time - ramp_end,
        "final_mean_force": time_mean(time[last], force[last]),
        "steady_state_force_error": time_mean(time[last], np.abs(force[last] - reference)),
        "max_relative_force_error_held": float(np.max(error_held)),
        "slip": float(np.max(np.abs(result.slip[holding, index]))),
        # Along its face, m/s: the least-squares slope of the slip over the hold.
        "slip_rate": least_squares_slope(time[holding], result.slip[holding, index]),
    }


def _outcome(fingers: list[dict], brick_drop: float) -> str:
    """crushed (a finger's force beyond CRUSH_FACTOR Fr after the ramp), lost (a finger
    out of contact, or the brick dropped DROP_LIMIT), else held."""
    crushed = any(f["peak_force_after_ramp"] > CRUSH_FACTOR * f["force_reference"] for f in fingers)
    lost = any(not f["in_contact_after_ramp"] for f in fingers)
    if crushed:
        return "crushed"
    if lost or brick_drop >= DROP_LIMIT:
        return "lost"
    return "held"


def _disturbance_metrics(result: GraspResult) -> dict:
    """From the disturbance's start: the forces' extremes, whether contact held, the
    recovery into the band and the brick's drop."""
    time = result.time
    disturbance = result.scenario.disturbance
    references = np.asarray(result.scenario.force_reference)
    z = result.brick_pose[:, 1]
    start = disturbance.start
    end = start + (disturbance.duration if disturbance.kind == "force_pulse" else 0.0)
    after = time >= start
    recovery = [settled_from(time, result.force[:, i], references[i], start) for i in range(3)]
    return {
        "kind": disturbance.kind,
        "start": start,
        "end": end,
        "peak_force": [float(np.max(result.force[after, i])) for i in range(3)],
        "min_force": [float(np.min(result.force[after, i])) for i in range(3)],
        "contact_kept": bool(np.all(in_contact(result.force[after], references[np.newaxis, :]))),
        # From the disturbance's start until every force is back within the band.
        "recovery_time": None if None in recovery else max(recovery) - start,
        "brick_drop": max(0.0, float(np.interp(start, time, z) - np.min(z[after]))),
    }


def run_grasp(
    scenario: GraspScenario,
    *,
    loop: GraspLoop | None = None,
    progress: Callable[[float], None] | None = None,
) -> GraspResult:
    """Builds (unless given), initializes and simulates a grasp; returns its time series.

    A ``mass_step`` disturbance sets the brick's mass parameter at its start time.
    `progress` is called with the simulated time (s) after every step.

    Raises:
        SimulationDivergedError: the run blew up (the exception carries the partial result).
    """
    loop = loop or BuildGrasp(scenario)
    stops = []
    disturbance = scenario.disturbance
    if disturbance.kind == "mass_step":

        def heavier_brick(context) -> None:
            brick = loop.plant.GetBodyByName(BRICK_BODY)
            plant_context = loop.plant.GetMyMutableContextFromRoot(context)
            brick.SetMass(plant_context, disturbance.mass_scale * brick.default_mass())

        stops.append((disturbance.start, heavier_brick))
    run = simulate_loop(
        loop.diagram,
        loop.plant,
        scenario.simulator,
        scenario.duration,
        initialize=lambda context: SetGraspInitialConditions(loop, context),
        stops=stops,
        progress=progress,
        solver="simulation",
    )
    context = run.context
    steps = (
        int(round(context.get_time() / scenario.time_step))
        if scenario.time_step > 0
        else int(run.simulator.get_integrator().get_num_steps_taken())
    )
    return finish_run(_collect(loop, context, run.wall_time, steps), run.divergence)


def _collect(loop: GraspLoop, context, wall_time: float, steps: int) -> GraspResult:
    scenario, plant = loop.scenario, loop.plant

    def logged(name: str) -> tuple[np.ndarray, np.ndarray]:
        log = loop.loggers[name].FindLog(context)
        return log.sample_times(), log.data().T

    sample_times, states = logged("state")
    count = sample_times.size
    force = logged("contact_force")[1]
    measured = logged("measured_force")[1]
    reference = logged("force_reference")[1]
    plan = logged("plan")[1].reshape(count, 3, 4)[:, :, :2]
    if "reference_offset" in loop.loggers:
        offset = logged("reference_offset")[1].reshape(count, 3, 2)
    else:
        offset = np.zeros((count, 3, 2))
    q = states[:, : plant.num_positions()]
    brick_pose = np.column_stack(
        [q[:, plant.GetJointByName(name).position_start()] for name in BRICK_JOINTS]
    )
    # Each tip in its face frame, from the logged state, once, at the end.
    tip = np.full((count, 3, 2), np.nan)
    for index, finger in enumerate(FINGERS):
        kinematics = PlanarFrameKinematics(
            plant,
            tip_centre_frame(finger),
            coordinates=FINGER_COORDINATES,
            expressed_in=contact_frame(finger),
        )
        for row, state in enumerate(states):
            if np.all(np.isfinite(state)):
                kinematics.set_state(state)
                tip[row, index] = kinematics.pose()
    result = GraspResult(
        scenario=scenario,
        time=sample_times,
        force=force,
        force_measured=measured,
        force_reference=reference,
        plan=plan,
        reference_offset=offset,
        tip=tip,
        slip=np.zeros((count, 3)),
        brick_pose=brick_pose,
        joint_positions=q,
        wall_time=wall_time,
        steps=steps,
    )
    along_face = _along_face(loop, tip, brick_pose)
    result.metrics = compute_grasp_metrics(result)
    hold = result.metrics["hold_start"]
    start = np.array([np.interp(hold, sample_times, along_face[:, i]) for i in range(3)])
    result.slip = along_face - start
    result.metrics = compute_grasp_metrics(result)
    return result


def _along_face(loop: GraspLoop, tip: np.ndarray, brick_pose: np.ndarray) -> np.ndarray:
    """Each tip centre's coordinate along its face, in the brick's frame, m (N, 3).

    The tip in world (y, z) from its face frame, then into the brick's frame (translated by
    its y, z and turned by theta about x): the side fingers' coordinate is the brick's z,
    finger3's the brick's y.
    """
    count = tip.shape[0]
    along = np.zeros((count, 3))
    cos_theta, sin_theta = np.cos(brick_pose[:, 2]), np.sin(brick_pose[:, 2])
    for index, X_WC in enumerate(loop.geometry.face_frames):
        p_C = np.column_stack([tip[:, index, 0], tip[:, index, 1], np.zeros(count)])
        p_W = (X_WC.rotation().matrix() @ p_C.T).T + X_WC.translation()
        dy, dz = p_W[:, 1] - brick_pose[:, 0], p_W[:, 2] - brick_pose[:, 1]
        y_brick = cos_theta * dy + sin_theta * dz
        z_brick = -sin_theta * dy + cos_theta * dz
        along[:, index] = z_brick if index < 2 else y_brick
    return along


def grasp_verdict_line(result: GraspResult) -> str:
    """One line: outcome, drop, worst force error while held, peak force ratio."""
    m = result.metrics
    settle = "never" if m["settling_time"] is None else f"{m['settling_time']:.3g} s"
    return (
        f"{m['outcome']}: settled at {settle}, brick drop {1e3 * m['brick_drop']:.3g} mm, "
        f"max |F - Fr| / Fr while held {100 * m['max_relative_force_error_held']:.3g} %, "
        f"peak F / Fr {m['peak_force_ratio']:.3g}"
    )


def grasp_summary(result: GraspResult) -> str:
    """A few lines for the terminal."""
    m = result.metrics
    rtf = m["real_time_factor"]
    lines = [
        f"scenario {result.scenario.name}: {result.time[-1]:.3g} s simulated in "
        f"{m['wall_time']:.2f} s (real-time factor {rtf:.3g}), {m['steps']} steps",
        f"  {grasp_verdict_line(result)}",
    ]
    for finger in m["fingers"]:
        lines.append(
            f"  {finger['finger']}: Fr {finger['force_reference']:g} N, final "
            f"{finger['final_mean_force']:.3g} N, peak after ramp "
            f"{finger['peak_force_after_ramp']:.3g} N, slip {1e3 * finger['slip']:.3g} mm "
            f"({1e6 * finger['slip_rate']:.3g} um/s)"
        )
    b = m["brick_displacement"]
    lines.append(
        f"  brick from the hold's start: rise {1e3 * b['max_rise']:.3g} mm, drop "
        f"{1e3 * b['max_drop']:.3g} mm, |y| {1e3 * b['max_abs_y']:.3g} mm, |theta| "
        f"{1e3 * b['max_abs_rotation']:.3g} mrad"
    )
    if "disturbance" in m:
        d = m["disturbance"]
        recovery = "n/a" if d["recovery_time"] is None else f"{d['recovery_time']:.3g} s"
        peaks = ", ".join(f"{p:.3g}" for p in d["peak_force"])
        lines.append(
            f"  {d['kind']} at {d['start']:g} s: peak forces ({peaks}) N, contact kept "
            f"{d['contact_kept']}, back within 5 % in {recovery}"
        )
    return "\n".join(lines)
