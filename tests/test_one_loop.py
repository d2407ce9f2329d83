"""One loop for every robot: every built-in scenario through the same public builder, the
same wiring at every force-controlled point, the same run path and the same metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.loop.build import BuildLoop
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.planar_arm.plant import fingertip_point
from admittance.diagrams.robots.planar_gripper.plant import finger_points
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario
from admittance.diagrams.robots.spatial_arm.plant import example_robot_data_packages, spatial_point
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.run.metrics import (
    CONTACT_FRACTION,
    SETTLE_BAND,
    STEADY_WINDOW,
    contact_loss_indices,
    final_window,
    first_contact_time,
    in_contact,
    settled_from,
    settling_time,
    time_mean,
)
from admittance.diagrams.scenario.files import builtin_scenario_names, load_scenario

# The systems that the shared steps of loop.point add at every point, whatever the robot.
SHARED_ROLES = ("fingertip_kinematics", "cartesian_pid")


def _points(scenario, loop) -> list[ForcePoint]:
    if isinstance(scenario, GraspScenario):
        return finger_points(scenario)
    if isinstance(scenario, SpatialScenario):
        return [spatial_point(scenario, loop.plant, loop.initial_positions)]
    return [fingertip_point(scenario)]


@pytest.mark.parametrize("name", builtin_scenario_names())
def test_every_builtin_scenario_builds_through_the_one_builder(name):
    """Each point of the robot's description gets its kinematics, its PID, its sensor
    chain and its force law from the same steps, named after the point."""
    scenario = load_scenario(name)
    if isinstance(scenario, SpatialScenario) and example_robot_data_packages() is None:
        pytest.skip('example-robot-data is not installed: pip install "optimal-admittance[robots]"')
    loop = BuildLoop(scenario)
    names = {loop.diagram.GetSystems()[i].get_name() for i in range(len(loop.diagram.GetSystems()))}
    points = _points(scenario, loop)
    assert len(points) == (3 if isinstance(scenario, GraspScenario) else 1)
    for point in points:
        for role in SHARED_ROLES:
            assert point.system_name(role) in names, (name, point.name, role)
        if point.sensor.kind == "flexiforce":
            assert point.system_name("flexiforce_sensor") in names
        layer = getattr(getattr(scenario, "safety", None), "enabled", False)
        if point.law.kind != "pid_only" and not layer:
            assert point.system_name(point.law.kind) in names
    # One actuation input: every point's PID drives the one plant.
    assert loop.plant.get_actuation_input_port().size() == loop.plant.num_actuated_dofs()


def test_a_point_describes_the_paper_arm_and_each_finger_alike():
    arm = fingertip_point(load_scenario("paper_stiffness_step"))
    assert (arm.coordinates, arm.expressed_in, arm.force_axes) == (
        ("x", "y", "theta"),
        "world",
        (0,),
    )
    # K of eq. 10 is the PID's stiffness on the force axis.
    assert arm.stiffness == load_scenario("paper_stiffness_step").pid.kp[0]
    fingers = finger_points(load_scenario("grasp_hold"))
    assert [f.name for f in fingers] == ["finger1", "finger2", "finger3"]
    for finger in fingers:
        assert finger.coordinates == ("x", "y") and finger.force_axes == (0,)
        assert finger.expressed_in.startswith(finger.name)
        # The sampled hand: the sensor, the law and the PID at the plant's time step.
        assert finger.sensor.period == finger.law.period == finger.pid_period == 0.001


def test_settling_is_measured_alike_for_every_robot():
    """By hand: Fr = 1 N, the band is +-SETTLE_BAND N; samples every 0.1 s."""
    time = np.round(np.arange(0.0, 1.01, 0.1), 10)
    force = np.array([0.0, 0.5, 0.9, 1.2, 0.96, 1.02, 1.0, 1.0, 0.99, 1.01, 1.0])
    assert SETTLE_BAND == 0.05
    # The last sample outside the band is 1.2 at 0.3 s (0.96 is inside): settled at 0.4 s.
    assert settled_from(time, force, 1.0, 0.0) == pytest.approx(0.4)
    assert settling_time(time, force, 1.0, 0.2, math.inf) == pytest.approx(0.2)
    # From 0.4 s on it never leaves the band: settled from the start of the look.
    assert settled_from(time, force, 1.0, 0.4) == 0.4
    # Outside at the end: not settled.
    assert settled_from(time, np.where(time > 0.95, 2.0, force), 1.0, 0.0) is None
    # The look ends before `end` (exclusive), as a disturbance ends the hold: still
    # outside at 0.2 s when the look ends at 0.3 s; settled at 0.4 s when it ends at 0.95 s.
    assert settled_from(time, force, 1.0, 0.0, 0.3) is None
    assert settled_from(time, force, 1.0, 0.0, 0.95) == pytest.approx(0.4)
    # Trapezoid mean of a ramp 0..1 over 1 s is 0.5.
    assert time_mean(time, time) == pytest.approx(0.5)


def test_contact_is_counted_alike_for_every_robot():
    """By hand: Fr = 2 N, so contact is a force above CONTACT_FRACTION * 2 N = 0.02 N."""
    assert CONTACT_FRACTION == 0.01
    time = np.arange(8) * 0.5
    force = np.array([0.0, 0.01, 0.5, 2.0, 0.015, 1.0, 0.0, 2.0])
    contact = in_contact(force, 2.0)
    assert contact.tolist() == [False, False, True, True, False, True, False, True]
    assert first_contact_time(time, contact) == 1.0
    assert first_contact_time(time, np.zeros(8, dtype=bool)) is None
    # Lost after 1.5 s (index 3) and after 2.5 s (index 5).
    assert contact_loss_indices(contact).tolist() == [3, 5]
    # The last STEADY_WINDOW (1 s) of a 3.5 s run: 2.5, 3.0 and 3.5 s.
    assert STEADY_WINDOW == 1.0
    assert time[final_window(time)].tolist() == [2.5, 3.0, 3.5]
