"""A grasp's result folder and figure: timeseries.csv, metrics.json, scenario.yaml, PNG.

Written like an arm run's (diagrams/report.py): into a staging folder moved into place at
the end, so a folder holds a complete result or is left as it was.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from admittance.diagrams.grasp_scenario import FINGERS
from admittance.diagrams.grasp_simulation import DROP_LIMIT, GraspResult, grasp_verdict_line
from admittance.diagrams.output import atomic_output_dir, json_safe
from admittance.diagrams.scenario import scenario_to_yaml

__all__ = ["GRASP_FIGURE", "grasp_summary", "plot_grasp", "write_grasp_results"]

GRASP_FIGURE = "grasp_forces.png"


def plot_grasp(result: GraspResult, axes=None):
    """The three normal forces against their Fr (above) and the brick's drop (below)."""
    if axes is None:
        _, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    columns = result.columns()
    t = columns["time"]
    for finger, color in zip(FINGERS, ("C0", "C1", "C2"), strict=True):
        axes[0].plot(t, columns[f"{finger}_force"], color=color, label=f"{finger} F")
        axes[0].plot(
            t, columns[f"{finger}_force_reference"], color=color, ls="--", lw=1, label="Fr"
        )
    axes[0].set_ylabel("normal force (N)")
    axes[0].legend(loc="upper right", ncol=3, fontsize="small")
    axes[0].grid(True, alpha=0.3)
    hold = result.metrics.get("hold_start")
    axes[1].plot(t, 1e3 * columns["brick_drop"], color="k", label="brick drop")
    axes[1].axhline(1e3 * DROP_LIMIT, color="r", ls=":", lw=1, label="drop limit")
    for axis in axes:
        if hold is not None:
            axis.axvline(hold, color="0.5", lw=0.8)
    axes[1].set_ylabel("drop since the hold start (mm)")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(loc="upper right", fontsize="small")
    axes[1].grid(True, alpha=0.3)
    scenario = result.scenario
    axes[0].set_title(
        f"{scenario.name} ({scenario.controller.kind}): {result.metrics.get('outcome', '')}"
    )
    return axes


def write_csv(result: GraspResult, path: Path) -> None:
    columns = result.columns()
    data = np.column_stack(list(columns.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def write_grasp_results(result: GraspResult, out_dir: str | Path, overwrite: bool = True) -> Path:
    """Writes a complete grasp result folder atomically; returns its path."""
    with atomic_output_dir(out_dir, overwrite=overwrite) as staging:
        write_csv(result, staging / "timeseries.csv")
        (staging / "metrics.json").write_text(
            json.dumps(json_safe(result.metrics), indent=2) + "\n"
        )
        (staging / "scenario.yaml").write_text(scenario_to_yaml(result.scenario))
        axes = plot_grasp(result)
        figure = axes[0].figure
        figure.tight_layout()
        figure.savefig(staging / GRASP_FIGURE, dpi=110)
        plt.close(figure)
    return Path(out_dir)


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
            f"{finger['peak_force_after_ramp']:.3g} N, slip {1e3 * finger['slip']:.3g} mm"
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
