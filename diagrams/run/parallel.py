"""Simulations in worker processes: one point, a pool of workers, and Ctrl-C.

``admittance sweep``, ``admittance compare`` and ``admittance grasp-compare`` run their
points here:

* :func:`simulate_point` loads one scenario with its overrides and runs it (an arm's
  ``run_scenario`` or a grasp's ``run_grasp``, by the scenario's kind); a run that fails (it
  diverges, the integrator gives up, the scenario cannot start) comes back as a failed
  :class:`PointRun` with a one-line reason, never as an exception, so one bad point does
  not stop the others.
* :func:`run_tasks` calls a task function on each task in worker processes (``local``: a
  ``ProcessPoolExecutor`` started with ``spawn``, a fresh interpreter with no forked Drake
  state; ``dask``: a ``dask.distributed`` cluster) and hands each result to a callback in
  the parent as it finishes.
* Ctrl-C: the workers ignore SIGINT (a terminal sends it to the whole process group; the
  parent stops them), and SIGINT stays blocked while they start, so that a worker never
  prints a traceback of its own. The parent gets KeyboardInterrupt (SIGTERM too, inside
  :func:`sigterm_interrupts`), terminates the workers and re-raises.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import multiprocessing
import os
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence

from admittance.diagrams.results.interrupts import sigint_held_back
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError

__all__ = [
    "ENGINES",
    "PointRun",
    "WorkerDiedError",
    "check_workers",
    "check_engine",
    "default_workers",
    "max_workers",
    "run_tasks",
    "sigterm_interrupts",
    "simulate_point",
]

ENGINES = ("local", "dask")


class WorkerDiedError(RuntimeError):
    """A worker process died (killed, out of memory, a crash): the run of the tasks stopped."""


# --- one point ----------------------------------------------------------------------------


@dataclasses.dataclass
class PointRun:
    """One simulated point: its metrics, or why it failed; the time series if asked for."""

    failed: bool
    # One line: why the run failed (None if it did not).
    failure: str | None
    # The run's metrics.json dictionary (partial for a diverged run, empty without a run).
    metrics: dict
    # Fr of the point's scenario, N: a float for the arm, one per finger for a grasp (None
    # if the scenario did not load).
    force_reference: float | list[float] | None
    # Seconds of Simulator.AdvanceTo (None without a run).
    wall_time: float | None
    # Build, run and metrics, s.
    point_time: float = 0.0
    # time and force arrays (and, for the arm, reference_offset: the wall-normal Xr), with
    # keep_series.
    series: dict | None = None


def _first_line(error: BaseException) -> str:
    text = str(error)
    return text.splitlines()[0] if text else ""


def simulate_point(
    scenario: str, overrides: Sequence[str] | Mapping, *, keep_series: bool = False
) -> PointRun:
    """Loads `scenario` (a built-in name or a YAML path) with `overrides` and runs it.

    Runs in a worker process: it imports the simulation itself. The scenario runs through
    its robot's record. Failures are returned as a failed PointRun: SimulationDivergedError
    (with the partial run's metrics and series), and ScenarioError or RuntimeError (the
    scenario cannot start, Drake refuses it).
    """
    from admittance.diagrams.robots.kinds import robot_of
    from admittance.diagrams.run.engine import SimulationDivergedError

    start = time.perf_counter()
    force_reference = None
    robot = None
    try:
        loaded = load_scenario(scenario, overrides)
        force_reference = loaded.force_reference
        robot = robot_of(loaded)
        result = robot.run(loaded)
        failed, failure = False, None
    except SimulationDivergedError as diverged:
        result = diverged.result
        failed, failure = True, _first_line(diverged)
    except (ScenarioError, RuntimeError) as error:
        return PointRun(
            failed=True,
            failure=f"{type(error).__name__}: {_first_line(error)}",
            metrics={},
            force_reference=force_reference,
            wall_time=None,
            point_time=time.perf_counter() - start,
        )
    series = robot.series(result) if keep_series else None
    return PointRun(
        failed=failed,
        failure=failure,
        metrics=result.metrics,
        force_reference=force_reference,
        wall_time=result.wall_time,
        point_time=time.perf_counter() - start,
        series=series,
    )


# --- workers ------------------------------------------------------------------------------

# Each worker is a process of its own with Drake loaded (a few hundred MB): more than this
# many would only exhaust the memory.
_WORKERS_PER_CORE = 4
_MIN_WORKER_LIMIT = 16


def default_workers() -> int:
    """All cores."""
    return os.cpu_count() or 1


def max_workers() -> int:
    """The most --workers allowed on this machine: 4 per core, and at least 16."""
    return max(_MIN_WORKER_LIMIT, _WORKERS_PER_CORE * default_workers())


def check_workers(workers: int | None) -> int:
    """`workers`, or all cores for None; raises ScenarioError outside [1, max_workers()]."""
    if workers is None:
        return default_workers()
    limit = max_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= limit:
        raise ScenarioError(
            f"--workers {workers}: must be an integer in [1, {limit}] (each worker is a "
            f"process with Drake loaded; this machine has {default_workers()} cores)"
        )
    return workers


def check_engine(engine: str, scheduler: str | None) -> None:
    """Raises ScenarioError for an unknown engine, a scheduler without dask, dask missing."""
    if engine not in ENGINES:
        raise ScenarioError(f"--engine {engine}: must be 'local' or 'dask'")
    if scheduler and engine != "dask":
        raise ScenarioError("--scheduler: only used with --engine dask")
    if engine == "dask":
        _import_distributed()


def _worker_ignores_sigint() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the workers).

    The worker started with SIGINT blocked (inherited from the parent, see sigint_held_back):
    ignore it, then unblock, which drops a Ctrl-C that arrived while the worker started.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@contextlib.contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """While it is active, SIGTERM (plain `kill`) stops the run as Ctrl-C does."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _stop_pool(executor: concurrent.futures.ProcessPoolExecutor) -> None:
    """Cancels pending tasks and terminates the workers (a task in progress is lost)."""
    # ProcessPoolExecutor has no public terminate before Python 3.14.
    processes = list(getattr(executor, "_processes", {}).values())
    manager = getattr(executor, "_executor_manager_thread", None)
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
            process.join(timeout=5)
    # The pool's manager thread sees its workers gone and closes its wake-up pipe; let it
    # finish here. Left to the interpreter's exit, CPython 3.11's exit hook can write to
    # that pipe while the thread closes it and print "Exception ignored ... Bad file
    # descriptor" after the command's one line (seen once in CI, under heavy load).
    if manager is not None:
        manager.join(timeout=10)


