"""Position-only fingers against the paper's law, over brick size and stiffness errors.

Each point is one grasp scenario with ``brick.size_error`` and ``brick.stiffness_error``
set and ``controller.kind`` either ``pid_only`` (the fingers on the plan that closes on the
nominal brick) or ``optimal_admittance``; everything else is the base scenario's. The
verdict of each run (held, crushed, dropped) is grasp_simulation's.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import multiprocessing
import os
from collections.abc import Mapping, Sequence

from admittance.diagrams.grasp_scenario import FINGERS, GRASP_CONTROLLER_KINDS
from admittance.diagrams.scenario import ScenarioError, load_scenario

__all__ = [
    "DEFAULT_SIZE_ERRORS",
    "DEFAULT_STIFFNESS_ERRORS",
    "compare_grasps",
    "format_grasp_table",
    "grasp_point",
]

# Brick 2 mm smaller, as planned, 2 mm larger (m).
DEFAULT_SIZE_ERRORS = (-0.002, 0.0, 0.002)
# Real contact stiffness over the planned one: two decades.
DEFAULT_STIFFNESS_ERRORS = (0.1, 1.0, 10.0)


def grasp_point(task: Mapping) -> dict:
    """Runs one point (in a worker process) and returns its row."""
    from admittance.diagrams.grasp_simulation import run_grasp
    from admittance.diagrams.simulation import SimulationDivergedError

    overrides = dict(task["overrides"])
    scenario = load_scenario(task["scenario"], overrides)
    row = {
        "controller": overrides["controller.kind"],
        "size_error": overrides["brick.size_error"],
        "stiffness_error": overrides["brick.stiffness_error"],
    }
    try:
        result = run_grasp(scenario)
        failure = None
    except SimulationDivergedError as diverged:
        result, failure = diverged.result, str(diverged)
    m = result.metrics
    row.update(
        {
            "outcome": "failed" if failure else m["outcome"],
            "failure": failure,
            "settling_time": m["settling_time"],
            "brick_drop": m["brick_drop"],
            "max_relative_force_error_held": m["max_relative_force_error_held"],
            "peak_force_ratio": m["peak_force_ratio"],
            "final_force_ratio": [
                f["final_mean_force"] / f["force_reference"] for f in m["fingers"]
            ],
            "in_contact": [f["in_contact_after_ramp"] for f in m["fingers"]],
            "max_slip": m["max_slip"],
            "wall_time": m["wall_time"],
        }
    )
    return row


def compare_grasps(
    scenario: str,
    overrides: Sequence[str] = (),
    *,
    size_errors: Sequence[float] = DEFAULT_SIZE_ERRORS,
    stiffness_errors: Sequence[float] = DEFAULT_STIFFNESS_ERRORS,
    controllers: Sequence[str] = GRASP_CONTROLLER_KINDS,
    workers: int | None = None,
) -> list[dict]:
    """One row per (controller, size error, stiffness error), in that order.

    Every point is validated before any runs (a bad value raises ScenarioError).
    """
    base = dict(item.split("=", 1) for item in overrides)
    tasks = []
    for controller, size, stiffness in itertools.product(
        controllers, size_errors, stiffness_errors
    ):
        if controller not in GRASP_CONTROLLER_KINDS:
            raise ScenarioError(
                f"--controllers: {controller!r}; allowed: {', '.join(GRASP_CONTROLLER_KINDS)}"
            )
        point = {
            **base,
            "controller.kind": controller,
            "brick.size_error": float(size),
            "brick.stiffness_error": float(stiffness),
        }
        load_scenario(scenario, point)  # validate before anything runs
        tasks.append({"scenario": scenario, "overrides": point})
    workers = max(1, min(workers or os.cpu_count() or 1, len(tasks)))
    if workers == 1:
        return [grasp_point(task) for task in tasks]
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as executor:
        return list(executor.map(grasp_point, tasks))


def _percent(value) -> str:
    return "n/a" if value is None else f"{100 * value:.1f} %"


def format_grasp_table(rows: Sequence[Mapping]) -> str:
    """The comparison as a Markdown table."""
    header = (
        "| controller | size error (mm) | stiffness error | outcome | settled (s) | "
        "brick drop (mm) | max \\|F - Fr\\| / Fr held | peak F / Fr | final F / Fr "
        f"({', '.join(FINGERS)}) |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for row in rows:
        settled = "never" if row["settling_time"] is None else f"{row['settling_time']:.2f}"
        final = ", ".join(f"{ratio:.2f}" for ratio in row["final_force_ratio"])
        lines.append(
            f"| {row['controller']} | {1e3 * row['size_error']:+.0f} | "
            f"x{row['stiffness_error']:g} | **{row['outcome']}** | {settled} | "
            f"{1e3 * row['brick_drop']:.3f} | {_percent(row['max_relative_force_error_held'])} | "
            f"{row['peak_force_ratio']:.2f} | {final} |"
        )
    return header + "\n".join(lines) + "\n"
