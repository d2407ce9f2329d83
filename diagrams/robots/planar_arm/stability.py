"""Stability of the optimal admittance loop: eq. 13 symbolically, and the full closed loop.

The paper's proof (Section III-C) is quasi-static: E is a function of Xr through the
impedance model of eq. 5 and the arm, PID and sensor dynamics are ignored. Here:

* `symbolic_eq13` re-derives eq. 12-13 with pydrake.symbolic for the corrected sign of
  eq. 10 (and shows the printed sign makes V grow);
* `modal_summary` and `lyapunov_certificate` read the linearized full loop (Linearize at the
  contact equilibrium, the package's ``linearization``): eigenvalues, time constants, damping,
  and P > 0 from A^T P + P A = -Q (RealContinuousLyapunovEquation);
* `linear_versus_nonlinear` checks the linear model against the nonlinear diagram on a
  small step of Fr;
* `lyapunov_along_trajectory` evaluates V = 1/2 (E + alpha dE/dt)^2 along a simulated run
  and reports where it grows;
* `stability_map`, `critical_gamma` and `sampled_spectral_radius` map where the loop is
  stable over Gamma, Ke, alpha, the sensor filter's cut-off and the sampled block's period;
  `simulate_near_critical` confirms a boundary point on the nonlinear diagram (the
  sampled, delayed loop: diagrams/robots/planar_arm/safety_margins.py).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import (
    ApplySimulatorConfig,
    DiscreteTimeApproximation,
    Simulator,
    SimulatorStatus,
)
from pydrake.systems.framework import DiagramBuilder, EventStatus, InputPortIndex
from pydrake.systems.primitives import Linearize

from admittance.diagrams.analysis.linear import critical_gain
from admittance.diagrams.robots.planar_arm.linearization import (
    FindContactEquilibrium,
    LinearizeAtEquilibrium,
    static_scenario,
)
from admittance.diagrams.robots.planar_arm.loop import WALL_NORMAL_AXIS, BuildClosedLoop
from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.run import SimulationResult
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.robots.planar_arm.validation import validate
from admittance.diagrams.scenario.schema import ScenarioError, scenario_keys
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

__all__ = [
    "StepResponse",
    "critical_gamma",
    "linear_versus_nonlinear",
    "lyapunov_along_trajectory",
    "max_real_part",
    "sampled_spectral_radius",
    "simulate_near_critical",
    "stability_map",
    "with_values",
]


# --- eq. 13, symbolically -----------------------------------------------------------------


# --- modes and the Lyapunov certificate -----------------------------------------------------


# --- scenario variations ---------------------------------------------------------------------


def with_values(scenario: Scenario, values: dict) -> Scenario:
    """A validated copy of `scenario` with dotted keys set (e.g. {"admittance.gamma": 2e-5})."""
    varied = copy.deepcopy(scenario)
    valid = scenario_keys(Scenario)
    for key, value in values.items():
        if key not in valid:
            raise ScenarioError(f"{key}: unknown scenario key")
        node = varied
        *parents, leaf = key.split(".")
        for part in parents:
            node = getattr(node, part)
        setattr(node, leaf, value)
    return validate(varied)


def max_real_part(scenario: Scenario) -> float:
    """Largest real part of the linearized closed loop's eigenvalues at its equilibrium."""
    equilibrium = FindContactEquilibrium(scenario)
    return float(np.max(np.linalg.eigvals(LinearizeAtEquilibrium(equilibrium).A()).real))


