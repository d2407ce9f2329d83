"""The planar gripper's record: what the rest of the code reaches this robot through."""

from __future__ import annotations

from admittance.diagrams.robots.planar_gripper.compare import grasp_compare_command
from admittance.diagrams.robots.planar_gripper.figures import plot_grasp
from admittance.diagrams.robots.planar_gripper.loop import BuildGrasp
from admittance.diagrams.robots.planar_gripper.replay import write_grasp_meshcat_replay
from admittance.diagrams.robots.planar_gripper.run import grasp_summary, run_grasp
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario, load_grasp_scenario
from admittance.diagrams.robots.planar_gripper.stability_report import grasp_stability
from admittance.diagrams.robots.record import Robot

__all__ = ["ROBOT"]


def _build(scenario: GraspScenario, *, analysis: bool = False):
    """The hand's loop. It has no analysis build: its analysis linearizes the sampled loop
    as it runs (the package's ``analysis``), so asking for one is an error."""
    if analysis:
        raise ValueError("analysis: the gripper's loop is analysed as it runs (its analysis)")
    return BuildGrasp(scenario)


ROBOT = Robot(
    kind="grasp",
    noun="grasp",
    plural="grasps",
    scenario_type=GraspScenario,
    load=load_grasp_scenario,
    build=_build,
    run=run_grasp,
    summary=grasp_summary,
    # The three normal forces against their Fr, and the brick.
    figures={"grasp_forces.png": plot_grasp},
    replay=write_grasp_meshcat_replay,
    commands=("simulate", "diagram", "stability", "grasp-compare"),
    stability=grasp_stability,
    compare=grasp_compare_command,
)
