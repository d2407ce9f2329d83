"""points.jsonl, the sweep's record: one row per finished point, and how a worker makes it.

A row is ``{"index", "point_id", "values", "failed", "failure", "metrics"}`` (see the
package's description); a worker makes it with :func:`run_point`, the parent appends it
with one ``os.write`` and an ``fsync``, and :func:`read_points` reads it back on resume.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from admittance.diagrams.results.folder import atomic_write_text, json_safe
from admittance.diagrams.run.metrics import settling_columns
from admittance.diagrams.run.parallel import simulate_point

__all__ = [
    "SCALAR_METRICS",
    "PointsFile",
    "point_metrics",
    "read_points",
    "rewrite_points",
    "run_point",
]

# Scalar metrics copied from metrics.json into a point's row, in table order.
SCALAR_METRICS = (
    "peak_force",
    "steady_state_force_error",
    "rms_force_error",
    "mean_abs_force_error_settled",
    "contact_losses",
    "first_contact_time",
    "force_min_while_wall_moves",
    "force_max_while_wall_moves",
)

# Bookkeeping of a run, not results: left out of the rows (wall_time is added last).
_UNTABLED_METRICS = frozenset(
    ("wall_time", "real_time_factor", "integrator_steps", "derivative_evaluations", "samples")
)


def point_metrics(metrics: Mapping, force_reference: float) -> dict:
    """The flat metrics of a point's row from a run's metrics.json dictionary."""
    row: dict = {"force_reference": force_reference}
    for name in SCALAR_METRICS:
        if name in metrics:
            row[name] = metrics[name]
    for name, value in metrics.items():  # any other scalar metric (e.g. a new one)
        scalar = value is None or (isinstance(value, int | float) and not isinstance(value, bool))
        if scalar and name not in row and name not in _UNTABLED_METRICS:
            row[name] = value
    row.update(settling_columns(metrics))
    row["wall_time"] = metrics.get("wall_time")
    return row


def run_point(task: Mapping) -> dict:
    """Runs one point; returns its points.jsonl row. Failures are rows, not exceptions.

    `task` holds ``index``, ``point_id``, ``values``, ``scenario`` (a built-in name or an
    absolute YAML path) and ``overrides`` (the mapping for load_scenario). Runs in a worker
    process (or a Dask worker).
    """
    run = simulate_point(task["scenario"], task["overrides"])
    if not run.failed:
        metrics = point_metrics(run.metrics, run.force_reference)
    elif run.wall_time is not None:  # diverged: only its time
        metrics = {"wall_time": run.wall_time}
    else:
        metrics = {}
    metrics["point_time"] = run.point_time
    row = {
        "index": task["index"],
        "point_id": task["point_id"],
        "values": dict(task["values"]),
        "failed": run.failed,
        "failure": run.failure,
        "metrics": metrics,
    }
    return json_safe(row)


def read_points(path: str | Path) -> tuple[dict[str, dict], int]:
    """Reads points.jsonl: (rows by point id, number of unreadable lines ignored).

    A torn last line (a write killed midway) and any other line that is not a complete
    JSON object with a point id are ignored; the first row of a point id wins.
    """
    path = Path(path)
    if not path.exists():
        return {}, 0
    data = path.read_bytes()
    rows: dict[str, dict] = {}
    bad = 0
    lines = data.split(b"\n")
    for number, raw in enumerate(lines):
        if not raw.strip():
            continue
        torn = number == len(lines) - 1  # no newline after it
        try:
            row = json.loads(raw)
        except ValueError:
            row = None
        if torn or not isinstance(row, dict) or not isinstance(row.get("point_id"), str):
            bad += 1
            continue
        rows.setdefault(row["point_id"], row)
    return rows, bad


def rewrite_points(path: Path, rows: Iterable[dict]) -> None:
    lines = "".join(_line(row) for row in rows)
    atomic_write_text(path, lines)


def _line(row: Mapping) -> str:
    return json.dumps(json_safe(dict(row)), separators=(",", ":"), allow_nan=False) + "\n"


class PointsFile:
    """points.jsonl opened for appending: one os.write per line, then fsync."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def append(self, row: Mapping) -> None:
        data = _line(row).encode()
        written = os.write(self.fd, data)  # one call: a kill leaves at most a torn last line
        while written < len(data):  # a short write (not seen on local disks): finish it
            written += os.write(self.fd, data[written:])
        os.fsync(self.fd)

    def close(self) -> None:
        os.close(self.fd)
