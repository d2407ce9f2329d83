"""One public builder for every robot: the loop of Fig. 1 for a scenario of any kind.

:func:`BuildLoop` builds the loop that a scenario describes through its robot's record.
Every robot wires its force-controlled points with the same steps (``loop.point``); what a
robot adds is its plant, its contact and its plan.
"""

from __future__ import annotations

from admittance.diagrams.robots.kinds import robot_of

__all__ = ["BuildLoop"]


def BuildLoop(scenario, *, analysis: bool = False):
    """The loop of Fig. 1 for `scenario` (a validated scenario of any kind).

    Args:
        analysis: build for Linearize (no random source, no loggers), where the robot has
            such a build (a ValueError names where its analysis is otherwise).
    """
    return robot_of(scenario).build(scenario, analysis=analysis)
