"""`admittance simulate` of a grasp: its result folder and its summary for the terminal.

The folder holds timeseries.csv, metrics.json, scenario.yaml and the grasp's figure; it is
written like an arm run's (app/simulate.py): into a temporary sibling folder moved into
place at the end, so a folder holds a complete result or is left as it was.
"""

from __future__ import annotations

from pathlib import Path

from admittance.diagrams.app.result_folder import ResultFolder
from admittance.diagrams.app.simulate import write_results
from admittance.diagrams.grasp_plots import plot_grasp
from admittance.diagrams.grasp_simulation import GraspResult, grasp_verdict_line

__all__ = ["GRASP_FIGURE", "grasp_summary", "write_grasp_results"]

GRASP_FIGURE = "grasp_forces.png"


def write_grasp_results(
    result: GraspResult, out_dir: str | Path, overwrite: bool = True
) -> ResultFolder:
    """Writes a complete grasp result folder atomically; returns what it wrote."""
    return write_results(result, out_dir, overwrite, figures={GRASP_FIGURE: plot_grasp})


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
