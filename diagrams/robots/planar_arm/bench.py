"""Benchmark of one scenario: how long Simulator.AdvanceTo takes and where the time goes.

``run_benchmark(scenario, repeat)`` measures, in one call:

* the closed loop (BuildClosedLoop + SetInitialConditions): one warm-up run through the
  project's ``run_scenario`` (it stops a diverging scenario before any timing, and gives the
  force metrics and, under tracemalloc, the peak of Python allocations), then ``repeat``
  timed runs of ``Simulator.AdvanceTo`` alone (building and result collection excluded):
  median, min and max wall time, real-time factor, the integrator's statistics (steps,
  derivative evaluations, Newton iterations, Jacobians, ...);
* the Python callbacks, in one extra profiling run: every calc of the project's LeafSystems
  (``Do*``, ``_Calc*``/``_calc*``, ``*Update*`` methods) is wrapped with a counter and a
  timer, so the timed runs are not slowed. It gives the calls per derivative evaluation
  and the time spent inside them (exclusive of nested callbacks, inclusive of the pydrake
  calls they make);
* the FLOOR: the bare MultibodyPlant of the same URDF (``AddPlanarArm``) held at the
  closed loop's initial configuration by constant gravity torques, simulated for the same
  duration with the same SimulatorConfig; and the ratio closed loop / floor;
* one derivative evaluation alone, of the closed loop and of the floor at their initial
  states, timed in CPU time of this process (``time.process_time``, the least of many
  rounds), so that other processes on a shared machine barely move it: the cost per
  evaluation without the integrator's own work and the logging;
* the logging cost: one run with the loggers off (or, for a scenario that logs
  periodically, logging every step), against the timed median;
* memory: the process's peak resident set size (``ru_maxrss``) and the tracemalloc peak of
  the warm-up run.

The runs themselves are :mod:`.bench_runs`'s; ``bench_report.format_benchmark(report,
before)`` renders the report as a readable table, with an earlier run's report beside it if
one is given.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import os
import platform
import resource
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable

import numpy as np

from admittance.diagrams.robots.planar_arm.bench_runs import (
    TimedRun,
    advance,
    advance_closed_loop,
    advance_floor,
    initial_positions,
    profile_callbacks,
    spread,
    time_one_evaluation_of_each,
)
from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop, SetInitialConditions
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.scenario.sections import LoggingConfig
from admittance.diagrams.views.formatting import seconds

__all__ = [
    "run_benchmark",
]

# --- memory and environment -------------------------------------------------------------


def _peak_rss_mb() -> float:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # Linux reports KiB, macOS bytes.
    return peak / (1024.0**2 if sys.platform == "darwin" else 1024.0)


def _environment() -> dict:
    try:
        drake = importlib.metadata.version("drake")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover (a source build)
        drake = "unknown"
    return {
        "python": platform.python_version(),
        "drake": drake,
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
    }


# --- the benchmark ----------------------------------------------------------------------


def _per(numerator: float, denominator: float) -> float | None:
    return numerator / denominator if denominator else None


def _silent(stage: str) -> None:
    pass


def run_benchmark(
    scenario: Scenario, repeat: int = 3, progress: Callable[[str], None] = _silent
) -> dict:
    """Times `scenario` and its floor, and reports where the time goes.

    Args:
        scenario: a validated scenario (``load_scenario``).
        repeat: number of timed runs after the warm-up (>= 1).
        progress: called with a short description as each run starts.

    Returns:
        A JSON-serialisable dict (see ``bench_report.format_benchmark`` for its reading):
        ``scenario``, ``repeat``, ``closed_loop``, ``python``, ``floor``,
        ``ratio_to_floor``, ``per_evaluation_ratio_to_floor``, ``cpu_ratio_to_floor``,
        ``cpu_per_evaluation_ratio_to_floor``, ``one_evaluation``, ``logging``, ``memory``,
        ``environment``. Times are in seconds unless a key says otherwise.

    Raises:
        ValueError: `repeat` < 1.
        SimulationDivergedError: the warm-up run diverged (nothing is timed).
    """
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat}")
    rss_before = _peak_rss_mb()
    warm_up, python_peak = _warm_up(scenario, progress)
    runs, build_times = _timed_runs(scenario, repeat, progress)
    median = statistics.median([run.wall_time for run in runs])
    python, profiled = _python_section(scenario, median, progress)
    closed_loop = _closed_loop_section(scenario, runs, build_times, profiled, warm_up)
    progress(f"the floor: the bare arm, {repeat + 1} run(s)")
    positions = initial_positions(scenario)
    floor = _floor_section(scenario, repeat, positions)
    progress("one derivative evaluation alone, of the closed loop and of the floor")
    one_evaluation = time_one_evaluation_of_each(scenario, positions)
    logging = _logging_section(scenario, median, runs[0], progress)
    return {
        "scenario": _scenario_section(scenario),
        "repeat": repeat,
        "closed_loop": closed_loop,
        "python": python,
        "floor": floor,
        **_ratios_to_floor(closed_loop, floor),
        "one_evaluation": one_evaluation,
        "logging": logging,
        "memory": {
            "peak_rss_mb": _peak_rss_mb(),
            "peak_rss_mb_before": rss_before,
            "python_peak_mb": python_peak / 1024.0**2,
        },
        "environment": _environment(),
    }


def _warm_up(scenario: Scenario, progress: Callable[[str], None]) -> tuple[object, float]:
    """The warm-up through the project's path (not timed), under tracemalloc: its result
    and the peak of Python allocations, bytes."""
    tracing = tracemalloc.is_tracing()
    if not tracing:
        tracemalloc.start()
    tracemalloc.reset_peak()
    progress("warm-up run (not timed)")
    try:
        warm_up = run_scenario(scenario)
        _, python_peak = tracemalloc.get_traced_memory()
    finally:
        if not tracing:
            tracemalloc.stop()
    return warm_up, python_peak


def _timed_runs(
    scenario: Scenario, repeat: int, progress: Callable[[str], None]
) -> tuple[list[TimedRun], list[float]]:
    """`repeat` timed runs of AdvanceTo alone, and the build time of each loop."""
    build_times = []
    runs = []
    for number_of_run in range(1, repeat + 1):
        progress(f"timed run {number_of_run} of {repeat}")
        start = time.perf_counter()
        loop = BuildClosedLoop(scenario)
        build_times.append(time.perf_counter() - start)
        runs.append(
            advance(
                loop.diagram,
                scenario,
                lambda context, loop=loop: SetInitialConditions(loop, context),
            )
        )
    return runs, build_times


def _closed_loop_section(
    scenario: Scenario,
    runs: list[TimedRun],
    build_times: list[float],
    profiled: TimedRun,
    warm_up,
) -> dict:
    """The report's ``closed_loop``: the timed runs' spread, the first one's integrator
    statistics, whether every run (the profiling one too) took the same steps, and the
    warm-up's force check."""
    wall = spread([run.wall_time for run in runs])
    cpu = spread([run.cpu_time for run in runs])
    median = wall["median"]
    timed = runs[0]
    per_evaluation = _per(median, timed.derivative_evaluations)
    metrics = warm_up.metrics
    return {
        "wall_time": wall,
        "cpu_time": cpu,
        "build_time": statistics.median(build_times),
        "real_time_factor": _per(scenario.duration, median),
        "integrator_steps": timed.steps,
        "derivative_evaluations": timed.derivative_evaluations,
        "derivative_evaluations_per_step": _per(timed.derivative_evaluations, timed.steps),
        "wall_time_per_step_us": 1e6 * median / timed.steps,
        "wall_time_per_derivative_evaluation_us": 1e6 * per_evaluation,
        "deterministic": all(
            (run.steps, run.derivative_evaluations) == (timed.steps, timed.derivative_evaluations)
            for run in [*runs, profiled]
        ),
        "integrator": timed.statistics,
        "warm_up_wall_time": warm_up.wall_time,
        "peak_force": metrics.get("peak_force"),
        "contact_losses": metrics.get("contact_losses"),
    }