def _run_local(function: Callable, tasks: list, workers: int, on_result: Callable) -> None:
    context = multiprocessing.get_context("spawn")  # a fresh interpreter: no forked Drake
    executor = concurrent.futures.ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)),
        mp_context=context,
        initializer=_worker_ignores_sigint,
    )
    try:
        with sigint_held_back():  # submit starts the workers, which inherit the block
            futures = [executor.submit(function, task) for task in tasks]
        for future in concurrent.futures.as_completed(futures):
            on_result(future.result())
    except concurrent.futures.process.BrokenProcessPool:
        _stop_pool(executor)
        raise WorkerDiedError("a worker process died (killed, out of memory or crashed)") from None
    except BaseException:
        _stop_pool(executor)
        raise
    executor.shutdown(wait=True)


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ScenarioError(
            "--engine dask: dask.distributed is not installed; install it with "
            "`pip install -e .[dask]` (or `pip install distributed`)"
        ) from None
    return distributed


def _run_dask(
    function: Callable,
    tasks: list,
    workers: int,
    scheduler: str | None,
    on_result: Callable,
    key: Callable[[object], str],
) -> None:
    distributed = _import_distributed()
    cluster = None
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as error:
            message = _first_line(error) or type(error).__name__
            raise ScenarioError(f"--scheduler {scheduler}: cannot connect: {message}") from None
    else:
        cluster = distributed.LocalCluster(
            n_workers=min(workers, len(tasks)),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
        )
        client = distributed.Client(cluster)
    futures = []
    try:
        run = uuid.uuid4().hex[:8]
        futures = [
            client.submit(function, task, key=f"admittance-{run}-{key(task)}") for task in tasks
        ]
        for future in distributed.as_completed(futures):
            on_result(future.result())
    except distributed.KilledWorker:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise WorkerDiedError("a worker process died (killed, out of memory or crashed)") from None
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_tasks(
    function: Callable,
    tasks: list,
    on_result: Callable,
    *,
    workers: int,
    engine: str = "local",
    scheduler: str | None = None,
    key: Callable[[object], str] = lambda task: uuid.uuid4().hex,
) -> None:
    """Calls ``on_result(function(task))`` for every task, in worker processes.

    `function` must be importable by the workers (a module-level function); `on_result`
    runs in the parent, in completion order. `key` names a task on a dask cluster.

    Raises:
        KeyboardInterrupt: (Ctrl-C, or SIGTERM inside sigterm_interrupts) after the workers
            were stopped.
        WorkerDiedError: a worker process died; the other tasks were stopped.
    """
    if not tasks:
        return
    if engine == "local":
        _run_local(function, tasks, workers, on_result)
    else:
        _run_dask(function, tasks, workers, scheduler, on_result, key)
