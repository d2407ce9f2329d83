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

``bench_report.format_benchmark(report, before)`` renders the report as a readable table,
with an earlier run's report beside it if one is given.
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
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop, SetInitialConditions
from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.run.profiling import (
    CallbackProfiler,
    named_subsystems,
    python_system_classes,
)
from admittance.diagrams.scenario.sections import LoggingConfig
from admittance.diagrams.views.formatting import seconds

__all__ = [
    "run_benchmark",
]

# Rounds and evaluations per round of the single-evaluation timing.
_EVALUATION_ROUNDS = 25
_EVALUATIONS_PER_ROUND = 200


# --- timing helpers ---------------------------------------------------------------------


def _spread(samples: list[float]) -> dict:
    """Median, min, max and the samples of a list of wall times, s."""
    return {
        "median": statistics.median(samples),
        "min": min(samples),
        "max": max(samples),
        "samples": list(samples),
    }


def _integrator_statistics(simulator: Simulator) -> dict:
    """The integrator's statistics (IntegratorBase.GetStatisticsSummary), plain numbers."""
    summary = {}
    for name, value in simulator.get_integrator().GetStatisticsSummary():
        key = name.removeprefix("integrator_")
        summary[key] = int(value) if float(value).is_integer() else float(value)
    return summary


@dataclasses.dataclass
class _Run:
    """One simulated run: AdvanceTo's wall time and the integrator's statistics."""

    wall_time: float
    cpu_time: float  # this process's CPU time over the same AdvanceTo, s
    steps: int
    derivative_evaluations: int
    statistics: dict
    final_positions: np.ndarray | None = None


def _advance(
    diagram: Diagram,
    scenario: Scenario,
    initialize: Callable[[Context], None],
    plant=None,
) -> _Run:
    """Simulates `diagram` for scenario.duration with scenario.simulator; times AdvanceTo."""
    simulator = Simulator(diagram)
    ApplySimulatorConfig(scenario.simulator, simulator)
    context = simulator.get_mutable_context()
    initialize(context)
    simulator.Initialize()
    start, cpu_start = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(scenario.duration)
    wall_time = time.perf_counter() - start
    cpu_time = time.process_time() - cpu_start
    integrator = simulator.get_integrator()
    final_positions = None
    if plant is not None:
        final_positions = plant.GetPositions(plant.GetMyContextFromRoot(context)).copy()
    return _Run(
        wall_time=wall_time,
        cpu_time=cpu_time,
        steps=int(integrator.get_num_steps_taken()),
        derivative_evaluations=int(integrator.get_num_derivative_evaluations()),
        statistics=_integrator_statistics(simulator),
        final_positions=final_positions,
    )


def _advance_closed_loop(scenario: Scenario) -> _Run:
    loop = BuildClosedLoop(scenario)
    return _advance(loop.diagram, scenario, lambda context: SetInitialConditions(loop, context))


# --- Python callbacks -------------------------------------------------------------------


def _profile_callbacks(scenario: Scenario) -> tuple[_Run, CallbackProfiler, dict[int, str]]:
    """One closed-loop run with every Python calc counted and timed."""
    classes = python_system_classes(BuildClosedLoop(scenario).diagram)
    profiler = CallbackProfiler()
    profiler.patch(classes)
    try:
        loop = BuildClosedLoop(scenario)
        names = {id(system): name for name, system in named_subsystems(loop.diagram)}
        run = _advance(loop.diagram, scenario, lambda context: SetInitialConditions(loop, context))
    finally:
        profiler.restore()
    return run, profiler, names


# --- the floor --------------------------------------------------------------------------


