"""The closed loop at its contact equilibrium, linearized with Drake's Linearize.

For a constant desired position in contact the loop has one equilibrium: F = Fr, zero
Cartesian error, the PID integral carrying gravity and the wall force. It is found by
simulating the (noise-free) analysis diagram until it stops moving, then refined by Newton
steps on the state derivative; the linear model is Drake's `Linearize` of the whole diagram
(plant, PID, admittance, wall and sensor filter) there.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Context
from pydrake.systems.primitives import Linearize, LinearSystem

from diagrams.closed_loop import BuildClosedLoop, ClosedLoop, SetInitialConditions
from diagrams.scenario import Scenario, ScenarioError

__all__ = ["Equilibrium", "FindContactEquilibrium", "LinearizeAtEquilibrium", "static_scenario"]


@dataclass
class Equilibrium:
    """A closed-loop equilibrium: the analysis diagram, its context and the residual."""

    loop: ClosedLoop
    context: Context
    residual: float  # max |xdot| at the returned state


def static_scenario(scenario: Scenario) -> Scenario:
    """The scenario with everything that moves frozen: Xd at its centre, a static wall at
    its initial stiffness (no steps), and no noise. The rest is kept."""
    frozen = copy.deepcopy(scenario)
    frozen.trajectory.amplitude = [0.0] * len(frozen.trajectory.amplitude)
    frozen.trajectory.frequency = 0.0
    frozen.wall.stiffness_steps = []
    frozen.wall.velocity = 0.0
    frozen.sensor.noise_std = 0.0
    if frozen.admittance.period > 0 or frozen.pid.period > 0:
        raise ScenarioError(
            "admittance.period, pid.period: the linearization needs the continuous loop (0)"
        )
    return frozen


def FindContactEquilibrium(
    scenario: Scenario, *, settle_time: float = 40.0, tolerance: float = 1e-8
) -> Equilibrium:
    """Settles the frozen scenario in contact and polishes the state with Newton steps.

    Raises:
        ScenarioError: the loop does not settle (unstable or no contact at the end).
    """
    frozen = static_scenario(scenario)
    loop = BuildClosedLoop(frozen, analysis=True)
    simulator = Simulator(loop.diagram)
    ApplySimulatorConfig(frozen.simulator, simulator)
    context = simulator.get_mutable_context()
    SetInitialConditions(loop, context)
    simulator.Initialize()
    simulator.AdvanceTo(settle_time)

    # Newton steps on f(x) = 0 with the Jacobian from Linearize (time is frozen at the end).
    diagram = loop.diagram
    for _ in range(10):
        residual = _residual(diagram, context)
        if residual < tolerance:
            break
        linear = Linearize(diagram, context, equilibrium_check_tolerance=np.inf)
        x = context.get_continuous_state_vector().CopyToVector()
        xdot = diagram.EvalTimeDerivatives(context).CopyToVector()
        step = np.linalg.lstsq(linear.A(), -xdot, rcond=None)[0]
        context.SetContinuousState(x + step)
    residual = _residual(diagram, context)
    force = loop.wall.contact_force_output.Eval(loop.wall.GetMyContextFromRoot(context))[0]
    if not np.isfinite(residual) or residual > 1e-6 or force <= 0:
        raise ScenarioError(
            f"scenario: the loop does not settle in contact (residual {residual:.3g}, "
            f"force {force:.3g} N after {settle_time} s)"
        )
    return Equilibrium(loop=loop, context=context, residual=residual)


def _residual(diagram, context) -> float:
    return float(np.max(np.abs(diagram.EvalTimeDerivatives(context).CopyToVector())))


def LinearizeAtEquilibrium(equilibrium: Equilibrium) -> LinearSystem:
    """Drake's Linearize of the whole closed loop at `equilibrium` (no inputs, no outputs:
    the linear model dx/dt = A (x - x0))."""
    return Linearize(
        equilibrium.loop.diagram,
        equilibrium.context,
        equilibrium_check_tolerance=max(1e-6, 10 * equilibrium.residual),
    )
