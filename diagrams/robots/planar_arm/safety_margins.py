"""The stability analysis of the safety layer: its map over Ke against the paper's law's,
confirmed by nonlinear simulation at the map's edges; and the margins of the loop a 1 kHz
controller runs.

`sampled_margins` and `sampled_stability_map` read the loop with the PID, the law and the
layer in one tick of h = admittance.period and the reading `sensor.latency` late, from
the discrete-time reduced model of systems/sampled_loop.py (Linearize cannot take a
sampled loop whole): its critical Gamma, the Gamma the layer schedules, and the latency
tolerable at that Gamma. `resolving_step` says which integrator step a nonlinear run
needs to show the loop's fastest mode.

With the layer on, the Gamma of the map is the user's: the layer runs with
Gamma_s = min(Gamma, Gamma*(k_hat) / margin), the estimate frozen at the equilibrium's
(docs/evidence/safety.md). Each edge run starts at the contact equilibrium of the nonlinear diagram
(arm, PID, wall, sensor filter, the layer) and steps Fr by 0.5 N
(stability.simulate_near_critical): it is stable when contact holds and the force error's
peak over the last fifth of the run is below its peak over the first fifth.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from admittance.diagrams.robots.planar_arm.linearization import FindContactEquilibrium
from admittance.diagrams.robots.planar_arm.loop import WALL_NORMAL_AXIS
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.robots.planar_arm.stability import simulate_near_critical, with_values
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems import contact_model
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics
from admittance.systems.sampled_loop import SampledContactLoop

__all__ = [
    "MARGIN_STIFFNESSES",
    "continuous_counterpart",
    "edge_confirmations",
    "is_sampled",
    "resolving_step",
    "sampled_margins",
    "sampled_stability_map",
    "unstable_points",
]


def unstable_points(grid: np.ndarray) -> int:
    """How many points of a stability map have max Re(eig) >= 0 (NaN: no equilibrium)."""
    return int(np.sum(np.nan_to_num(grid, nan=-1.0) >= 0))


def edge_confirmations(
    scenario: Scenario, stiffness: tuple[float, float], gamma: tuple[float, float]
) -> list[dict]:
    """Nonlinear runs at the corners (Ke, Gamma) of a map, with the scenario's layer."""
    runs = []
    for ke, g in itertools.product(stiffness, gamma):
        run = simulate_near_critical(with_values(scenario, {"wall.stiffness": float(ke)}), g)
        run["stiffness"] = float(ke)
        run["stable"] = bool(
            run["contact_lost_time"] is None
            and run["peak_error_last_fifth"] < run["peak_error_first_fifth"]
        )
        runs.append(run)
    return runs


# --- the sampled, delayed loop (reduced model) ----------------------------------------------

# The walls of the table in sampled_margins, N/m.
MARGIN_STIFFNESSES = (1e3, 1e4, 1e5, 1e6, 1e7)


def is_sampled(scenario: Scenario) -> bool:
    """A sampled controller or a delayed reading: Linearize cannot take the loop whole."""
    return scenario.admittance.period > 0 or scenario.pid.period > 0 or scenario.sensor.latency > 0


def continuous_counterpart(scenario: Scenario) -> Scenario:
    """The scenario with the continuous controller and no latency (the full loop that
    Linearize reads; the sampled one is read by `sampled_margins`)."""
    return with_values(
        scenario, {"admittance.period": 0.0, "pid.period": 0.0, "sensor.latency": 0.0}
    )


def _contact_loop(scenario: Scenario) -> tuple[SampledContactLoop, dict]:
    """The reduced loop at the scenario's contact equilibrium (m from M(q) and J(q) there,
    the layer's c when it is on), sampled at the scenario's period."""
    continuous = continuous_counterpart(scenario)
    equilibrium = FindContactEquilibrium(continuous)
    loop = equilibrium.loop
    kp, kd = scenario.pid.kp[WALL_NORMAL_AXIS], scenario.pid.kd[WALL_NORMAL_AXIS]
    if scenario.safety.enabled:
        law = loop.admittance.law
        numbers = law.numbers(law.GetMyContextFromRoot(equilibrium.context))
        mass, damping = numbers["apparent_mass"], numbers["injected_damping"]
    else:
        plant_context = loop.plant.GetMyContextFromRoot(equilibrium.context)
        kinematics = PlanarFrameKinematics(
            loop.plant, scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
        )
        kinematics.set_state(loop.plant.GetPositionsAndVelocities(plant_context))
        mass = contact_model.apparent_mass(
            loop.plant.CalcMassMatrix(plant_context), kinematics.jacobian()[WALL_NORMAL_AXIS]
        )
        damping = 0.0
    tau = loop.sensor.filter_time_constant if loop.sensor is not None else 0.0
    reduced = SampledContactLoop(
        mass, kp, kd + damping, scenario.admittance.alpha, tau, kp, scenario.admittance.period
    )
    return reduced, {"apparent_mass": mass, "injected_damping": damping, "kp": kp, "kd": kd}


