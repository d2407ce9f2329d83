"""The sweep's table (table.csv) and its summary for people (summary.txt)."""

from __future__ import annotations

import csv
import io
import json
import math
import statistics
from collections.abc import Callable, Iterable, Mapping, Sequence

import numpy as np

from admittance.diagrams.app.sweep.definition import SweepDefinition
from admittance.diagrams.app.sweep.points import SCALAR_METRICS
from admittance.diagrams.views import formatting
from admittance.diagrams.views.formatting import number, seconds

__all__ = ["DEGRADED_FRACTION", "as_number", "degraded", "summarize", "table_text"]

# Tracking "degrades" where the steady-state force error exceeds this fraction of Fr.
DEGRADED_FRACTION = 0.05


def _ordered_metric_names(rows: Sequence[Mapping]) -> list[str]:
    names = ["force_reference", *SCALAR_METRICS]
    seen = set(names)
    extra = []
    for row in rows:
        for name in row.get("metrics", {}):
            if name not in seen:
                seen.add(name)
                extra.append(name)
    settling = [n for n in extra if n.startswith("settling_")]
    times = ("wall_time", "point_time")
    rest = [n for n in extra if not n.startswith("settling_") and n not in times]
    present = {name for row in rows for name in row.get("metrics", {})}
    names = [n for n in names if n in present]
    return names + settling + rest + [n for n in times if n in present]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | dict):
        return json.dumps(value)
    return str(value)


def table_text(keys: Sequence[str], rows: Sequence[Mapping]) -> str:
    """table.csv: one row per point, sorted by index."""
    metric_names = _ordered_metric_names(rows)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["index", "point_id", *keys, "failed", "failure", *metric_names])
    for row in sorted(rows, key=lambda r: r["index"]):
        values, metrics = row.get("values", {}), row.get("metrics", {})
        writer.writerow(
            [row["index"], row["point_id"]]
            + [_cell(values.get(key)) for key in keys]
            + [_cell(row.get("failed")), _cell(row.get("failure"))]
            + [_cell(metrics.get(name)) for name in metric_names]
        )
    return buffer.getvalue()


def as_number(value) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def degraded(row: Mapping) -> bool:
    """Failed, or steady-state force error above 5 % of the point's Fr."""
    if row.get("failed"):
        return True
    metrics = row.get("metrics", {})
    error = as_number(metrics.get("steady_state_force_error"))
    reference = as_number(metrics.get("force_reference"))
    return error is None or reference is None or error > DEGRADED_FRACTION * reference


def _bins(values: list, log: bool, count: int = 5) -> list[tuple[str, Callable[[object], bool]]]:
    """Ranges of a swept key's values: each distinct value if few, else `count` ranges."""
    distinct = []
    for value in values:
        if value not in distinct:
            distinct.append(value)
    numbers = [as_number(v) for v in distinct]
    if len(distinct) <= 8 or any(n is None for n in numbers):
        ordered = sorted(distinct, key=lambda v: (as_number(v) is None, as_number(v) or 0, str(v)))
        return [(f"= {formatting.value(v)}", lambda x, v=v: x == v) for v in ordered]
    low, high = min(numbers), max(numbers)
    if log and low > 0:
        edges = np.geomspace(low, high, count + 1)
    else:
        edges = np.linspace(low, high, count + 1)
    result = []
    for i in range(count):
        a, b = float(edges[i]), float(edges[i + 1])
        last = i == count - 1
        label = f"in [{number(a)}, {number(b)}{']' if last else ')'}"

        def inside(x, a=a, b=b, last=last):
            n = as_number(x)
            return n is not None and a <= n and (n <= b if last else n < b)

        result.append((label, inside))
    return result


def _metric_values(rows: Iterable[Mapping], name: str) -> list[float]:
    """The finite values of metric `name` over the rows that did not fail."""
    values = (as_number(r.get("metrics", {}).get(name)) for r in rows if not r.get("failed"))
    return [v for v in values if v is not None]


def _bin_line(label: str, members: Sequence[Mapping], moving: bool) -> str:
    """One line of the per-key table of summarize()."""
    errors = _metric_values(members, "steady_state_force_error")
    peaks = _metric_values(members, "peak_force")
    losses = sum(1 for v in _metric_values(members, "contact_losses") if v > 0)
    failures = sum(bool(r.get("failed")) for r in members)
    line = (
        f"      {label:32s} {len(members):6d} {sum(map(degraded, members)):8d} {failures:6d}"
        f"  {number(statistics.median(errors) if errors else None, ' N'):>15s}"
        f"  {number(max(peaks) if peaks else None, ' N'):>8s}  {losses:12d}"
    )
    if moving:
        low = _metric_values(members, "force_min_while_wall_moves")
        line += f"  {number(min(low) if low else None, ' N'):>19s}"
    return line


def _point_label(row: Mapping, keys: Sequence[str]) -> str:
    values = row.get("values", {})
    described = ", ".join(f"{k}={formatting.value(values.get(k))}" for k in keys)
    return f"#{row['index']} ({described})"