def sampled_spectral_radius(scenario: Scenario, period: float) -> float:
    """Spectral radius of the loop with the admittance block sampled at `period` (ZOH).

    The arm, PID, wall and sensor stay continuous; the loop the admittance block closes is
    linearized at the equilibrium with Xr as its input, discretized exactly (zero-order
    hold, Drake's DiscreteTimeApproximation) and closed with the sampled law
    z[k+1] = z[k] + h E[k], Xr[k+1] = Gamma K (z[k] + alpha (E[k] - E0)). < 1 is stable.
    """
    continuous = static_scenario(scenario)
    equilibrium = FindContactEquilibrium(continuous)
    open_loop = BuildClosedLoop(continuous, analysis=True, open_admittance_loop=True)
    context = open_loop.diagram.CreateDefaultContext()
    for system in (open_loop.plant, open_loop.pid, open_loop.sensor):
        if system is None:  # the ideal sensor is a wire
            continue
        source = equilibrium.loop.diagram.GetSubsystemByName(system.get_name())
        state = source.GetMyContextFromRoot(equilibrium.context).get_continuous_state_vector()
        system.GetMyMutableContextFromRoot(context).SetContinuousState(state.CopyToVector())
    offset = equilibrium.loop.admittance.reference_offset_output.Eval(
        equilibrium.loop.admittance.GetMyContextFromRoot(equilibrium.context)
    )
    input_port = open_loop.diagram.GetInputPort("reference_offset")
    input_port.FixValue(context, offset)
    linear = Linearize(
        open_loop.diagram,
        context,
        input_port_index=input_port.get_index(),
        output_port_index=open_loop.diagram.GetOutputPort("measured_force").get_index(),
        equilibrium_check_tolerance=1e-6,
    )
    discrete = DiscreteTimeApproximation(linear, period)
    Ad, Bd, Cd = discrete.A(), discrete.B()[:, [WALL_NORMAL_AXIS]], discrete.C()
    n = Ad.shape[0]
    admittance = equilibrium.loop.admittance
    ki = admittance.integral_gain[0]
    kp = admittance.proportional_gain[0]
    # Drake's discrete update at t_k latches Xr = Gamma K (z[k] + alpha (E[k] - E0)), held
    # over [t_k, t_k+1), and advances z. In deviations, with dE = -C dx (Fr fixed):
    #   dx[k+1] = Ad dx[k] + Bd (ki dz[k] - kp C dx[k]),   dz[k+1] = dz[k] - h C dx[k].
    M = np.zeros((n + 1, n + 1))
    M[:n, :n] = Ad - kp * Bd @ Cd
    M[:n, n:] = ki * Bd
    M[n:, :n] = -period * Cd
    M[n, n] = 1.0
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def stability_map(scenario: Scenario, x_key: str, x_values, y_key: str, y_values) -> np.ndarray:
    """Max real part of the eigenvalues over a grid (rows: y values, columns: x values).

    For `admittance.period` the entry is log(spectral radius) / period of the sampled loop,
    so that the sign means the same thing (< 0 stable) on every map.
    """
    grid = np.full((len(y_values), len(x_values)), np.nan)
    for row, y in enumerate(y_values):
        for column, x in enumerate(x_values):
            values = {x_key: float(x), y_key: float(y)}
            period = values.pop("admittance.period", 0.0)
            try:
                varied = with_values(scenario, values)
                if period > 0:
                    radius = sampled_spectral_radius(varied, period)
                    grid[row, column] = math.log(radius) / period
                else:
                    grid[row, column] = max_real_part(varied)
            except ScenarioError:
                pass  # no equilibrium there: left as NaN and drawn blank
    return grid


def critical_gamma(
    scenario: Scenario, low: float = 1e-7, high: float = 1e-2, *, iterations: int = 40
) -> float | None:
    """The smallest Gamma at which the linearized loop loses stability (log bisection).

    Returns None if the loop is stable up to `high`.
    """

    def matrix(gamma: float) -> np.ndarray:
        varied = with_values(scenario, {"admittance.gamma": gamma})
        return LinearizeAtEquilibrium(FindContactEquilibrium(varied)).A()

    try:
        return critical_gain(matrix, low, high, iterations=iterations)
    except ValueError as error:
        if isinstance(error, ScenarioError):
            raise
        raise ScenarioError(f"admittance.gamma: {error}") from None


# --- the nonlinear diagram ---------------------------------------------------------------------


@dataclass
class StepResponse:
    time: np.ndarray
    nonlinear: np.ndarray  # contact force change, N
    linear: np.ndarray


def linear_versus_nonlinear(
    scenario: Scenario, step: float = 0.1, duration: float = 1.0, samples: int = 201
) -> StepResponse:
    """Response of the contact force to a step of Fr, nonlinear diagram against Linearize.

    Both start at the contact equilibrium; Fr steps by `step` N at t = 0.
    """
    equilibrium = FindContactEquilibrium(scenario)
    diagram, context = equilibrium.loop.diagram, equilibrium.context
    reference = static_scenario(scenario).force_reference
    force_port = diagram.GetOutputPort("contact_force")
    force0 = force_port.Eval(context)[0]
    linear = Linearize(
        diagram,
        context,
        input_port_index=InputPortIndex(0),
        output_port_index=force_port.get_index(),
        equilibrium_check_tolerance=max(1e-6, 10 * equilibrium.residual),
    )
    times = np.linspace(0.0, duration, samples)

    def response(system, system_context, port, offset) -> np.ndarray:
        simulator = Simulator(system, system_context)
        ApplySimulatorConfig(scenario.simulator, simulator)
        simulator.get_mutable_integrator().set_target_accuracy(1e-7)
        start = system_context.get_time()
        values = []
        for t in times:
            simulator.AdvanceTo(start + t)
            values.append(port.Eval(system_context)[0] - offset)
        return np.array(values)

    nonlinear_context = context.Clone()
    diagram.get_input_port(0).FixValue(nonlinear_context, [reference + step])
    nonlinear = response(diagram, nonlinear_context, force_port, force0)
    linear_context = linear.CreateDefaultContext()
    linear.get_input_port().FixValue(linear_context, [step])
    linear_response = response(linear, linear_context, linear.get_output_port(), 0.0)
    return StepResponse(time=times, nonlinear=nonlinear, linear=linear_response)


