"""Every force controller on the same scenario, side by side (``admittance compare``).

Each controller of ``CONTROLLER_KINDS`` runs the scenario with only ``controller.kind``
changed (baselines tuned by the matched rule of diagrams/robots/planar_arm/plant.py): a one-axis
study over ``controller.kind``, defined and validated as a sweep's points and run in
parallel by the sweep's runner (diagrams/run/parallel.py: its worker processes and
Ctrl-C handling). The result folder (written atomically) holds:

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

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from admittance.diagrams.results.folder import ResultFolder, result_folder
from admittance.diagrams.robots.planar_arm.loop import CheckScenarioStarts
from admittance.diagrams.robots.planar_arm.scenario import CONTROLLER_KINDS, Scenario
from admittance.diagrams.run.metrics import SETTLE_BAND, settling_columns
from admittance.diagrams.run.parallel import (
    check_workers,
    run_tasks,
    sigterm_interrupts,
    simulate_point,
)
from admittance.diagrams.scenario.files import load_scenario, scenario_to_yaml, worker_source
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.diagrams.views.formatting import number, seconds

__all__ = [
    "ControllerRun",
    "compare_command",
    "compare_controllers",
    "controller_kinds",
    "format_table",
    "write_comparison",
]


@dataclass
class ControllerRun:
    """One controller's run: its table row, and the series to plot."""

    kind: str
    row: dict
    metrics: dict = field(default_factory=dict)
    time: np.ndarray | None = None
    force: np.ndarray | None = None
    reference_offset: np.ndarray | None = None
    # Build, run and metrics, s.
    point_time: float = 0.0


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


def table_row(kind: str, metrics: dict, force_reference: float) -> dict:
    row = {
        "controller": kind,
        # N: overall, and after the first contact transient (metrics of robots.planar_arm.run).
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


def _run_controller(task: dict) -> ControllerRun:
    """Runs one controller (in a worker process); a failed run is a row, not an exception."""
    kind = task["kind"]
    run = simulate_point(
        task["scenario"], [*task["overrides"], f"controller.kind={kind}"], keep_series=True
    )
    metrics = dict(run.metrics)
    if run.failed:
        metrics.update(failed=True, failure=run.failure)
    force_reference = run.force_reference if run.force_reference is not None else math.nan
    controller_run = ControllerRun(kind, table_row(kind, metrics, force_reference), metrics)
    if run.series is not None:
        controller_run.time = run.series["time"]
        controller_run.force = run.series["force"]
        controller_run.reference_offset = run.series["reference_offset"]
    controller_run.point_time = run.point_time
    return controller_run


def _silent(line: str) -> None:
    pass


def compare_controllers(
    source,
    overrides: list[str] = (),
    kinds: list[str] = CONTROLLER_KINDS,
    workers: int | None = None,
    progress: Callable[[str], None] = _silent,
) -> tuple[Scenario, list[ControllerRun]]:
    """Runs `kinds` on the scenario `source` with `overrides`, in parallel processes.

    A one-axis study over ``controller.kind``: every point is validated first (so a bad key
    fails before any run), then run by the parallel runner (its worker pool and Ctrl-C
    handling).

    Args:
        progress: called with one line as the runs start and as each one finishes.

    Returns:
        (the scenario as loaded, with the optimal admittance), the runs in `kinds` order.

    Raises:
        ScenarioError: a bad key or value, a scenario that cannot start, bad `workers`.
        KeyboardInterrupt: Ctrl-C or SIGTERM, after the workers were stopped.
    """
    overrides = list(overrides)
    workers = check_workers(workers)
    scenario = load_scenario(source, overrides)
    worker_scenario = worker_source(source)
    for kind in kinds:  # every point valid before any runs
        load_scenario(worker_scenario, [*overrides, f"controller.kind={kind}"])
    CheckScenarioStarts(scenario)  # once, before five workers find out each on its own
    tasks = [{"kind": kind, "scenario": worker_scenario, "overrides": overrides} for kind in kinds]
    workers = min(workers, len(tasks))
    progress(f"running {len(tasks)} controllers ({workers} worker{'s' if workers > 1 else ''})")
    runs: dict[str, ControllerRun] = {}

    def on_run(run: ControllerRun) -> None:
        runs[run.kind] = run
        progress(
            f"[{len(runs)}/{len(tasks)}] {run.kind} in {seconds(run.point_time)}: "
            f"{run.row['verdict']}" + (f" ({run.row['failure']})" if run.row["failure"] else "")
        )

    with sigterm_interrupts():
        run_tasks(_run_controller, tasks, on_run, workers=workers, key=lambda task: task["kind"])
    return scenario, [runs[task["kind"]] for task in tasks]


def _cell(value) -> str:
    return value if isinstance(value, str) else number(value, missing="-")


def format_table(runs: list[ControllerRun]) -> str:
    """The comparison as aligned text, one row per controller."""
    columns = []
    for run in runs:
        columns += [key for key in run.row if key not in columns and key != "failure"]
    cells = [columns] + [[_cell(run.row.get(key)) for key in columns] for run in runs]
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
) -> ResultFolder:
    """Writes table.txt, table.csv, metrics.json, scenario.yaml and force.png atomically."""
    from admittance.diagrams.robots.planar_arm.plant import baseline_gains

    report = {
        "scenario": scenario.name,
        "baseline_gains": baseline_gains(scenario),
        "controllers": {run.kind: run.metrics for run in runs},
    }
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_text("table.txt", format_table(runs))
        folder.write_with("table.csv", lambda path: _write_csv(runs, path))
        folder.write_json("metrics.json", report)
        folder.write_text("scenario.yaml", scenario_to_yaml(scenario))
        folder.write_figure("force.png", plot_comparison(scenario, runs)[0].figure)
    return folder


def controller_kinds(text: str | None) -> list[str]:
    """The --controllers list, checked: known kinds, each once (None: every kind)."""
    if text is None:
        return list(CONTROLLER_KINDS)
    kinds = [kind.strip() for kind in text.split(",")]
    for index, kind in enumerate(kinds):
        if kind not in CONTROLLER_KINDS:
            raise ScenarioError(
                f"--controllers: {kind!r} is not a controller; allowed: "
                + ", ".join(CONTROLLER_KINDS)
            )
        if kind in kinds[:index]:
            raise ScenarioError(f"--controllers: {kind!r} is listed twice")
    return kinds


def compare_command(
    source,
    overrides,
    out: Path,
    *,
    controllers: str | None = None,
    workers: int | None = None,
    overwrite: bool = False,
    progress: Callable[[str], None] = _silent,
) -> tuple[str, ResultFolder]:
    """`admittance compare`: every force controller (or the comma list `controllers`) on
    the scenario; the folder written to `out`, and the text to print."""
    from admittance.diagrams.robots.planar_arm.plant import baseline_gains

    kinds = controller_kinds(controllers)
    scenario, runs = compare_controllers(
        source, overrides, kinds, workers=workers, progress=progress
    )
    gains = ", ".join(f"{k} {number(v)}" for k, v in baseline_gains(scenario).items())
    text = (
        f"{scenario.name}: Fr = {number(scenario.force_reference, ' N')}; baseline gains "
        f"({gains})\n" + format_table(runs)
    )
    progress(f"writing {out}/")
    return text, write_comparison(scenario, runs, out, overwrite=overwrite)
