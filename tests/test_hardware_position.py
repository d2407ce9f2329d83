"""Position mode's inverse-kinematics step (the spatial arm's ``joint_command``): it reaches a
commanded pose, keeps the joints inside their limits, and the tool stiffness of a joint
stiffness by hand."""

from __future__ import annotations

import numpy as np
import pytest

from admittance.diagrams.hardware.config import load_hardware_config, scenario_of
from admittance.diagrams.robots.spatial_arm.control_law import SpatialControlLaw
from admittance.diagrams.robots.spatial_arm.joint_command import LIMIT_MARGIN, tool_stiffness
from admittance.diagrams.robots.spatial_arm.plant import example_robot_data_packages

pytestmark = pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason='example-robot-data is not installed: pip install "optimal-admittance[robots]"',
)


def _ik():
    config = load_hardware_config("panda_surface_press", ["mode=position"])
    law = SpatialControlLaw(
        scenario_of(config),
        joint_gains=lambda plant, q: {"joint_stiffness": [600.0] * 7, "joint_damping": [40.0] * 7},
    )
    law.ik.reset(law.initial_positions)
    return law


def test_the_step_reaches_a_pose_1_cm_deeper_and_keeps_the_orientation():
    """The tool tip commanded 1 cm along the control frame's z: a Newton step per sample
    converges (the error after 10 samples below 1 um); the pose read back from the
    plant's forward kinematics at the commanded joints, rotation unchanged."""
    law = _ik()
    start, _ = law.ik.pose_and_jacobian(law.initial_positions)
    target = start + np.array([0.0, 0.0, 0.01, 0.0, 0.0, 0.0])
    for _ in range(10):
        q = law.ik.step(target)
    reached, _ = law.ik.pose_and_jacobian(q)
    np.testing.assert_allclose(reached, target, atol=1e-6)


def test_the_step_keeps_the_joints_inside_their_limits():
    """A pose 2 m away, out of reach: the commanded joints stay within the limits less the
    margin, however many samples."""
    law = _ik()
    start, _ = law.ik.pose_and_jacobian(law.initial_positions)
    plant = law.plant
    low, high = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    for _ in range(200):
        q = law.ik.step(start + np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        assert np.all(q >= low + LIMIT_MARGIN - 1e-12) and np.all(q <= high - LIMIT_MARGIN + 1e-12)


def test_the_tool_stiffness_of_equal_joint_stiffnesses_by_hand():
    """K_q = k I: (J K_q^-1 J^T)_zz = |J_z|^2 / k, so K = k / |J_z|^2; a joint twice as
    stiff as the others takes its share of the compliance halved."""
    row = np.array([0.0, 0.5, 0.0, 0.3, 0.0, 0.1, 0.0])
    jacobian = np.zeros((6, 7))
    jacobian[2] = row
    assert tool_stiffness(jacobian, [600.0] * 7) == pytest.approx(600.0 / 0.35)
    stiffer = [600.0, 1200.0, 600.0, 600.0, 600.0, 600.0, 600.0]
    assert tool_stiffness(jacobian, stiffer) == pytest.approx(1.0 / (0.125 / 600 + 0.1 / 600))
