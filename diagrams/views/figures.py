"""One plot set and one replay writer for every robot's result.

:func:`result_figures` names the figures of a result (the paper's Fig. 5-7 for the arm,
the forces and the brick for the gripper); :func:`write_replay` writes its Meshcat replay.
Both pick the robot's own drawing by the result's type, so a caller never branches on the
robot.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from admittance.diagrams.run.planar_gripper import GraspResult
from admittance.diagrams.run.spatial_arm import SpatialResult
from admittance.diagrams.views.gripper_plots import plot_grasp
from admittance.diagrams.views.gripper_replay import write_grasp_meshcat_replay
from admittance.diagrams.views.plots import plot_errors, plot_force, plot_reference
from admittance.diagrams.views.replay import write_meshcat_replay
from admittance.diagrams.views.spatial_arm import plot_spatial
from admittance.diagrams.views.spatial_replay import write_spatial_meshcat_replay

__all__ = ["ARM_FIGURES", "GRASP_FIGURES", "SPATIAL_FIGURES", "result_figures", "write_replay"]

# The paper's figures of an arm's run, by file name.
ARM_FIGURES = {
    "fig5_errors.png": plot_errors,
    "fig6_reference.png": plot_reference,
    "fig7_force.png": plot_force,
}
# The grasp's figure: the three normal forces against their Fr, and the brick.
GRASP_FIGURES = {"grasp_forces.png": plot_grasp}
# The spatial arm's figure: the force against Fr, the path and orientation errors.
SPATIAL_FIGURES = {"spatial_force_path.png": plot_spatial}


def result_figures(result) -> dict[str, Callable]:
    """File name -> a function of the result that draws it and returns its axes."""
    if isinstance(result, SpatialResult):
        return SPATIAL_FIGURES
    return GRASP_FIGURES if isinstance(result, GraspResult) else ARM_FIGURES


def write_replay(result, path: str | os.PathLike) -> Path:
    """A self-contained Meshcat HTML replay of `result` (any robot's); returns its path."""
    if isinstance(result, GraspResult):
        return write_grasp_meshcat_replay(result, path)
    if isinstance(result, SpatialResult):
        return write_spatial_meshcat_replay(result, path)
    return write_meshcat_replay(result, path)