def _time_one_evaluation(diagram: Diagram, context: Context) -> float:
    """CPU time of one derivative evaluation at the context's state, s.

    The state is set again before each evaluation (with a time a nanosecond later), so
    that every cached value that depends on it is recomputed, as in an integrator step.
    The least of several rounds, in this process's CPU time.
    """
    state = context.get_continuous_state_vector().CopyToVector()
    derivatives = diagram.AllocateTimeDerivatives()
    start_time = context.get_time()
    best = np.inf
    for _ in range(_EVALUATION_ROUNDS):
        start = time.process_time()
        for k in range(_EVALUATIONS_PER_ROUND):
            context.SetTimeAndContinuousState(start_time + 1e-9 * k, state)
            diagram.CalcTimeDerivatives(context, derivatives)
        best = min(best, (time.process_time() - start) / _EVALUATIONS_PER_ROUND)
    return best


def _time_one_evaluation_of_each(scenario: Scenario, positions: np.ndarray) -> dict:
    """One derivative evaluation of the closed loop and of the floor, interleaved."""
    loop = BuildClosedLoop(scenario)
    loop_context = loop.diagram.CreateDefaultContext()
    SetInitialConditions(loop, loop_context)
    floor, plant = _build_floor(scenario, positions)
    floor_context = floor.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(floor_context), positions)
    closed, bare = np.inf, np.inf
    for _ in range(2):  # interleaved, so that both see the same machine
        closed = min(closed, _time_one_evaluation(loop.diagram, loop_context))
        bare = min(bare, _time_one_evaluation(floor, floor_context))
    return {
        "closed_loop_us": 1e6 * closed,
        "floor_us": 1e6 * bare,
        "ratio": closed / bare,
        "rounds": _EVALUATION_ROUNDS,
    }


def _initial_positions(scenario: Scenario) -> np.ndarray:
    """The closed loop's initial joint positions (SetInitialConditions)."""
    loop = BuildClosedLoop(scenario)
    context = loop.diagram.CreateDefaultContext()
    SetInitialConditions(loop, context)
    return loop.plant.GetPositions(loop.plant.GetMyContextFromRoot(context)).copy()


def _build_floor(scenario: Scenario, positions: np.ndarray):
    """The bare arm held at `positions` by constant torques equal to gravity's."""
    builder = DiagramBuilder()
    plant, _ = AddScenarioArm(builder, scenario.arm)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, positions)
    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    # B u = -tau_g: the actuators cancel gravity, so the arm stays at rest.
    actuation = np.linalg.lstsq(plant.MakeActuationMatrix(), -gravity, rcond=None)[0]
    source = builder.AddSystem(ConstantVectorSource(actuation))
    source.set_name("gravity_torques")
    builder.Connect(source.get_output_port(), plant.get_actuation_input_port())
    diagram = builder.Build()
    diagram.set_name("floor")
    return diagram, plant


