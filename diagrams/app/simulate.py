"""`admittance simulate`: a run's result folder and its summary for the terminal, for
every robot.

The folder holds timeseries.csv, metrics.json, scenario.yaml and the result's figures (the
robot's: the paper's Fig. 5-7 for the planar arm, ...); it is written into
a temporary sibling folder and moved into place at the end, so a folder either holds a
complete result or is left as it was.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from admittance.diagrams.results.folder import ResultFolder, result_folder
from admittance.diagrams.robots.kinds import robot_of
from admittance.diagrams.scenario.files import scenario_to_yaml

__all__ = ["summary", "write_results"]


def _write_timeseries(result, path: Path) -> None:
    columns = result.columns()
    data = np.column_stack(list(columns.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def write_results(
    result,
    out_dir: str | Path,
    overwrite: bool = True,
    *,
    figures: dict | None = None,
) -> ResultFolder:
    """Writes a complete result folder atomically; returns what it wrote.

    `figures` maps a file name to a function of the result that returns its axes (default:
    the result's robot's); any result with ``columns()``, ``metrics`` and
    ``scenario`` is written.
    """
    figures = robot_of(result).figures if figures is None else figures
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_with("timeseries.csv", lambda path: _write_timeseries(result, path))
        folder.write_json("metrics.json", result.metrics)
        folder.write_text("scenario.yaml", scenario_to_yaml(result.scenario))
        for name, plot in figures.items():
            folder.write_figure(name, plot(result)[0].figure)
    return folder


def summary(result) -> str:
    """A few lines for the terminal (the robot's own)."""
    return robot_of(result).summary(result)
