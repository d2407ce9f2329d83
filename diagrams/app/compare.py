"""Every force controller on the same scenario, side by side (``admittance compare``).

Each controller of ``CONTROLLER_KINDS`` runs the scenario with only ``controller.kind``
changed (baselines tuned by the matched rule of diagrams/force_controllers.py), in parallel
on the local cores. The result folder (written atomically) holds:

* ``table.txt`` and ``table.csv``: one row per controller: peak force, peak after the first
  contact transient, settling time (5 %) after each event, RMS and steady-state force error,
  largest y and theta tracking errors, contact losses, and a verdict;
* ``force.png``: the contact forces overlaid, and the reference offsets Xr;
* ``metrics.json``: every controller's full metrics, and the baselines' gains.

A controller whose run fails (diverges, or the integrator gives up) gets a row marked failed
with the reason; the others are still compared.

Verdicts, on the mean force over the last second (``final_mean_force`` of the metrics; the
5 % band of the settling metrics):
``tracks Fr`` within 5 % of Fr; ``excessive force`` above it; ``too little force`` below it
(contact lost or never pressed); ``failed`` for a run that did not finish.
"""

from __future__ import annotations

import concurrent.futures
import json
import math
import multiprocessing
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from admittance.diagrams.app.result_folder import atomic_output_dir, json_safe
from admittance.diagrams.scenario import CONTROLLER_KINDS, Scenario, load_scenario, scenario_to_yaml
from admittance.diagrams.simulation import SETTLE_BAND, settling_columns

__all__ = ["ControllerRun", "compare_controllers", "format_table", "write_comparison"]


@dataclass
class ControllerRun:
    """One controller's run: its table row, and the series to plot."""

    kind: str
    row: dict
    metrics: dict = field(default_factory=dict)
    time: np.ndarray | None = None
    force: np.ndarray | None = None
    reference_offset: np.ndarray | None = None


def _verdict(metrics: dict, force_reference: float) -> str:
    if metrics.get("failed"):
        return "failed"
    final = metrics.get("final_mean_force")
    if final is None:
        return "failed"
    if final > (1 + SETTLE_BAND) * force_reference:
        return "excessive force"
    if final < (1 - SETTLE_BAND) * force_reference:
        return "too little force"
    return "tracks Fr"


def _row(kind: str, metrics: dict, force_reference: float) -> dict:
    row = {
        "controller": kind,
        # N: overall, and after the first contact transient (metrics of simulation.py).
        "peak_force": metrics.get("peak_force"),
        "peak_after_transient": metrics.get("peak_force_after_first_contact_transient"),
        "rms_error": metrics.get("rms_force_error"),
        "steady_error": metrics.get("steady_state_force_error"),
        # Largest |Xd - X| on the motion-controlled axes.
        "max_ey_mm": _scaled(metrics.get("max_y_tracking_error"), 1e3),
        "max_etheta_mrad": _scaled(metrics.get("max_theta_tracking_error"), 1e3),
        "contact_losses": metrics.get("contact_losses"),
    }
    row.update(settling_columns(metrics))  # s, after each event
    row["verdict"] = _verdict(metrics, force_reference)
    row["failure"] = metrics.get("failure", "")
    return row


def _scaled(value, factor):
    return None if value is None else value * factor


def _run_one(source, overrides: list[str], kind: str) -> ControllerRun:
    """Runs one controller (in a worker process); never raises for a failed run."""
    from admittance.diagrams.simulation import SimulationDivergedError, run_scenario

    scenario = load_scenario(source, [*overrides, f"controller.kind={kind}"])
    try:
        result = run_scenario(scenario)
    except SimulationDivergedError as diverged:
        result = diverged.result
    except RuntimeError as error:  # a failure inside Drake that is not a divergence
        metrics = {"failed": True, "failure": str(error).splitlines()[0]}
        return ControllerRun(kind, _row(kind, metrics, scenario.force_reference), metrics)
    return ControllerRun(
        kind,
        _row(kind, result.metrics, scenario.force_reference),
        result.metrics,
        result.time,
        result.force,
        result.reference_offset[:, 0],
    )


