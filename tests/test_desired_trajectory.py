"""The desired trajectory of eq. 19 and its time derivative."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.systems.desired_trajectory import DesiredTrajectory


@pytest.mark.parametrize("time", [0.0, 1.3, 2.5, 7.0])
def test_eq_19(time):
    trajectory = DesiredTrajectory(
        center=[0.2, -0.25, math.pi / 2], amplitude=[0.0, 0.025, 0.0], frequency=0.1
    )
    context = trajectory.CreateDefaultContext()
    context.SetTime(time)
    expected = [0.2, 0.025 * math.sin(0.2 * math.pi * time) - 0.25, math.pi / 2]
    np.testing.assert_allclose(
        trajectory.desired_position_output.Eval(context), expected, atol=1e-15
    )
    rate = [0.0, 0.025 * 0.2 * math.pi * math.cos(0.2 * math.pi * time), 0.0]
    np.testing.assert_allclose(trajectory.desired_velocity_output.Eval(context), rate, atol=1e-15)


def test_bad_frequency():
    with pytest.raises(ValueError, match="frequency"):
        DesiredTrajectory(center=[0, 0, 0], frequency=-1.0)
