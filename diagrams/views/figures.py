"""The figures and the replay of any robot's result: its robot's own (its record's).

:func:`result_figures` names the figures of a result (the paper's Fig. 5-7 for the planar
arm, the forces and the brick for the gripper, ...); :func:`write_replay` writes its
Meshcat replay. A caller never branches on the robot.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from admittance.diagrams.robots.kinds import robot_of

__all__ = ["result_figures", "write_replay"]


def result_figures(result) -> dict[str, Callable]:
    """File name -> a function of the result that draws it and returns its axes."""
    return dict(robot_of(result).figures)


def write_replay(result, path: str | os.PathLike) -> Path:
    """A self-contained Meshcat HTML replay of `result` (any robot's); returns its path."""
    return robot_of(result).replay(result, path)
