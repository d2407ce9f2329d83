"""The one run path every robot's loop goes through.

:func:`simulate_loop` takes a built loop's diagram and plant, a Drake ``SimulatorConfig``
and the robot's own initial conditions, and advances it to the end of the run (through
optional stops at which the scenario changes the plant, such as the brick's mass step),
watching the plant's state: a non-finite state or a runaway joint speed stops the run
with its reason, and so does a solver failure. :func:`finish_run` then marks the
collected result failed or not, and raises :class:`SimulationDivergedError` carrying it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.framework import Context, Diagram, EventStatus

__all__ = [
    "DIVERGED_JOINT_SPEED",
    "LoopRun",
    "RunResult",
    "SimulationDivergedError",
    "divergence_monitor",
    "finish_run",
    "simulate_loop",
]

# A run whose joint speed exceeds this is diverging (the arm's motors reach a few rad/s,
# the gripper's fingers less).
DIVERGED_JOINT_SPEED = 1e3  # rad/s


@dataclass
class RunResult:
    """What every robot's run returns: its scenario and its logged time series as plain
    arrays (SI units), with its metrics.

    Each robot's result (robots.planar_arm.run's SimulationResult, robots.planar_gripper.run's
    GraspResult) adds its own series and metrics; the result folder, the figures and the
    replay take any of them (a ``columns()`` of the timeseries.csv, ``metrics``,
    ``scenario``).
    """

    scenario: object
    time: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        """The timeseries.csv columns, in order (``time`` first)."""
        raise NotImplementedError


class SimulationDivergedError(RuntimeError):
    """The simulation blew up; `result` holds what was logged until then (failed=True)."""

    def __init__(self, message: str, result) -> None:
        super().__init__(message)
        self.result = result


def divergence_monitor(plant, found: list, progress: Callable[[float], None] | None = None):
    """A Simulator monitor that stops at the first non-finite or runaway state of `plant`,
    and tells `progress` the simulated time after each step."""
    num_positions = plant.num_positions()

    def monitor(root_context):
        if progress is not None:
            progress(root_context.get_time())
        state = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(root_context))
        if not np.all(np.isfinite(state)):
            found.append(f"the plant state is not finite at t = {root_context.get_time():.6g} s")
        elif np.max(np.abs(state[num_positions:])) > DIVERGED_JOINT_SPEED:
            found.append(
                f"a joint speed exceeds {DIVERGED_JOINT_SPEED:g} rad/s at "
                f"t = {root_context.get_time():.6g} s"
            )
        else:
            return EventStatus.Succeeded()
        return EventStatus.ReachedTermination(None, found[-1])

    return monitor


@dataclass
class LoopRun:
    """A finished (or stopped) run: its simulator, its wall-clock time and why it stopped."""

    simulator: Simulator
    wall_time: float
    # The reasons the run stopped early (empty: it reached the end).
    divergence: list[str] = field(default_factory=list)

    @property
    def context(self) -> Context:
        return self.simulator.get_context()


def simulate_loop(
    diagram: Diagram,
    plant,
    config: SimulatorConfig,
    duration: float,
    *,
    initialize: Callable[[Context], None],
    configure: Callable[[Simulator], None] | None = None,
    initialized: Callable[[Context], None] | None = None,
    stops: Sequence[tuple[float, Callable[[Context], None]]] = (),
    progress: Callable[[float], None] | None = None,
    solver: str = "integrator",
) -> LoopRun:
    """Simulates a built loop from the robot's initial conditions to `duration`.

    Args:
        initialize: sets the robot's initial state (and checks that the run can start) in
            the simulator's context, before the simulator is initialized.
        configure: further settings of the simulator, after `config` is applied.
        initialized: called with the context once the simulator is initialized (to read
            what the initialization events set).
        stops: (time, action) pairs, in time order: the run stops at each time and the
            action changes the context (a disturbance of the plant's parameters).
        progress: called with the simulated time (s) after every step.
        solver: what a RuntimeError of the simulator is called in the reason ("the
            integrator failed at ..." for a continuous plant).

    Returns:
        The run; `divergence` is empty if it reached `duration`.
    """
    simulator = Simulator(diagram)
    ApplySimulatorConfig(config, simulator)
    if configure is not None:
        configure(simulator)
    context = simulator.get_mutable_context()
    initialize(context)
    divergence: list[str] = []
    simulator.set_monitor(divergence_monitor(plant, divergence, progress))
    simulator.Initialize()
    if initialized is not None:
        initialized(context)
    start = time.perf_counter()
    try:
        for stop, action in [*stops, (duration, None)]:
            simulator.AdvanceTo(stop)
            if divergence:
                break
            if action is not None:
                action(context)
    except RuntimeError as error:  # e.g. the integrator cannot reach the accuracy
        divergence.append(
            f"the {solver} failed at t = {context.get_time():.6g} s: {str(error).splitlines()[0]}"
        )
    return LoopRun(simulator, time.perf_counter() - start, divergence)


def finish_run(result, divergence: list[str]):
    """`result` marked failed or not in its metrics; raises SimulationDivergedError with it
    if `divergence` holds a reason (the last one is reported)."""
    if divergence:
        result.metrics["failed"] = True
        result.metrics["failure"] = divergence[-1]
        raise SimulationDivergedError(f"simulation diverged: {divergence[-1]}", result)
    result.metrics["failed"] = False
    return result
