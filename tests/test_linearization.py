"""Drake's Linearize on the whole closed loop, at its contact equilibrium."""

from __future__ import annotations

import numpy as np
import pytest

from admittance.diagrams.robots.planar_arm.linearization import (
    FindContactEquilibrium,
    LinearizeAtEquilibrium,
)
from admittance.diagrams.scenario.files import load_scenario


def _linearize(*overrides):
    scenario = load_scenario("paper_stiffness_step", list(overrides))
    equilibrium = FindContactEquilibrium(scenario)
    return scenario, equilibrium, LinearizeAtEquilibrium(equilibrium)


def test_equilibrium_is_force_tracking_and_stable():
    scenario, equilibrium, linear = _linearize("sensor.kind=ideal")
    loop, context = equilibrium.loop, equilibrium.context
    force = loop.wall.contact_force_output.Eval(loop.wall.GetMyContextFromRoot(context))[0]
    assert force == pytest.approx(scenario.force_reference, abs=1e-6)
    # Plant (6) + PID integral (3) + admittance integral (1); the ideal sensor has no state.
    assert linear.A().shape == (10, 10)
    eigenvalues = np.linalg.eigvals(linear.A())
    assert np.max(eigenvalues.real) < -0.05  # the slowest mode: the PID integral, Ki/Kp
    # The Cartesian error is zero: the PID's integral carries the wrench.
    pid_context = loop.pid.GetMyContextFromRoot(context)
    error = loop.pid.cartesian_error(pid_context)
    np.testing.assert_allclose(error, 0.0, atol=1e-9)


@pytest.mark.parametrize("cutoff, stable", [(5000.0, True), (1000.0, False)])
def test_sensor_filter_cutoff_decides_stability_on_the_stiff_wall(cutoff, stable):
    """The paper's gains on Ke = 1e5 N/m need the sensor's filter above ~2.1 kHz."""
    overrides = ["sensor.kind=flexiforce", "wall.stiffness=1e5", f"sensor.filter_cutoff={cutoff}"]
    _, equilibrium, linear = _linearize(*overrides)
    assert linear.A().shape == (11, 11)  # + the sensor's filter state
    assert (np.max(np.linalg.eigvals(linear.A()).real) < 0) == stable
