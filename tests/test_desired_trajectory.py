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
    # The float helpers (the run's initial pose and speed) say the same.
    np.testing.assert_allclose(trajectory.position_at(time), expected, atol=1e-15)
    np.testing.assert_allclose(trajectory.velocity_at(time), rate, atol=1e-15)


def test_bad_frequency():
    with pytest.raises(ValueError, match="frequency"):
        DesiredTrajectory(center=[0, 0, 0], frequency=-1.0)


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(center=[0.2, math.nan, 0.0]), "center and amplitude must be finite"),
        (dict(center=[0.2, 0.0, 0.0], amplitude=[0.0, math.inf, 0.0]), "must be finite"),
        (dict(center=[0.2, 0.0, 0.0], frequency=math.inf), "frequency must be >= 0 Hz"),
    ],
)
def test_bad_center_amplitude_or_frequency(arguments, message):
    with pytest.raises(ValueError, match=message):
        DesiredTrajectory(**arguments)


@pytest.mark.parametrize("extra", [{}, dict(frequency=0.5), dict(amplitude=[0.0, 0.025, 0.0])])
def test_without_an_amplitude_or_a_frequency_the_trajectory_holds_its_center(extra):
    """The defaults (no amplitude, 0 Hz), a frequency alone or an amplitude alone: Xd =
    center, at rest, at any time; the arguments are keyword-only."""
    trajectory = DesiredTrajectory(center=[0.2, -0.25, 1.0], **extra)
    context = trajectory.CreateDefaultContext()
    context.SetTime(0.3)
    assert list(trajectory.desired_position_output.Eval(context)) == [0.2, -0.25, 1.0]
    assert list(trajectory.desired_velocity_output.Eval(context)) == [0.0, 0.0, 0.0]
    assert list(trajectory.position_at(0.3)) == [0.2, -0.25, 1.0]
    assert list(trajectory.velocity_at(0.3)) == [0.0, 0.0, 0.0]
    with pytest.raises(TypeError):
        DesiredTrajectory([0.2, -0.25, 1.0])
