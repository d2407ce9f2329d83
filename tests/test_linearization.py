"""Drake's Linearize on the whole closed loop, at its contact equilibrium."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.primitives import Linearize

from diagrams.closed_loop import BuildClosedLoop
from diagrams.linearization import (
    FindContactEquilibrium,
    LinearizeAtEquilibrium,
    static_scenario,
)
from diagrams.scenario import load_scenario


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


@pytest.mark.parametrize("cutoff, stable", [(5000.0, True), (1000.0, False)])
def test_sensor_filter_cutoff_decides_stability_on_the_stiff_wall(cutoff, stable):
    """The paper's gains on Ke = 1e5 N/m need the sensor's filter above ~2.1 kHz."""
    overrides = ["sensor.kind=flexiforce", "wall.stiffness=1e5", f"sensor.filter_cutoff={cutoff}"]
    if not stable:
        # Settle with a fast filter (same equilibrium), then linearize with the slow one.
        _, equilibrium, _ = _linearize(*overrides[:-1], "sensor.filter_cutoff=5000")
        scenario = load_scenario("paper_stiffness_step", overrides)
        loop = BuildClosedLoop(static_scenario(scenario), analysis=True)
        context = loop.diagram.CreateDefaultContext()
        context.SetTimeStateAndParametersFrom(equilibrium.context)
        linear = Linearize(loop.diagram, context, equilibrium_check_tolerance=1e-6)
    else:
        _, equilibrium, linear = _linearize(*overrides)
        assert linear.A().shape == (11, 11)  # + the sensor's filter state
    assert (np.max(np.linalg.eigvals(linear.A()).real) < 0) == stable