def simulate_near_critical(scenario: Scenario, gamma: float, duration: float = 2.0) -> dict:
    """Nonlinear run of the frozen scenario at `gamma` from its equilibrium, nudged by a
    0.5 N step of Fr: does the force oscillation die out or grow?

    Returns the force error's peak in the first and the last fifth of the run, or the time
    at which contact was lost (the run stops there: a growing oscillation ends in a
    bouncing contact); `converges` is True when contact held and the last fifth's peak is
    below a tenth of the first's.
    """
    varied = with_values(scenario, {"admittance.gamma": gamma})
    equilibrium = FindContactEquilibrium(varied)
    diagram, context = equilibrium.loop.diagram, equilibrium.context
    reference = static_scenario(varied).force_reference + 0.5
    diagram.get_input_port(0).FixValue(context, [reference])
    simulator = Simulator(diagram, context)
    ApplySimulatorConfig(varied.simulator, simulator)
    port = diagram.GetOutputPort("contact_force")

    def stop_when_contact_is_lost(root_context):
        if port.Eval(root_context)[0] <= 0.0:
            return EventStatus.ReachedTermination(None, "contact lost")
        return EventStatus.Succeeded()

    simulator.set_monitor(stop_when_contact_is_lost)
    times = np.linspace(0.0, duration, 2001)
    forces = []
    start = context.get_time()
    contact_lost_time = None
    for t in times:
        status = simulator.AdvanceTo(start + t)
        forces.append(port.Eval(context)[0])
        if status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition:
            contact_lost_time = context.get_time() - start
            break
    forces = np.array(forces)
    error = np.abs(forces - reference)
    fifth = len(times) // 5
    first = float(np.max(error[:fifth]))
    last = float(np.max(error[-fifth:])) if contact_lost_time is None else math.inf
    return {
        "gamma": gamma,
        "peak_error_first_fifth": first,
        "peak_error_last_fifth": last,
        "contact_lost_time": contact_lost_time,
        "converges": bool(contact_lost_time is None and last < 0.1 * first),
    }


# --- V along a trajectory ---------------------------------------------------------------------


def lyapunov_along_trajectory(result: SimulationResult) -> dict:
    """V(t) = 1/2 (E + alpha dE/dt)^2 along a run, with dE/dt = -dF/dt computed exactly
    from the state (dF/dt = Ke (dx/dt - dXe/dt) while in contact), and where V grows.

    Returns:
        time, V, and the intervals (after first contact) where dV/dt > 0, with the fraction
        of time they cover.
    """
    scenario = result.scenario
    alpha = scenario.admittance.alpha
    plant, _ = AddScenarioArm(DiagramBuilder(), scenario.arm)
    kinematics = PlanarFrameKinematics(
        plant, scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    tip_speed = np.empty(result.time.size)
    for row, (q, v) in enumerate(zip(result.joint_positions, result.joint_velocities, strict=True)):
        kinematics.set_state(np.concatenate([q, v]))
        tip_speed[row] = (kinematics.jacobian() @ v)[WALL_NORMAL_AXIS]
    wall_speed = np.gradient(result.wall_position, result.time)
    in_contact = result.force > 0
    force_rate = np.where(in_contact, result.wall_stiffness * (tip_speed - wall_speed), 0.0)
    error = result.force_reference - result.force
    weighted = error + alpha * (-force_rate)
    V = 0.5 * weighted**2
    dV = np.diff(V) / np.maximum(np.diff(result.time), 1e-12)
    first = result.metrics.get("first_contact_time")
    start = first if first is not None else result.time[-1]
    growing = (dV > 0) & (result.time[1:] > start)
    intervals = []
    index = 0
    while index < growing.size:
        if growing[index]:
            end = index
            while end + 1 < growing.size and growing[end + 1]:
                end += 1
            intervals.append([float(result.time[index]), float(result.time[end + 1])])
            index = end + 1
        else:
            index += 1
    after = result.time[-1] - start
    covered = sum(b - a for a, b in intervals)
    return {
        "time": result.time,
        "V": V,
        "growing_intervals": intervals,
        "growing_fraction": covered / after if after > 0 else 0.0,
        "monotone_after_contact": not intervals,
    }
