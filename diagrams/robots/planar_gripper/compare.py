"""Position-only fingers against the paper's law, over brick size and stiffness errors.

Each point is one grasp scenario with ``brick.size_error`` and ``brick.stiffness_error``
set and ``controller.kind`` either ``pid_only`` (the fingers on the plan that closes on the
nominal brick) or ``optimal_admittance``; everything else is the base scenario's. The
verdict of each run (held, crushed, lost) is robots.planar_gripper.run's. The points run in worker
processes by the application's runner (diagrams/run/parallel.py: ``simulate_point``
for one run, ``run_tasks`` for the pool and Ctrl-C), as ``admittance compare`` and
``admittance sweep`` do; a run that fails is a row marked failed, not an exception.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from admittance.diagrams.results.folder import ResultFolder, result_folder
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GRASP_CONTROLLER_KINDS
from admittance.diagrams.run.parallel import (
    check_workers,
    run_tasks,
    sigterm_interrupts,
    simulate_point,
)
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.diagrams.views.formatting import seconds

__all__ = [
    "grasp_compare_command",
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
    """Runs one point (in a worker process) and returns its row (a failed run's too)."""
    overrides = dict(task["overrides"])
    run = simulate_point(task["scenario"], overrides)
    metrics = run.metrics  # partial for a diverged run, empty if it never started
    fingers = metrics.get("fingers", [])
    return {
        "index": task["index"],
        "controller": overrides["controller.kind"],
        "size_error": overrides["brick.size_error"],
        "stiffness_error": overrides["brick.stiffness_error"],
        "outcome": "failed" if run.failed else metrics["outcome"],
        "failure": run.failure,
        "settling_time": metrics.get("settling_time"),
        "brick_drop": metrics.get("brick_drop"),
        "max_relative_force_error_held": metrics.get("max_relative_force_error_held"),
        "peak_force_ratio": metrics.get("peak_force_ratio"),
        "final_force_ratio": [f["final_mean_force"] / f["force_reference"] for f in fingers],
        "in_contact": [f["in_contact_after_ramp"] for f in fingers],
        "max_slip": metrics.get("max_slip"),
        "wall_time": metrics.get("wall_time"),
        "point_time": run.point_time,
    }


def _silent(line: str) -> None:
    pass


def compare_grasps(
    scenario: str,
    overrides: Sequence[str] = (),
    *,
    size_errors: Sequence[float] = DEFAULT_SIZE_ERRORS,
    stiffness_errors: Sequence[float] = DEFAULT_STIFFNESS_ERRORS,
    controllers: Sequence[str] = GRASP_CONTROLLER_KINDS,
    workers: int | None = None,
    progress: Callable[[str], None] = _silent,
) -> list[dict]:
    """One row per (controller, size error, stiffness error), in that order.

    Every point is validated before any runs; the runs go to `workers` processes (default:
    all cores).

    Args:
        progress: called with one line as the runs start and as each one finishes.

    Raises:
        ScenarioError: a bad key, value, controller or `workers`.
        KeyboardInterrupt: Ctrl-C or SIGTERM, after the workers were stopped.
        WorkerDiedError: a worker process died.
    """
    workers = check_workers(workers)
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
        tasks.append({"index": len(tasks), "scenario": scenario, "overrides": point})
    if not tasks:
        return []
    workers = min(workers, len(tasks))
    progress(f"running {len(tasks)} grasps ({workers} worker{'s' if workers > 1 else ''})")
    rows: dict[int, dict] = {}

    def on_row(row: dict) -> None:
        rows[row["index"]] = row
        progress(
            f"[{len(rows)}/{len(tasks)}] {row['controller']}, size "
            f"{1e3 * row['size_error']:+.0f} mm, stiffness x{row['stiffness_error']:g} in "
            f"{seconds(row['point_time'])}: {row['outcome']}"
            + (f" ({row['failure']})" if row["failure"] else "")
        )

    with sigterm_interrupts():
        run_tasks(grasp_point, tasks, on_row, workers=workers, key=lambda task: str(task["index"]))
    return [rows[index] for index in range(len(tasks))]


def _fixed(value, scale: float = 1.0, digits: int = 2, suffix: str = "") -> str:
    return "n/a" if value is None else f"{scale * value:.{digits}f}{suffix}"


def format_grasp_table(rows: Sequence[Mapping]) -> str:
    """The comparison as a Markdown table; a failed run's reason on a line below it."""
    header = (
        "| controller | size error (mm) | stiffness error | outcome | settled (s) | "
        "brick drop (mm) | max \\|F - Fr\\| / Fr held | peak F / Fr | final F / Fr "
        f"({', '.join(FINGERS)}) |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines, failures = [], []
    for row in rows:
        if row["settling_time"] is None:
            settled = "n/a" if row["failure"] else "never"
        else:
            settled = f"{row['settling_time']:.2f}"
        final = ", ".join(f"{ratio:.2f}" for ratio in row["final_force_ratio"]) or "n/a"
        lines.append(
            f"| {row['controller']} | {1e3 * row['size_error']:+.0f} | "
            f"x{row['stiffness_error']:g} | **{row['outcome']}** | {settled} | "
            f"{_fixed(row['brick_drop'], 1e3, 3)} | "
            f"{_fixed(row['max_relative_force_error_held'], 100, 1, ' %')} | "
            f"{_fixed(row['peak_force_ratio'])} | {final} |"
        )
        if row["failure"]:
            failures.append(
                f"{row['controller']}, size {1e3 * row['size_error']:+.0f} mm, stiffness "
                f"x{row['stiffness_error']:g}: {row['failure']}"
            )
    table = header + "\n".join(lines) + "\n"
    return table + ("\n" + "\n".join(failures) + "\n" if failures else "")


def grasp_compare_command(
    source,
    overrides,
    out: Path,
    *,
    controllers: str | None = None,
    size_errors: Sequence[float] = DEFAULT_SIZE_ERRORS,
    stiffness_errors: Sequence[float] = DEFAULT_STIFFNESS_ERRORS,
    workers: int | None = None,
    overwrite: bool = False,
    progress: Callable[[str], None] = _silent,
) -> tuple[str, ResultFolder]:
    """`admittance grasp-compare`: the controllers (the comma list `controllers`, default
    all) over the brick's size and stiffness errors; table.md and rows.json written to
    `out`, and the table to print."""
    kinds = (
        [kind.strip() for kind in controllers.split(",")]
        if controllers
        else list(GRASP_CONTROLLER_KINDS)
    )
    rows = compare_grasps(
        source,
        overrides,
        size_errors=size_errors,
        stiffness_errors=stiffness_errors,
        controllers=kinds,
        workers=workers,
        progress=progress,
    )
    table = format_grasp_table(rows)
    progress(f"writing {out}/")
    with result_folder(out, overwrite=overwrite) as folder:
        folder.write_text("table.md", table)
        folder.write_json("rows.json", rows)
    return table, folder
