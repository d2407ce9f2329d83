"""A real arm's tool on a table in six dimensions: scenario keys, the plant, the loop.

The arms come from example-robot-data (the optional extra ``robots``); without it the tests
that load them are skipped with that reason, and the one-line error naming the extra is
checked on its own.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots import spatial_arm as robots
from admittance.diagrams.robots.spatial_arm import (
    CONTROL_FRAME,
    TOOL_TIP_FRAME,
    AddSpatialArm,
    SolveSpatialInverseKinematics,
    example_robot_data_packages,
)
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.diagrams.scenario.spatial_arm import SpatialScenario, load_spatial_scenario

needs_robots = pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason='example-robot-data is not installed: pip install "optimal-admittance[robots]"',
)

UR5_KEYS = [
    "arm.urdf=package://ur_description/urdf/ur5_robot.urdf",
    "arm.base_frame=base_link",
    "arm.flange_frame=tool0",
    "arm.joint_guess=[0.0, -1.57, 1.57, -1.57, -1.57, 0.0]",
]


def test_spatial_builtins_load_as_spatial_scenarios():
    for name in ("panda_surface_press", "panda_surface_follow", "ur5_surface_follow"):
        scenario = load_scenario(name)
        assert isinstance(scenario, SpatialScenario) and scenario.name == name
        assert scenario.force_reference == 10.0
        assert scenario.trajectory.approach_height == 0.02
    follow = load_scenario("panda_surface_follow")
    # 10 cm at 2 cm/s and back, with 0.5 s blends: 2 (5 s + 0.5 s) of slide.
    assert follow.slide_end - follow.slide_start == pytest.approx(11.0)
    assert follow.duration >= follow.slide_end


@pytest.mark.parametrize(
    "override, message",
    [
        ("surface.tilt_x=45", "surface.tilt_x: must be in [-30, 30] degrees, got 45.0"),
        ("surface.height_error=0.5", "surface.height_error: must be in [-0.02, 0.02] m"),
        ("tool.shape=cube", "tool.shape: must be one of sphere, disc, got 'cube'"),
        ("pid.kp=[1, 2, 3]", "pid.kp: must be 6 values (x, y, z, rx, ry, rz)"),
        ("controller.kind=fixed_reference", "controller.kind: must be one of"),
        ("surface.colour=red", "surface.colour: unknown scenario key"),
        ("arm.urdf=arm.stl", "arm.urdf: must be a .urdf or .sdf file"),
        ("surface.position=[0.5]", "surface.position: must be 2 finite values"),
        ("duration=2", "duration: must be > trajectory.approach_time"),
        ("admittance.max_push=0.001", "admittance.max_push: must be > force_reference"),
    ],
)
def test_bad_spatial_keys_name_the_key(override, message):
    with pytest.raises(ScenarioError) as error:
        load_scenario("panda_surface_follow", [override])
    assert message in str(error.value) and "\n" not in str(error.value)


def test_missing_extra_gives_one_line_naming_it(monkeypatch):
    monkeypatch.setattr(robots, "example_robot_data_packages", lambda: None)
    scenario = load_scenario("panda_surface_press")
    with pytest.raises(ScenarioError) as error:
        AddSpatialArm(DiagramBuilder(), scenario)
    text = str(error.value)
    assert text.startswith("arm.urdf:") and 'pip install "optimal-admittance[robots]"' in text
    assert "\n" not in text


@needs_robots
@pytest.mark.parametrize(
    "override, message",
    [
        ("arm.flange_frame=panda_link99", "arm.flange_frame: the model has no frame named"),
        ("arm.base_frame=nowhere", "arm.base_frame: the model has no frame named 'nowhere'"),
    ],
)
def test_bad_frames_name_the_key(override, message):
    scenario = load_scenario("panda_surface_press", [override])
    with pytest.raises(ScenarioError) as error:
        AddSpatialArm(DiagramBuilder(), scenario)
    assert message in str(error.value) and "\n" not in str(error.value)


@needs_robots
def test_panda_plant_actuators_table_and_control_frame():
    scenario = load_scenario("panda_surface_press", ["surface.height_error=0.003"])
    plant, _, geometry = AddSpatialArm(DiagramBuilder(), scenario)
    # The Panda's URDF has no transmissions: one actuator per arm joint, its effort limit
    # from the URDF's <limit effort> (87 N m on joints 1-4, 12 N m on 5-7, Franka's data
    # sheet); the fingers are welded, so the plant has 7 positions.
    efforts = [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()]
    assert efforts == [87.0] * 4 + [12.0] * 3
    assert plant.num_positions() == 7
    context = plant.CreateDefaultContext()
    X_WE = plant.CalcRelativeTransform(
        context, plant.world_frame(), plant.GetFrameByName(CONTROL_FRAME)
    )
    # E at the planned point, z along the planned inward normal: world -z.
    np.testing.assert_allclose(X_WE.translation(), [0.5, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(X_WE.rotation().matrix()[:, 2], [0.0, 0.0, -1.0], atol=1e-12)
    # The real table's top is 3 mm higher than planned.
    assert geometry.X_WS.translation()[2] == pytest.approx(0.203)


@needs_robots
@pytest.mark.parametrize("keys", [[], UR5_KEYS], ids=["panda", "ur5"])
def test_inverse_kinematics_reaches_the_plan_start(keys):
    scenario = load_scenario("panda_surface_press", keys)
    plant, _, geometry = AddSpatialArm(DiagramBuilder(), scenario)
    target = geometry.X_WE @ RigidTransform([0.0, 0.0, -0.02])
    q = SolveSpatialInverseKinematics(plant, TOOL_TIP_FRAME, target, scenario.arm.joint_guess)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X_WT = plant.CalcRelativeTransform(
        context, plant.world_frame(), plant.GetFrameByName(TOOL_TIP_FRAME)
    )
    # 2 cm above the planned point, the tool pointing down (world -z).
    np.testing.assert_allclose(X_WT.translation(), [0.5, 0.0, 0.22], atol=1e-9)
    np.testing.assert_allclose(X_WT.rotation().matrix()[:, 2], [0.0, 0.0, -1.0], atol=1e-9)


def test_spatial_scenario_defaults_are_consistent():
    scenario = load_spatial_scenario({})
    assert scenario.kind == "spatial" and len(scenario.pid.kp) == 6
    # K of eq. 10 is the PID's stiffness on z: the bound must let the PID push Fr.
    assert scenario.admittance.max_push > scenario.force_reference / scenario.pid.kp[2]
    assert math.isclose(scenario.slide_start, 4.0)
