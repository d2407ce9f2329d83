"""`admittance simulate`: a run's result folder and its summary for the terminal, for
every robot.

The folder holds timeseries.csv, metrics.json, scenario.yaml and the result's figures (the
paper's Fig. 5-7 for the arm, the forces and the brick for the gripper); it is written into
a temporary sibling folder and moved into place at the end, so a folder either holds a
complete result or is left as it was.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from admittance.diagrams.app.formatting import number, seconds
from admittance.diagrams.app.result_folder import ResultFolder, result_folder
from admittance.diagrams.run.planar_arm import SimulationResult
from admittance.diagrams.run.planar_gripper import GraspResult, grasp_verdict_line
from admittance.diagrams.run.spatial_arm import SpatialResult, spatial_verdict_line
from admittance.diagrams.scenario.files import scenario_to_yaml
from admittance.diagrams.views.figures import result_figures

__all__ = ["summary", "write_results"]


def _write_timeseries(result: SimulationResult, path: Path) -> None:
    columns = result.columns()
    data = np.column_stack(list(columns.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def write_results(
    result: SimulationResult | GraspResult,
    out_dir: str | Path,
    overwrite: bool = True,
    *,
    figures: dict | None = None,
) -> ResultFolder:
    """Writes a complete result folder atomically; returns what it wrote.

    `figures` maps a file name to a function of the result that returns its axes (default:
    the result's own, views.result_figures); any result with ``columns()``, ``metrics`` and
    ``scenario`` is written.
    """
    figures = result_figures(result) if figures is None else figures
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_with("timeseries.csv", lambda path: _write_timeseries(result, path))
        folder.write_json("metrics.json", result.metrics)
        folder.write_text("scenario.yaml", scenario_to_yaml(result.scenario))
        for name, plot in figures.items():
            folder.write_figure(name, plot(result)[0].figure)
    return folder


def summary(result: SimulationResult | GraspResult) -> str:
    """A few lines for the terminal."""
    if isinstance(result, GraspResult):
        return _grasp_summary(result)
    if isinstance(result, SpatialResult):
        return _spatial_summary(result)
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


def _spatial_summary(result: SpatialResult) -> str:
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


def _grasp_summary(result: GraspResult) -> str:
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
