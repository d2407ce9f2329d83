"""One public run for every robot: a scenario of any kind, simulated headless.

:func:`simulate` runs the scenario through its robot's record (the robot builds its loop
and runs it through the one run path, ``run.engine``) and returns its result: the time
series as plain arrays and the metrics, those every robot shares (``run.metrics``) and the
robot's own additions.
"""

from __future__ import annotations

from collections.abc import Callable

from admittance.diagrams.robots.kinds import robot_of

__all__ = ["simulate"]


def simulate(scenario, *, progress: Callable[[float], None] | None = None):
    """Builds, initializes and simulates `scenario` (any kind); returns its result.

    Raises:
        SimulationDivergedError: the run blew up; the exception carries the partial result.
    """
    return robot_of(scenario).run(scenario, progress=progress)