def _advance_floor(scenario: Scenario, positions: np.ndarray) -> _Run:
    diagram, plant = _build_floor(scenario, positions)

    def initialize(context: Context) -> None:
        plant_context = plant.GetMyMutableContextFromRoot(context)
        plant.SetPositions(plant_context, positions)
        plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    return _advance(diagram, scenario, initialize, plant)


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

    # Warm-up through the project's path, under tracemalloc (it is not timed).
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

    # Timed runs: AdvanceTo alone.
    build_times = []
    runs = []
    for number_of_run in range(1, repeat + 1):
        progress(f"timed run {number_of_run} of {repeat}")
        start = time.perf_counter()
        loop = BuildClosedLoop(scenario)
        build_times.append(time.perf_counter() - start)
        runs.append(
            _advance(
                loop.diagram,
                scenario,
                lambda context, loop=loop: SetInitialConditions(loop, context),
            )
        )
    wall = _spread([run.wall_time for run in runs])
    cpu = _spread([run.cpu_time for run in runs])
    median = wall["median"]
    timed = runs[0]

    # Python callbacks, in a separate run.
    progress("profiling run (every Python callback counted and timed)")
    profiled, profiler, names = _profile_callbacks(scenario)
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

    # The floor: the bare plant, same duration and SimulatorConfig.
    progress(f"the floor: the bare arm, {repeat + 1} run(s)")
    positions = _initial_positions(scenario)
    _advance_floor(scenario, positions)  # warm-up
    floor_runs = [_advance_floor(scenario, positions) for _ in range(repeat)]
    floor_wall = _spread([run.wall_time for run in floor_runs])
    floor_cpu = _spread([run.cpu_time for run in floor_runs])
    floor = floor_runs[0]
    floor_per_evaluation = _per(floor_wall["median"], floor.derivative_evaluations)
    per_evaluation = _per(median, timed.derivative_evaluations)
    progress("one derivative evaluation alone, of the closed loop and of the floor")
    one_evaluation = _time_one_evaluation_of_each(scenario, positions)

    # Logging cost: one run with the other logging setting.
    progress("one run with the other logging setting")
    if scenario.logging.period == 0.0:
        # Loggers that publish once, at t = 0: the cost of the loop without logging.
        variant, variant_period = "none", 2.0 * scenario.duration + 1.0
    else:
        variant, variant_period = "every step", 0.0
    variant_run = _advance_closed_loop(
        dataclasses.replace(scenario, logging=LoggingConfig(period=variant_period))
    )
    current = "every step" if scenario.logging.period == 0.0 else seconds(scenario.logging.period)
    logging = [
        {"logging": current, "wall_time": median, "integrator_steps": timed.steps},
        {
            "logging": variant,
            "wall_time": variant_run.wall_time,
            "integrator_steps": variant_run.steps,
            "relative_to_timed": _per(variant_run.wall_time, median),
        },
    ]

    metrics = warm_up.metrics
    simulator_config = scenario.simulator
    return {
        "scenario": {
            "name": scenario.name,
            "duration": scenario.duration,
            "sensor": scenario.sensor.kind,
            "integration_scheme": simulator_config.integration_scheme,
            "accuracy": simulator_config.accuracy,
            "max_step_size": simulator_config.max_step_size,
            "use_error_control": simulator_config.use_error_control,
            "logging_period": scenario.logging.period,
        },
        "repeat": repeat,
        "closed_loop": {
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
                (run.steps, run.derivative_evaluations)
                == (timed.steps, timed.derivative_evaluations)
                for run in [*runs, profiled]
            ),
            "integrator": timed.statistics,
            "warm_up_wall_time": warm_up.wall_time,
            "peak_force": metrics.get("peak_force"),
            "contact_losses": metrics.get("contact_losses"),
        },
        "python": {
            "callback_calls": total_calls,
            "callbacks_per_derivative_evaluation": _per(
                total_calls, profiled.derivative_evaluations
            ),
            "callbacks_per_step": _per(total_calls, profiled.steps),
            "time_in_callbacks": profiler.top_level_time,
            "fraction_of_wall_time": python_fraction,
            "estimated_time_in_timed_runs": (
                python_fraction * median if python_fraction is not None else None
            ),
            "profiled_wall_time": profiled.wall_time,
            "callbacks": callbacks,
        },
        "floor": {
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
        },
        "ratio_to_floor": _per(median, floor_wall["median"]),
        "per_evaluation_ratio_to_floor": (
            _per(per_evaluation, floor_per_evaluation) if floor_per_evaluation else None
        ),
        # The same ratios in this process's CPU time: on a shared machine, other processes
        # stretch wall times (short runs most), CPU times far less.
        "cpu_ratio_to_floor": _per(cpu["median"], floor_cpu["median"]),
        "cpu_per_evaluation_ratio_to_floor": _per(
            _per(cpu["median"], timed.derivative_evaluations),
            _per(floor_cpu["median"], floor.derivative_evaluations),
        ),
        "one_evaluation": one_evaluation,
        "logging": logging,
        "memory": {
            "peak_rss_mb": _peak_rss_mb(),
            "peak_rss_mb_before": rss_before,
            "python_peak_mb": python_peak / 1024.0**2,
        },
        "environment": _environment(),
    }