def _python_section(
    scenario: Scenario, median: float, progress: Callable[[str], None]
) -> tuple[dict, TimedRun]:
    """The report's ``python``: every callback of a separate profiling run, most time
    first; and that run."""
    progress("profiling run (every Python callback counted and timed)")
    profiled, profiler, names = profile_callbacks(scenario)
    callbacks = []
    for (system_id, method), (calls, time_inside) in profiler.entries.items():
        callbacks.append(
            {
                "name": f"{names.get(system_id, '?')}.{method}",
                "calls": calls,
                "per_derivative_evaluation": _per(calls, profiled.derivative_evaluations),
                "time": time_inside,
                "mean_us": 1e6 * time_inside / calls,
            }
        )
    callbacks.sort(key=lambda entry: entry["time"], reverse=True)
    total_calls = sum(entry["calls"] for entry in callbacks)
    python_fraction = _per(profiler.top_level_time, profiled.wall_time)
    section = {
        "callback_calls": total_calls,
        "callbacks_per_derivative_evaluation": _per(total_calls, profiled.derivative_evaluations),
        "callbacks_per_step": _per(total_calls, profiled.steps),
        "time_in_callbacks": profiler.top_level_time,
        "fraction_of_wall_time": python_fraction,
        "estimated_time_in_timed_runs": (
            python_fraction * median if python_fraction is not None else None
        ),
        "profiled_wall_time": profiled.wall_time,
        "callbacks": callbacks,
    }
    return section, profiled


