"""Running a sweep: the points not yet in points.jsonl, then the table, summary and plots."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

from admittance.diagrams.app.sweep.definition import SweepDefinition, SweepPoint
from admittance.diagrams.app.sweep.folder import (
    LOCK_FILE,
    POINTS_FILE,
    SUMMARY_FILE,
    TABLE_FILE,
    check_folder,
    finish_folder,
    locked,
    prepare_folder,
)
from admittance.diagrams.app.sweep.plots import plot_summary
from admittance.diagrams.app.sweep.points import PointsFile, read_points, rewrite_points, run_point
from admittance.diagrams.app.sweep.specs import SweepError
from admittance.diagrams.app.sweep.summary import summarize, table_text
from admittance.diagrams.results.folder import atomic_write_text
from admittance.diagrams.run.parallel import (
    WorkerDiedError,
    check_engine,
    check_workers,
    run_tasks,
    sigterm_interrupts,
)
from admittance.diagrams.views.formatting import number, seconds

__all__ = ["SweepOutcome", "run_sweep"]


@dataclasses.dataclass
class SweepOutcome:
    """What a (finished) run of a sweep did and wrote."""

    out_dir: Path
    total: int
    skipped: int
    ran: int
    failed: int
    elapsed: float
    summary: str
    files: list[Path]


def _task(definition: SweepDefinition, point: SweepPoint) -> dict:
    return {
        "index": point.index,
        "point_id": point.point_id,
        "values": point.values,
        "scenario": definition.scenario_source,
        "overrides": definition.overrides_of(point),
    }


def _silent(line: str) -> None:
    pass


def run_sweep(
    definition: SweepDefinition,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    engine: str = "local",
    scheduler: str | None = None,
    force: bool = False,
    progress: Callable[[str], None] = _silent,
) -> SweepOutcome:
    """Runs the points of `definition` not yet in `out_dir`/points.jsonl; writes the table.

    Args:
        progress: called with one line per finished point (and on resume).

    Raises:
        ScenarioError: (a SweepError or the runner's) bad workers/engine/scheduler, a folder
            holding another sweep (without `force`), dask missing; before any point runs.
        KeyboardInterrupt: (Ctrl-C or SIGTERM) the workers are stopped first; points.jsonl
            keeps every finished point, so running the same sweep again resumes.
        WorkerDiedError: a worker process died; the finished points are kept likewise.
    """
    workers = check_workers(workers)
    check_engine(engine, scheduler)
    out_dir = Path(out_dir)
    check_folder(out_dir, force)
    out_dir.mkdir(parents=True, exist_ok=True)
    lock_was_there = (out_dir / LOCK_FILE).exists()
    start = time.perf_counter()
    with locked(out_dir):
        _prepare(definition, out_dir, force, lock_was_there)
        points_path = out_dir / POINTS_FILE
        rows, done, todo = _pending(definition, out_dir, progress)
        if todo:
            where = f"dask at {scheduler}" if scheduler else f"{engine}, {workers} workers"
            progress(f"running {len(todo)} points ({where})")
        _run_points(
            definition,
            todo,
            rows,
            points_path,
            finished=len(done),
            progress=progress,
            workers=workers,
            engine=engine,
            scheduler=scheduler,
        )
        ours = [rows[point.point_id] for point in definition.points if point.point_id in rows]
        summary = summarize(definition, ours)
        table = out_dir / TABLE_FILE
        atomic_write_text(table, table_text(definition.keys, ours))
        atomic_write_text(out_dir / SUMMARY_FILE, summary)
        plots = plot_summary(definition, ours, out_dir) if ours else []
        finish_folder(definition, out_dir)
    return SweepOutcome(
        out_dir=out_dir,
        total=len(definition.points),
        skipped=len(done),
        ran=len(todo),
        failed=sum(bool(r.get("failed")) for r in ours),
        elapsed=time.perf_counter() - start,
        summary=summary,
        files=[points_path, table, out_dir / SUMMARY_FILE, *plots],
    )


def _prepare(definition: SweepDefinition, out_dir: Path, force: bool, lock_was_there: bool) -> None:
    """The folder made this sweep's (under its lock); as it was if it changed meanwhile."""
    try:
        prepare_folder(definition, out_dir, force)
    except SweepError:  # the folder changed since check_folder: leave it as it was
        if not lock_was_there:
            (out_dir / LOCK_FILE).unlink(missing_ok=True)
        raise


def _pending(
    definition: SweepDefinition, out_dir: Path, progress: Callable[[str], None]
) -> tuple[dict, set[str], list[SweepPoint]]:
    """The rows of points.jsonl (its unreadable lines dropped), the ids of this sweep's
    points among them, and the points still to run."""
    points_path = out_dir / POINTS_FILE
    rows, bad = read_points(points_path)
    if bad:
        rewrite_points(points_path, rows.values())
        progress(f"ignored {bad} unreadable line(s) of {points_path} (a run killed mid-write)")
    wanted = {point.point_id for point in definition.points}
    done = {point_id for point_id in rows if point_id in wanted}
    todo = [point for point in definition.points if point.point_id not in done]
    total = len(definition.points)
    if done:
        progress(
            f"resuming {out_dir}: skipped {len(done)} finished points of {total}; "
            f"{len(todo)} to run"
        )
    return rows, done, todo


def _point_line(definition: SweepDefinition, row: dict, finished: int) -> str:
    """The progress line of a finished point: its place, values, time and outcome."""
    total = len(definition.points)
    metrics = row["metrics"]
    outcome = (
        f"FAILED: {row['failure']}"
        if row["failed"]
        else f"peak {number(metrics.get('peak_force'), ' N')}, steady-state error "
        f"{number(metrics.get('steady_state_force_error'), ' N')}"
    )
    point = definition.points[row["index"]]
    return (
        f"[{finished:{len(str(total))}d}/{total}] #{row['index']} ({point.describe()}) "
        f"in {seconds(metrics.get('point_time'))}: {outcome}"
    )


def _run_points(
    definition: SweepDefinition,
    todo: list[SweepPoint],
    rows: dict,
    points_path: Path,
    *,
    finished: int,
    progress: Callable[[str], None],
    workers: int,
    engine: str,
    scheduler: str | None,
) -> None:
    """Runs `todo`, each finished row appended to points.jsonl and put in `rows`."""
    points_file = PointsFile(points_path)

    def on_row(row: dict) -> None:
        nonlocal finished
        points_file.append(row)
        rows[row["point_id"]] = row
        finished += 1
        progress(_point_line(definition, row, finished))

    try:
        with sigterm_interrupts():
            run_tasks(
                run_point,
                [_task(definition, point) for point in todo],
                on_row,
                workers=workers,
                engine=engine,
                scheduler=scheduler,
                key=lambda task: task["point_id"],
            )
    except WorkerDiedError:
        raise WorkerDiedError(
            "a worker process died while running a point (killed, out of memory or "
            f"crashed); the finished points are kept in {points_path}: run the same "
            "command again to resume"
        ) from None
    finally:
        points_file.close()
