"""The spatial arm's analysis: one discrete step's cost against the bare plant's, and the
reduced model along the normal (eigenvalues, Lyapunov certificate, critical Gamma)."""

from __future__ import annotations

import math

import pytest

from admittance.diagrams.app.spatial_bench import run_spatial_benchmark
from admittance.diagrams.robots.spatial_arm import example_robot_data_packages
from admittance.diagrams.scenario.files import load_scenario

needs_robots = pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason="needs the robots extra (example-robot-data)",
)


@needs_robots
def test_bench_of_the_panda_press_times_the_loop_against_its_floor():
    """One step of the loop costs more than one of the bare plant (the loop steps the same
    plant and runs its controllers besides), and the floor really stepped in contact."""
    report = run_spatial_benchmark(load_scenario("panda_surface_press"), repeat=1)
    contact = report["in_contact"]
    assert math.isfinite(contact["ratio"]) and contact["ratio"] > 1.0
    # The pressed state: the loop holds Fr = 10 N (measured 10.00 N; 2 % margin).
    assert contact["force"] == pytest.approx(10.0, rel=0.02)
    # Every Python calc of the loop runs once per step (the sampled systems at time_step).
    assert all(
        entry["calls_per_step"] == pytest.approx(1.0, abs=0.01)
        for entry in report["python"]["callbacks"]
    )
