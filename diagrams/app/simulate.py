"""`admittance simulate`: a run's result folder and its summary for the terminal.

The folder holds timeseries.csv, metrics.json, scenario.yaml and the paper's figures; it is
written into a temporary sibling folder and moved into place at the end, so a folder either
holds a complete result or is left as it was.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from admittance.diagrams.app.formatting import number, seconds
from admittance.diagrams.app.result_folder import ResultFolder, result_folder
from admittance.diagrams.plots import plot_errors, plot_force, plot_reference
from admittance.diagrams.scenario import scenario_to_yaml
from admittance.diagrams.simulation import SimulationResult

__all__ = ["FIGURES", "summary", "write_results"]

# The paper's figures of a run, by file name.
FIGURES = {
    "fig5_errors.png": plot_errors,
    "fig6_reference.png": plot_reference,
    "fig7_force.png": plot_force,
}


def _write_timeseries(result: SimulationResult, path: Path) -> None:
    columns = result.columns()
    data = np.column_stack(list(columns.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def write_results(
    result: SimulationResult,
    out_dir: str | Path,
    overwrite: bool = True,
    *,
    figures: dict = FIGURES,
) -> ResultFolder:
    """Writes a complete result folder atomically; returns what it wrote.

    `figures` maps a file name to a function of the result that returns its axes (a grasp
    passes its own; any result with ``columns()``, ``metrics`` and ``scenario`` is written).
    """
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_with("timeseries.csv", lambda path: _write_timeseries(result, path))
        folder.write_json("metrics.json", result.metrics)
        folder.write_text("scenario.yaml", scenario_to_yaml(result.scenario))
        for name, plot in figures.items():
            folder.write_figure(name, plot(result)[0].figure)
    return folder


def summary(result: SimulationResult) -> str:
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
    return "\n".join(lines)