def _scheduled_gamma(scenario: Scenario, critical: float) -> float:
    """The Gamma the loop runs: the layer's min(Gamma, Gamma* / margin), or Gamma."""
    gamma = scenario.admittance.gamma
    if not scenario.safety.enabled:
        return gamma
    return min(gamma, critical / scenario.safety.stability_margin)


def sampled_margins(scenario: Scenario) -> dict:
    """The margins of the loop that runs: the PID and the law (and the layer) in one tick
    of h = admittance.period, the reading sensor.latency L late (systems/sampled_loop.py).

    At the scenario's wall (and, in `table`, at other stiffnesses): Gamma* of the sampled
    loop with the latency and without it, the continuous loop's (Routh-Hurwitz), the Gamma
    the loop runs (the layer's schedule with the estimate at the wall's stiffness), the
    spectral radius there, and the latency tolerable at that Gamma.
    """
    if scenario.admittance.period <= 0:
        raise ScenarioError("admittance.period: the sampled margins need a sampled controller")
    reduced, parts = _contact_loop(scenario)
    latency = scenario.sensor.latency

    def at(stiffness: float) -> dict:
        critical = reduced.critical_gamma(stiffness, latency)
        scheduled = _scheduled_gamma(scenario, critical)
        return {
            "stiffness": stiffness,
            "critical_gamma": critical,
            "critical_gamma_without_latency": reduced.critical_gamma(stiffness, 0.0),
            "critical_gamma_continuous": reduced.continuous_critical_gamma(stiffness),
            "scheduled_gamma": scheduled,
            "spectral_radius": float(
                np.max(np.abs(np.linalg.eigvals(reduced.matrix(scheduled, stiffness, latency))))
            ),
            "tolerable_latency": reduced.tolerable_latency(scheduled, stiffness),
        }

    wall = at(scenario.wall.stiffness)
    return {
        "period": reduced.period,
        "latency": latency,
        "apparent_mass": parts["apparent_mass"],
        "damping": reduced.damping,
        "injected_damping": parts["injected_damping"],
        "gamma": scenario.admittance.gamma,
        **wall,
        "table": [at(ke) for ke in MARGIN_STIFFNESSES],
    }


def sampled_stability_map(scenario: Scenario, gammas, stiffnesses) -> np.ndarray:
    """ln(spectral radius) / h of the reduced sampled loop over a grid (rows: Ke, columns:
    Gamma): < 0 stable, the sign convention of `stability_map`."""
    reduced, _ = _contact_loop(scenario)
    grid = np.empty((len(stiffnesses), len(gammas)))
    for row, stiffness in enumerate(stiffnesses):
        for column, gamma in enumerate(gammas):
            M = reduced.matrix(float(gamma), float(stiffness), scenario.sensor.latency)
            radius = float(np.max(np.abs(np.linalg.eigvals(M))))
            grid[row, column] = math.log(radius) / reduced.period
    return grid


def resolving_step(A: np.ndarray, steps_per_period: int = 10) -> dict:
    """The integrator step a nonlinear run needs to show the loop's fastest oscillatory
    mode: `steps_per_period` steps over its period (an implicit integrator with a longer
    step damps it numerically, whatever the linear model says it does)."""
    eigenvalues = np.linalg.eigvals(A)
    oscillatory = eigenvalues[np.abs(eigenvalues.imag) > 1e-9]
    if oscillatory.size == 0:
        return {"fastest_mode_hz": 0.0, "step": math.inf}
    frequency = float(np.max(np.abs(oscillatory.imag))) / (2.0 * math.pi)
    return {"fastest_mode_hz": frequency, "step": 1.0 / (steps_per_period * frequency)}
