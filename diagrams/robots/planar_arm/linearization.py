"""The closed loop at its contact equilibrium, linearized with Drake's Linearize.

For a constant desired position in contact the loop has one equilibrium: F = Fr, zero
Cartesian error, the PID integral carrying gravity and the wall force. It is constructed
from the model and refined by Newton steps on the state derivative; the linear model is
Drake's `Linearize` of the whole diagram (plant, PID, admittance, wall and sensor filter).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context
from pydrake.systems.primitives import Linearize, LinearSystem

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.loop import WALL_NORMAL_AXIS, BuildClosedLoop, ClosedLoop
from admittance.diagrams.robots.planar_arm.safety_layer import SafetyLayer
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

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
    if frozen.sensor.latency > 0:
        raise ScenarioError(
            "sensor.latency: the linearization needs the continuous loop (0); "
            "analysis.sampled_loop models the delay"
        )
    return frozen


def FindContactEquilibrium(scenario: Scenario, *, tolerance: float = 1e-9) -> Equilibrium:
    """The contact equilibrium of the frozen scenario, constructed from the model.

    At equilibrium the tip rests at X = Xd with x moved to Xe + Fr/Ke (eq. 4 with F = Fr),
    v = 0, the Cartesian error is zero so the PID's integral carries the whole wrench
    (J^T Ki z = -tau_gravity + J^T (Fr, 0, 0)), the admittance offset is Xr = x - xd, and
    the sensor's filter holds the voltage of Fr. The state is then polished by Newton steps
    on dx/dt = 0. No simulation is involved, so unstable settings have an equilibrium too.

    Raises:
        ScenarioError: no equilibrium in contact (unreachable pose, or Newton fails).
    """
    frozen = static_scenario(scenario)
    if frozen.controller_kind != "optimal_admittance":
        raise ScenarioError(
            "controller.kind, admittance.enabled: the contact equilibrium is built for the "
            "paper's optimal_admittance (enabled)"
        )
    loop = BuildClosedLoop(frozen, analysis=True)
    plant, diagram = loop.plant, loop.diagram
    context = diagram.CreateDefaultContext()
    diagram.get_input_port(0).FixValue(context, [frozen.force_reference])

    center = np.array(frozen.trajectory.center, dtype=float)
    pose = center.copy()
    pose[WALL_NORMAL_AXIS] = frozen.wall.position + frozen.force_reference / frozen.wall.stiffness
    try:
        q = SolvePlanarInverseKinematics(
            plant,
            frozen.arm.fingertip_frame,
            pose,
            frozen.arm.joint_guess,
            coordinates=PLANAR_COORDINATES,
        )
    except ValueError as error:
        raise ScenarioError(f"trajectory.center: {error}") from None
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))

    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    kinematics = PlanarFrameKinematics(
        plant, frozen.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    kinematics.set_state(plant.GetPositionsAndVelocities(plant_context))
    wall_force = np.zeros(3)
    wall_force[WALL_NORMAL_AXIS] = frozen.force_reference
    wrench = np.linalg.solve(kinematics.jacobian().T, -gravity) + wall_force
    ki = np.asarray(frozen.pid.ki, dtype=float)
    pid_context = loop.pid.GetMyMutableContextFromRoot(context)
    loop.pid.set_integral(pid_context, np.divide(wrench, ki, out=np.zeros(3), where=ki > 0))

    admittance = loop.admittance
    offset = pose[WALL_NORMAL_AXIS] - center[WALL_NORMAL_AXIS]
    if not isinstance(admittance, SafetyLayer):
        admittance_context = admittance.GetMyMutableContextFromRoot(context)
        admittance.set_initial_force_error(admittance_context, [frozen.force_reference])
        admittance.set_integral(
            admittance_context,
            [
                offset / admittance.integral_gain[0]
                + frozen.admittance.alpha * frozen.force_reference
            ],
        )
    if frozen.sensor.kind != "ideal":
        loop.sensor.GetMyMutableContextFromRoot(context).SetContinuousState(
            [loop.sensor.static_output_voltage(frozen.force_reference)]
        )
    if isinstance(admittance, SafetyLayer):
        # The wall pushes the tip along -x with Fr: tau_ext = J^T (-Fr, 0, 0).
        admittance.set_equilibrium(context, offset, -kinematics.jacobian().T @ wall_force)

    residual = _polish(diagram, context, tolerance)
    return Equilibrium(loop=loop, context=context, residual=residual)


def _polish(diagram, context, tolerance: float) -> float:
    """Newton steps on dx/dt = 0 from the constructed state; returns the residual.

    Raises:
        ScenarioError: the steps do not converge.
    """
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
    if not np.isfinite(residual) or residual > 1e-6:
        raise ScenarioError(f"scenario: no contact equilibrium found (residual {residual:.3g})")
    return residual


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