def compare_controllers(
    source,
    overrides: list[str] = (),
    kinds: list[str] = CONTROLLER_KINDS,
    workers: int | None = None,
) -> tuple[Scenario, list[ControllerRun]]:
    """Runs `kinds` on the scenario `source` with `overrides`, in parallel processes.

    Every (scenario, kind) pair is validated first, so a bad key fails before any run.

    Returns:
        (the scenario as loaded, with the optimal admittance), the runs in `kinds` order.
    """
    overrides = list(overrides)
    scenario = load_scenario(source, overrides)
    for kind in kinds:
        load_scenario(source, [*overrides, f"controller.kind={kind}"])
    workers = max(1, min(len(kinds), workers or os.cpu_count() or 1))
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
        futures = [pool.submit(_run_one, source, overrides, kind) for kind in kinds]
        runs = [future.result() for future in futures]
    return scenario, runs


def _format(value) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def format_table(runs: list[ControllerRun]) -> str:
    """The comparison as aligned text, one row per controller."""
    columns = []
    for run in runs:
        columns += [key for key in run.row if key not in columns and key != "failure"]
    cells = [columns] + [[_format(run.row.get(key)) for key in columns] for run in runs]
    widths = [max(len(row[i]) for row in cells) for i in range(len(columns))]
    lines = [
        "  ".join(cell.rjust(width) for cell, width in zip(row, widths, strict=True))
        for row in cells
    ]
    for run in runs:
        if run.row.get("failure"):
            lines.append(f"{run.kind}: {run.row['failure']}")
    return "\n".join(lines) + "\n"


def _write_csv(runs: list[ControllerRun], path: Path) -> None:
    import csv

    columns = []
    for run in runs:
        columns += [key for key in run.row if key not in columns]
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        for run in runs:
            writer.writerow({key: "" if v is None else v for key, v in run.row.items()})


def plot_comparison(scenario: Scenario, runs: list[ControllerRun], axes=None):
    """Contact force (above) and reference offset Xr (below) of every controller."""
    import matplotlib.pyplot as plt

    if axes is None:
        _, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 7))
    for run in runs:
        if run.time is None:
            continue
        axes[0].plot(run.time, run.force, lw=1.2, label=run.kind)
        axes[1].plot(run.time, 1e3 * run.reference_offset, lw=1.2, label=run.kind)
    axes[0].axhline(scenario.force_reference, color="k", ls="--", lw=1, label="Fr")
    if math.isfinite(scenario.admittance.max_force):
        axes[0].axhline(scenario.admittance.max_force, color="r", ls=":", lw=1, label="Fmax")
    axes[0].set_ylabel("contact force (N)")
    axes[1].set_ylabel("reference offset xr (mm)")
    axes[1].set_xlabel("time (s)")
    for axis in axes:
        axis.grid(True, alpha=0.3)
        axis.legend(loc="upper right", fontsize=8)
    axes[0].set_title(f"{scenario.name}: force controllers compared")
    return axes


def write_comparison(
    scenario: Scenario, runs: list[ControllerRun], out_dir: str | Path, overwrite: bool
) -> Path:
    """Writes table.txt, table.csv, metrics.json, force.png and scenario.yaml atomically."""
    import matplotlib.pyplot as plt

    from admittance.diagrams.force_controllers import baseline_gains

    with atomic_output_dir(out_dir, overwrite=overwrite) as staging:
        (staging / "table.txt").write_text(format_table(runs))
        _write_csv(runs, staging / "table.csv")
        report = {
            "scenario": scenario.name,
            "baseline_gains": baseline_gains(scenario),
            "controllers": {run.kind: run.metrics for run in runs},
        }
        (staging / "metrics.json").write_text(json.dumps(json_safe(report), indent=2) + "\n")
        (staging / "scenario.yaml").write_text(scenario_to_yaml(scenario))
        axes = plot_comparison(scenario, runs)
        figure = axes[0].figure
        figure.tight_layout()
        figure.savefig(staging / "force.png", dpi=110)
        plt.close(figure)
    return Path(out_dir)
