"""The sweep's summary plots: per swept key, the metrics against the key's value."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

from admittance.diagrams.app.sweep.definition import SweepDefinition
from admittance.diagrams.app.sweep.folder import plot_name
from admittance.diagrams.app.sweep.summary import DEGRADED_FRACTION, as_number
from admittance.diagrams.results.folder import atomic_write
from admittance.diagrams.views import formatting
from admittance.diagrams.views.formatting import number

__all__ = ["PLOTTED_METRICS", "plot_summary"]

PLOTTED_METRICS = (
    ("peak_force", "peak force (N)"),
    ("steady_state_force_error", "steady-state |F - Fr| (N)"),
    ("rms_force_error", "RMS force error (N)"),
    ("mean_abs_force_error_settled", "settled mean |F - Fr| (N)"),
    ("contact_losses", "contact losses"),
    ("settling_first_contact_0", "settling after first contact (s)"),
    ("force_min_while_wall_moves", "min force while the wall moves (N)"),
    ("force_max_while_wall_moves", "max force while the wall moves (N)"),
)


def plot_summary(definition: SweepDefinition, rows: Sequence[Mapping], out_dir: Path) -> list[Path]:
    """One PNG per swept key: the metrics against the key; failed points as red crosses."""
    from matplotlib.figure import Figure

    written = []
    rows = sorted(rows, key=lambda r: r["index"])
    references = {as_number(r.get("metrics", {}).get("force_reference")) for r in rows}
    references.discard(None)
    for key in definition.keys:
        positions, categories = _x_positions(rows, key)
        numeric = categories is None
        log_x = numeric and key in definition.log_keys and min(positions) > 0
        plotted = _plotted_metrics(rows)
        grid_rows = math.ceil(len(plotted) / 2)
        figure = Figure(figsize=(11, 2.7 * grid_rows + 0.5))
        axes = figure.subplots(grid_rows, 2, sharex=True, squeeze=False).ravel()
        if len(plotted) % 2:
            axes[-1].set_visible(False)
            axes = axes[:-1]
        for axis, (name, label) in zip(axes, plotted, strict=True):
            any_failed = _plot_metric(axis, name, positions, rows, references)
            _scale_x(axis, log_x, numeric)
            axis.set_ylabel(label)
            axis.grid(True, alpha=0.3)
            if any_failed or name == "steady_state_force_error":
                axis.legend(loc="best", fontsize=7)
        for axis in axes[-2:]:
            axis.set_xlabel(key)
            axis.tick_params(labelbottom=True)
            if categories is not None:
                axis.set_xticks(range(len(categories)), categories)
                axis.set_xlim(-0.5, len(categories) - 0.5)
        figure.suptitle(f"sweep of {definition.scenario_name}: metrics against {key}")
        figure.tight_layout()
        path = out_dir / plot_name(key)
        atomic_write(path, lambda temporary, f=figure: f.savefig(temporary, format="png", dpi=100))
        written.append(path)
    return written


def _x_positions(rows: Sequence[Mapping], key: str) -> tuple[list, list[str] | None]:
    """Each row's x for `key`: its value if every value is a number (categories None),
    else the index of its written value among the categories, in order of appearance."""
    raw = [r.get("values", {}).get(key) for r in rows]
    if all(as_number(v) is not None for v in raw):
        return [as_number(v) for v in raw], None
    categories = []
    for value in raw:
        if formatting.value(value) not in categories:
            categories.append(formatting.value(value))
    return [categories.index(formatting.value(v)) for v in raw], categories


def _plotted_metrics(rows: Sequence[Mapping]) -> list[tuple[str, str]]:
    """The PLOTTED_METRICS some row has (the first if none: every point failed, show where)."""
    present = {name for row in rows for name in row.get("metrics", {})}
    plotted = [(name, label) for name, label in PLOTTED_METRICS if name in present]
    if not plotted:
        plotted = list(PLOTTED_METRICS[:1])
    return plotted


def _plot_metric(axis, name: str, positions: list, rows: Sequence[Mapping], references) -> bool:
    """Metric `name` of the finished points against x, the failed ones as red crosses at
    the bottom, the degraded threshold on the steady-state error (one Fr only), and the y
    scale; returns whether a point failed."""
    from matplotlib.transforms import blended_transform_factory

    xs, ys = [], []
    failed_xs = []
    for x, row in zip(positions, rows, strict=True):
        if row.get("failed"):
            failed_xs.append(x)
            continue
        y = as_number(row.get("metrics", {}).get(name))
        if y is not None:
            xs.append(x)
            ys.append(y)
    axis.plot(xs, ys, "o", ms=4, alpha=0.7, label="finished")
    if failed_xs:
        bottom = blended_transform_factory(axis.transData, axis.transAxes)
        axis.plot(
            failed_xs,
            [0.03] * len(failed_xs),
            "x",
            color="red",
            ms=7,
            transform=bottom,
            label="failed",
        )
    if name == "steady_state_force_error" and len(references) == 1:
        axis.axhline(
            DEGRADED_FRACTION * next(iter(references)),
            color="k",
            ls="--",
            lw=1,
            label=f"{number(100 * DEGRADED_FRACTION, ' %')} of Fr",
        )
    positive = [y for y in ys if y > 0]
    if (
        name != "contact_losses"
        and positive
        and len(positive) == len(ys)
        and max(positive) / min(positive) > 100
    ):
        axis.set_yscale("log")
    if name == "contact_losses":
        from matplotlib.ticker import MaxNLocator

        axis.yaxis.set_major_locator(MaxNLocator(integer=True))
        axis.set_ylim(-0.5, max([1.0, *ys]) + 0.5)
    return bool(failed_xs)


def _scale_x(axis, log_x: bool, numeric: bool) -> None:
    """A logarithmic x axis for a log-spaced key, else scientific tick labels (numbers)."""
    from matplotlib.ticker import NullFormatter

    if log_x:
        axis.set_xscale("log")
        axis.xaxis.set_minor_formatter(NullFormatter())
    elif numeric:
        axis.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
