"""The planar arm's record: what the rest of the code reaches this robot through."""

from __future__ import annotations

from admittance.diagrams.robots.planar_arm.bench import run_benchmark
from admittance.diagrams.robots.planar_arm.bench_report import (
    format_benchmark,
    load_benchmark_report,
)
from admittance.diagrams.robots.planar_arm.compare import compare_command
from admittance.diagrams.robots.planar_arm.figures import plot_errors, plot_force, plot_reference
from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop, CheckScenarioStarts
from admittance.diagrams.robots.planar_arm.replay import write_meshcat_replay
from admittance.diagrams.robots.planar_arm.run import arm_summary, run_scenario
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.robots.planar_arm.stability_report import arm_stability
from admittance.diagrams.robots.planar_arm.validation import load_arm_scenario
from admittance.diagrams.robots.record import BenchParts, Robot

__all__ = ["ROBOT"]


def _series(result) -> dict:
    """What a sweep or a comparison keeps of a run: the force and the reference offset."""
    return {
        "time": result.time,
        "force": result.force,
        "reference_offset": result.reference_offset[:, 0],
    }


ROBOT = Robot(
    kind="arm",
    noun="arm",
    plural="arms",
    scenario_type=Scenario,
    load=load_arm_scenario,
    build=BuildClosedLoop,
    run=run_scenario,
    summary=arm_summary,
    # The paper's figures of a run, by file name.
    figures={
        "fig5_errors.png": plot_errors,
        "fig6_reference.png": plot_reference,
        "fig7_force.png": plot_force,
    },
    replay=write_meshcat_replay,
    commands=("simulate", "diagram", "stability", "compare", "bench", "sweep"),
    check_start=CheckScenarioStarts,
    stability=arm_stability,
    bench=BenchParts(run=run_benchmark, format=format_benchmark, load_before=load_benchmark_report),
    compare=compare_command,
    series=_series,
)
