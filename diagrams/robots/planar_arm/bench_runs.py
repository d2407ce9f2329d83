"""The runs a benchmark times: the closed loop's AdvanceTo alone, its profiling run, the
floor (the bare arm held by constant gravity torques) and one derivative evaluation of each.

What they measure and how :mod:`.bench`'s ``run_benchmark`` reads them is told there.
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from collections.abc import Callable

import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop, SetInitialConditions
from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.run.profiling import (
    CallbackProfiler,
    named_subsystems,
    python_system_classes,
)

__all__ = [
    "TimedRun",
    "advance",
    "advance_closed_loop",
    "advance_floor",
    "initial_positions",
    "profile_callbacks",
    "spread",
    "time_one_evaluation_of_each",
]

# Rounds and evaluations per round of the single-evaluation timing.
_EVALUATION_ROUNDS = 25
_EVALUATIONS_PER_ROUND = 200


# --- timing helpers ---------------------------------------------------------------------


def spread(samples: list[float]) -> dict:
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
class TimedRun:
    """One simulated run: AdvanceTo's wall time and the integrator's statistics."""

    wall_time: float
    cpu_time: float  # this process's CPU time over the same AdvanceTo, s
    steps: int
    derivative_evaluations: int
    statistics: dict
    final_positions: np.ndarray | None = None


def advance(
    diagram: Diagram,
    scenario: Scenario,
    initialize: Callable[[Context], None],
    plant=None,
) -> TimedRun:
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
    return TimedRun(
        wall_time=wall_time,
        cpu_time=cpu_time,
        steps=int(integrator.get_num_steps_taken()),
        derivative_evaluations=int(integrator.get_num_derivative_evaluations()),
        statistics=_integrator_statistics(simulator),
        final_positions=final_positions,
    )


def advance_closed_loop(scenario: Scenario) -> TimedRun:
    loop = BuildClosedLoop(scenario)
    return advance(loop.diagram, scenario, lambda context: SetInitialConditions(loop, context))


# --- Python callbacks -------------------------------------------------------------------


def profile_callbacks(scenario: Scenario) -> tuple[TimedRun, CallbackProfiler, dict[int, str]]:
    """One closed-loop run with every Python calc counted and timed."""
    classes = python_system_classes(BuildClosedLoop(scenario).diagram)
    profiler = CallbackProfiler()
    profiler.patch(classes)
    try:
        loop = BuildClosedLoop(scenario)
        names = {id(system): name for name, system in named_subsystems(loop.diagram)}
        run = advance(loop.diagram, scenario, lambda context: SetInitialConditions(loop, context))
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


def time_one_evaluation_of_each(scenario: Scenario, positions: np.ndarray) -> dict:
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


def initial_positions(scenario: Scenario) -> np.ndarray:
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


def advance_floor(scenario: Scenario, positions: np.ndarray) -> TimedRun:
    diagram, plant = _build_floor(scenario, positions)

    def initialize(context: Context) -> None:
        plant_context = plant.GetMyMutableContextFromRoot(context)
        plant.SetPositions(plant_context, positions)
        plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    return advance(diagram, scenario, initialize, plant)
