"""One public builder for every robot: the loop of Fig. 1 for a scenario of any kind.

:func:`BuildLoop` builds the loop that a scenario describes, whatever its robot: the
paper's planar arm against its wall (``loop.planar_arm``), Drake's planar gripper holding
its brick (``loop.planar_gripper``) or a real arm's tool on a table (``loop.spatial_arm``).
All wire their force-controlled points with the same steps (``loop.point``); what a robot
adds is its plant, its contact and its plan.
"""

from __future__ import annotations

from admittance.diagrams.loop.planar_arm import BuildClosedLoop, ClosedLoop
from admittance.diagrams.loop.planar_gripper import BuildGrasp, GraspLoop
from admittance.diagrams.loop.spatial_arm import BuildSpatialLoop, SpatialLoop
from admittance.diagrams.scenario.planar_gripper import GraspScenario
from admittance.diagrams.scenario.spatial_arm import SpatialScenario

__all__ = ["BuildLoop"]


def BuildLoop(scenario, *, analysis: bool = False) -> ClosedLoop | GraspLoop | SpatialLoop:
    """The loop of Fig. 1 for `scenario` (a validated scenario of any kind).

    Args:
        analysis: build for Linearize (no random source, no loggers; see the arm's
            builder). The gripper's loop has none: its analysis linearizes the sampled loop
            as it runs (analysis.planar_gripper), so asking for one is an error.
    """
    if isinstance(scenario, GraspScenario):
        if analysis:
            raise ValueError(
                "analysis: the gripper's loop is analysed as it runs (analysis.planar_gripper)"
            )
        return BuildGrasp(scenario)
    if isinstance(scenario, SpatialScenario):
        if analysis:
            raise ValueError("analysis: the spatial arm's loop has no analysis diagram yet")
        return BuildSpatialLoop(scenario)
    return BuildClosedLoop(scenario, analysis=analysis)