def _floor_section(scenario: Scenario, repeat: int, positions: np.ndarray) -> dict:
    """The report's ``floor``: the bare plant, same duration and SimulatorConfig, after a
    warm-up run; its drift from `positions` over the first timed run."""
    advance_floor(scenario, positions)  # warm-up
    floor_runs = [advance_floor(scenario, positions) for _ in range(repeat)]
    floor_wall = spread([run.wall_time for run in floor_runs])
    floor_cpu = spread([run.cpu_time for run in floor_runs])
    floor = floor_runs[0]
    floor_per_evaluation = _per(floor_wall["median"], floor.derivative_evaluations)
    return {
        "wall_time": floor_wall,
        "cpu_time": floor_cpu,
        "real_time_factor": _per(scenario.duration, floor_wall["median"]),
        "integrator_steps": floor.steps,
        "derivative_evaluations": floor.derivative_evaluations,
        "wall_time_per_step_us": 1e6 * floor_wall["median"] / floor.steps,
        "wall_time_per_derivative_evaluation_us": (
            1e6 * floor_per_evaluation if floor_per_evaluation is not None else None
        ),
        "max_joint_drift": float(np.max(np.abs(floor.final_positions - positions))),
    }


def _ratios_to_floor(closed_loop: dict, floor: dict) -> dict:
    """The closed loop over the floor: in wall time, per derivative evaluation, and the
    same in this process's CPU time."""
    median = closed_loop["wall_time"]["median"]
    per_evaluation = _per(median, closed_loop["derivative_evaluations"])
    floor_median = floor["wall_time"]["median"]
    floor_per_evaluation = _per(floor_median, floor["derivative_evaluations"])
    cpu_median, floor_cpu_median = closed_loop["cpu_time"]["median"], floor["cpu_time"]["median"]
    return {
        "ratio_to_floor": _per(median, floor_median),
        "per_evaluation_ratio_to_floor": (
            _per(per_evaluation, floor_per_evaluation) if floor_per_evaluation else None
        ),
        # The same ratios in this process's CPU time: on a shared machine, other processes
        # stretch wall times (short runs most), CPU times far less.
        "cpu_ratio_to_floor": _per(cpu_median, floor_cpu_median),
        "cpu_per_evaluation_ratio_to_floor": _per(
            _per(cpu_median, closed_loop["derivative_evaluations"]),
            _per(floor_cpu_median, floor["derivative_evaluations"]),
        ),
    }


def _logging_section(
    scenario: Scenario, median: float, timed: TimedRun, progress: Callable[[str], None]
) -> list[dict]:
    """The report's ``logging``: the timed median against one run with the other logging
    setting (none for loggers that publish once, else every step)."""
    progress("one run with the other logging setting")
    if scenario.logging.period == 0.0:
        # Loggers that publish once, at t = 0: the cost of the loop without logging.
        variant, variant_period = "none", 2.0 * scenario.duration + 1.0
    else:
        variant, variant_period = "every step", 0.0
    variant_run = advance_closed_loop(
        dataclasses.replace(scenario, logging=LoggingConfig(period=variant_period))
    )
    current = "every step" if scenario.logging.period == 0.0 else seconds(scenario.logging.period)
    return [
        {"logging": current, "wall_time": median, "integrator_steps": timed.steps},
        {
            "logging": variant,
            "wall_time": variant_run.wall_time,
            "integrator_steps": variant_run.steps,
            "relative_to_timed": _per(variant_run.wall_time, median),
        },
    ]


def _scenario_section(scenario: Scenario) -> dict:
    """The report's ``scenario``: what was timed, and with which simulator settings."""
    simulator_config = scenario.simulator
    return {
        "name": scenario.name,
        "duration": scenario.duration,
        "sensor": scenario.sensor.kind,
        "integration_scheme": simulator_config.integration_scheme,
        "accuracy": simulator_config.accuracy,
        "max_step_size": simulator_config.max_step_size,
        "use_error_control": simulator_config.use_error_control,
        "logging_period": scenario.logging.period,
    }
