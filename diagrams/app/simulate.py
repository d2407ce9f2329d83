"""`admittance simulate`: a run's result folder and its summary for the terminal.

The folder holds timeseries.csv, metrics.json, scenario.yaml and the paper's figures; it is
written into a temporary sibling folder and moved into place at the end, so a folder either
holds a complete result or is left as it was.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from admittance.diagrams.app.result_folder import atomic_output_dir, json_safe
from admittance.diagrams.plots import plot_errors, plot_force, plot_reference
from admittance.diagrams.scenario import scenario_to_yaml
from admittance.diagrams.simulation import SimulationResult

__all__ = ["write_results", "summary"]


FIGURES = {
    "fig5_errors.png": plot_errors,
    "fig6_reference.png": plot_reference,
    "fig7_force.png": plot_force,
}


def write_csv(result: SimulationResult, path: Path) -> None:
    columns = result.columns()
    data = np.column_stack(list(columns.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def write_results(result: SimulationResult, out_dir: str | Path, overwrite: bool = True) -> Path:
    """Writes a complete result folder atomically; returns its path."""
    with atomic_output_dir(out_dir, overwrite=overwrite) as staging:
        write_csv(result, staging / "timeseries.csv")
        (staging / "metrics.json").write_text(
            json.dumps(json_safe(result.metrics), indent=2) + "\n"
        )
        (staging / "scenario.yaml").write_text(scenario_to_yaml(result.scenario))
        for name, plot in FIGURES.items():
            axes = plot(result)
            figure = axes[0].figure
            figure.tight_layout()
            figure.savefig(staging / name, dpi=110)
            plt.close(figure)
    return Path(out_dir)


def summary(result: SimulationResult) -> str:
    """A few lines for the terminal."""
    m = result.metrics

    def fmt(value, unit="", digits=3):
        return "n/a" if value is None else f"{value:.{digits}g}{unit}"

    lines = [
        f"scenario {result.scenario.name}: {result.time[-1]:.3g} s simulated in "
        f"{m['wall_time']:.2f} s (real-time factor {fmt(m['real_time_factor'])}), "
        f"{m['integrator_steps']} steps",
        f"  first contact {fmt(m['first_contact_time'], ' s')}, peak force "
        f"{fmt(m['peak_force'], ' N')} (Fr = {result.force_reference:g} N), contact losses "
        f"{m['contact_losses']}",
        f"  force error: steady state {fmt(m['steady_state_force_error'], ' N')}, rms "
        f"{fmt(m['rms_force_error'], ' N')}, settled mean "
        f"{fmt(m['mean_abs_force_error_settled'], ' N')}",
    ]
    for event in m["events"]:
        lines.append(
            f"  {event['kind']} at {event['time']:.3g} s: settles (5 %) in "
            f"{fmt(event['settling_time'], ' s')}, "
            f"peak after {fmt(event['peak_force_after'], ' N')}"
        )
    return "\n".join(lines)