def summarize(definition: SweepDefinition, rows: Sequence[Mapping], worst: int = 5) -> str:
    """The sweep's summary: counts, failures, where tracking degrades, the worst points."""
    keys = definition.keys
    rows = sorted(rows, key=lambda r: r["index"])
    failed = [r for r in rows if r.get("failed")]
    finished = [r for r in rows if not r.get("failed")]
    degraded_rows = [r for r in rows if degraded(r)]
    lines = _count_lines(definition, rows, failed)
    if finished:
        lines += _spread_lines(finished)
    percent = number(100 * DEGRADED_FRACTION, " %")
    lines.append(
        f"  tracking degrades (steady-state force error > {percent} of Fr, or failed) at "
        f"{len(degraded_rows)} of {len(rows)} points"
    )
    lines += _by_key_lines(definition, rows)
    lines += _worst_lines(degraded_rows, finished, keys, worst)
    if failed:
        lines += _failed_lines(failed, keys)
    return "\n".join(lines) + "\n"


def _count_lines(
    definition: SweepDefinition, rows: Sequence[Mapping], failed: Sequence[Mapping]
) -> list[str]:
    """The sweep, how many of its points finished and failed, and their compute time."""
    total = len(definition.points)
    lines = [
        f"sweep {definition.describe()}",
        f"  {total} points, {len(rows)} finished, {len(failed)} failed"
        + (f", {total - len(rows)} not run" if len(rows) < total else ""),
    ]
    times = [as_number(r.get("metrics", {}).get("point_time")) for r in rows]
    times = [t for t in times if t is not None]
    if times:
        lines.append(
            f"  compute: {seconds(sum(times))} in all, median {seconds(statistics.median(times))} "
            f"per point, longest {seconds(max(times))}"
        )
    return lines


def _spread_lines(finished: Sequence[Mapping]) -> list[str]:
    """Min / median / max of the main metrics over the points that ran; contact losses and
    points that did not settle."""
    lines = ["  over the points that ran (min / median / max):"]
    for name, unit in (
        ("peak_force", " N"),
        ("steady_state_force_error", " N"),
        ("rms_force_error", " N"),
        ("mean_abs_force_error_settled", " N"),
        ("contact_losses", ""),
        ("settling_first_contact_0", " s"),
        ("force_min_while_wall_moves", " N"),
        ("force_max_while_wall_moves", " N"),
    ):
        values = [as_number(r["metrics"].get(name)) for r in finished]
        values = [v for v in values if v is not None]
        if values:
            lines.append(
                f"    {name:30s} {number(min(values), unit)} / "
                f"{number(statistics.median(values), unit)} / {number(max(values), unit)}"
            )
    losses = [r for r in finished if (as_number(r["metrics"].get("contact_losses")) or 0) > 0]
    unsettled = [
        r
        for r in finished
        if any(
            k.startswith("settling_") and v is None and not k.startswith("settling_wall_starts")
            for k, v in r["metrics"].items()
        )
    ]
    lines.append(
        f"  contact lost at {len(losses)} points; not settled within 5 % of Fr after an "
        f"event (wall_starts excepted: a moving wall leaves a ramp error) at "
        f"{len(unsettled)} points"
    )
    return lines


def _by_key_lines(definition: SweepDefinition, rows: Sequence[Mapping]) -> list[str]:
    """Per swept key, a table of its values (or ranges of them): points, degraded, failed,
    median error, max peak, contact lost (and the least force while a wall moves)."""
    lines = []
    moving = any("force_min_while_wall_moves" in r.get("metrics", {}) for r in rows)
    for key in definition.keys:
        values = [r.get("values", {}).get(key) for r in rows]
        header = (
            f"    {'by ' + key:34s} points degraded failed  median ss error  max peak  contact lost"
        )
        lines.append(header + ("  min F, wall moving" if moving else ""))
        for label, inside in _bins(values, key in definition.log_keys):
            members = [r for r in rows if inside(r.get("values", {}).get(key))]
            if members:
                lines.append(_bin_line(label, members, moving))
    return lines


def _worst_lines(
    degraded_rows: Sequence[Mapping],
    finished: Sequence[Mapping],
    keys: Sequence[str],
    worst: int,
) -> list[str]:
    """The `worst` points by steady-state force error (of the degraded ones that ran), by
    peak force and by RMS force error."""
    lines = []
    shown = [r for r in degraded_rows if not r.get("failed")]
    shown.sort(key=lambda r: -(as_number(r["metrics"].get("steady_state_force_error")) or 0))
    if shown:
        lines.append("  the worst steady-state force errors:")
        for row in shown[:worst]:
            metrics = row["metrics"]
            lines.append(
                f"    {_point_label(row, keys)}: "
                f"{number(metrics.get('steady_state_force_error'), ' N')} "
                f"(Fr {number(metrics.get('force_reference'), ' N')})"
            )
    for name, title in (("peak_force", "peak force"), ("rms_force_error", "RMS force error")):
        ranked = [r for r in finished if as_number(r["metrics"].get(name)) is not None]
        ranked.sort(key=lambda r: -as_number(r["metrics"][name]))
        if ranked:
            lines.append(f"  the worst {title}:")
            for row in ranked[:worst]:
                lines.append(f"    {_point_label(row, keys)}: {number(row['metrics'][name], ' N')}")
    return lines


def _failed_lines(failed: Sequence[Mapping], keys: Sequence[str]) -> list[str]:
    """The first ten failed points and their failures."""
    lines = ["  failed points:"]
    for row in failed[:10]:
        lines.append(f"    {_point_label(row, keys)}: {row.get('failure')}")
    if len(failed) > 10:
        lines.append(f"    ... and {len(failed) - 10} more (table.csv, column failure)")
    return lines
