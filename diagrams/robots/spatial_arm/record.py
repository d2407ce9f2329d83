"""The spatial arm's record: what the rest of the code reaches this robot through."""

from __future__ import annotations

from admittance.diagrams.robots.record import BenchParts, HardwareParts, Robot
from admittance.diagrams.robots.spatial_arm.bench import (
    format_spatial_benchmark,
    run_spatial_benchmark,
)
from admittance.diagrams.robots.spatial_arm.control_law import SpatialControlLaw, start_positions
from admittance.diagrams.robots.spatial_arm.figures import plot_spatial
from admittance.diagrams.robots.spatial_arm.loop import BuildSpatialLoop
from admittance.diagrams.robots.spatial_arm.plant import (
    CONTROL_FRAME,
    NORMAL_AXIS,
    TOOL_BODY,
    TOOL_TIP_FRAME,
    AddSpatialArm,
    spatial_point,
)
from admittance.diagrams.robots.spatial_arm.replay import write_spatial_meshcat_replay
from admittance.diagrams.robots.spatial_arm.run import run_spatial, spatial_summary
from admittance.diagrams.robots.spatial_arm.scenario import SpatialArmConfig, SpatialScenario
from admittance.diagrams.robots.spatial_arm.stability_report import spatial_stability
from admittance.diagrams.robots.spatial_arm.validation import load_spatial_scenario

__all__ = ["ROBOT"]


def _build(scenario: SpatialScenario, *, analysis: bool = False):
    """The arm's loop. Its analysis differentiates the loop as it runs (the package's
    ``step_map``): there is no separate analysis build."""
    if analysis:
        raise ValueError("analysis: the spatial arm's loop has no analysis diagram yet")
    return BuildSpatialLoop(scenario)


def _format_bench(report: dict, before: dict | None) -> str:
    return format_spatial_benchmark(report)


ROBOT = Robot(
    kind="spatial",
    noun="spatial-arm",
    plural="spatial arms",
    scenario_type=SpatialScenario,
    load=load_spatial_scenario,
    build=_build,
    run=run_spatial,
    summary=spatial_summary,
    # The force against Fr, the path and orientation errors.
    figures={"spatial_force_path.png": plot_spatial},
    replay=write_spatial_meshcat_replay,
    commands=("simulate", "diagram", "stability", "bench", "station", "control"),
    stability=spatial_stability,
    bench=BenchParts(run=run_spatial_benchmark, format=_format_bench),
    hardware=HardwareParts(
        control_law=SpatialControlLaw,
        start_positions=start_positions,
        add_plant=AddSpatialArm,
        point=spatial_point,
        # The Panda's posture above the table (the scenario's default joint guess).
        home_positions=tuple(SpatialArmConfig().joint_guess),
        tool_body=TOOL_BODY,
        tip_frame=TOOL_TIP_FRAME,
        control_frame=CONTROL_FRAME,
        normal_axis=NORMAL_AXIS,
    ),
)
