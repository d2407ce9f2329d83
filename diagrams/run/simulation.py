"""One public run for every robot: a scenario of any kind, simulated headless.

:func:`simulate` builds the scenario's loop (``loop.BuildLoop``), runs it through the one
run path (``run.engine``) and returns its result: the time series as plain arrays and the
metrics, those every robot shares (``run.metrics``) and the robot's own additions (the
brick's displacement and each finger's slip for the gripper, the force, path and orientation
over the slide for a spatial arm).
"""

from __future__ import annotations

from collections.abc import Callable

from admittance.diagrams.run.planar_arm import SimulationResult, run_scenario
from admittance.diagrams.run.planar_gripper import GraspResult, run_grasp
from admittance.diagrams.run.spatial_arm import SpatialResult, run_spatial
from admittance.diagrams.scenario.planar_gripper import GraspScenario
from admittance.diagrams.scenario.spatial_arm import SpatialScenario

__all__ = ["simulate"]


def simulate(
    scenario, *, progress: Callable[[float], None] | None = None
) -> SimulationResult | GraspResult | SpatialResult:
    """Builds, initializes and simulates `scenario` (any kind); returns its result.

    Raises:
        SimulationDivergedError: the run blew up; the exception carries the partial result.
    """
    if isinstance(scenario, GraspScenario):
        return run_grasp(scenario, progress=progress)
    if isinstance(scenario, SpatialScenario):
        return run_spatial(scenario, progress=progress)
    return run_scenario(scenario, progress=progress)
