"""Stability of the spatial arm's force loop: a reduced model along the normal, sampled,
checked against the whole loop linearized through AutoDiffXd.

The whole loop (diagrams/robots/spatial_arm/step_map.py: seven joints, the contact engine,
the 6-D PID and the law, 33 states for the Panda) is the reference: one step of the
diagram differentiated by AutoDiffXd at the contact equilibrium, its critical Gamma
confirmed by nonlinear runs started at rest. The reduced model reads the loop along the
normal, as diagrams/robots/planar_arm/stability.py reads the paper's arm, at the loop's CONTACT
EQUILIBRIUM (the state at the end of the scenario's own run: the tool pressing with Fr, at
rest), so that its numbers can be read by hand:

* the arm's APPARENT MASS along the normal, m = Lambda_zz, Lambda = (J M^-1 J^T)^-1 with J
  the tool tip's 6 x n Jacobian in the control frame (the five other axes held by the PID);
* the contact's stiffness k (surface.stiffness: the two geometries' 2k in series) and its
  Hunt-Crossley damping linearized at Fr, c = d Fr (f = k x (1 + d dx/dt));
* the PID's z gains Kp, Kd, Ki (eq. 14) and the law's Gamma and alpha (eq. 10, K = Kp);

sampled at the plant's step h with the order of Drake's simultaneous discrete updates (each
update reads the state before any of them): the plant steps with the PID's HELD force (the
contact implicit, as SAP treats it; the actuation explicit), the PID latches its force from
the current position, the law latches Xr from the current reading (the ideal sensor: the
contact force of the step that ended now). State x = [z, v, u, w, zi, Xr] (deviations):

    v' = (m v + h u - h k z) / (m + h c + h^2 k)      z' = z + h v'
    F  = k z + c v                                    E = -F
    u' = Kp (Xr - z) - Kd v + Ki w                    w' = w + h (Xr - z)
    Xr' = Gamma K (zi + alpha E)                      zi' = zi + h E

`analyse_spatial_stability` gives the map's eigenvalues (analysis.linear.modal_summary),
the certificate P > 0 of A^T P A - P = -I (analysis.linear.lyapunov_certificate), the
critical Gamma (analysis.linear.critical_gain, bisection on the spectral radius) and its
confirmation by the scenario's nonlinear runs at 0.8 and 1.25 times it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from admittance.diagrams.analysis.linear import critical_gain, lyapunov_certificate, modal_summary
from admittance.diagrams.robots.spatial_arm.loop import BuildSpatialLoop
from admittance.diagrams.robots.spatial_arm.plant import CONTROL_FRAME, NORMAL_AXIS, TOOL_TIP_FRAME
from admittance.diagrams.robots.spatial_arm.run import SpatialResult, run_spatial
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.robots.spatial_arm.step_map import (
    LoopStepMap,
    confirm_loop_critical_gamma,
    equilibrium_force,
    loop_critical_gamma,
    loop_step_map,
)
from admittance.diagrams.run.engine import SimulationDivergedError
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems import contact_model

__all__ = [
    "NormalModel",
    "analyse_spatial_stability",
    "apparent_mass",
    "check_reducible",
    "confirm_spatial_critical_gamma",
    "normal_map",
    "normal_model",
    "routh_critical_gamma",
    "spatial_critical_gamma",
    "state_names",
    "whole_loop_summary",
]

#: The reduced state, in order.
STATE_NAMES = ("z", "v", "u", "w", "zi", "Xr")


@dataclass(frozen=True)
class NormalModel:
    """The loop along the normal: its plant, contact, PID and law (SI units)."""

    mass: float  # apparent mass along the normal, kg
    contact_stiffness: float  # k, N/m
    contact_damping: float  # c = d Fr, N s/m
    kp: float  # N/m (K of eq. 10)
    kd: float  # N s/m
    ki: float  # N/(m s)
    gamma: float
    alpha: float  # s
    period: float  # h, s

    def with_gamma(self, gamma: float) -> NormalModel:
        return NormalModel(**{**self.__dict__, "gamma": gamma})


def normal_map(model: NormalModel, *, after_step: bool = False) -> np.ndarray:
    """A of x[k+1] = A x[k], x = [z, v, u, w, zi, Xr] (see the module's docstring; without
    w when Ki = 0).

    With `after_step`, the PID and the law read the state after the plant's step (z', v'
    and the force of the step just taken), as in Drake's order for the simulated loop,
    where the plant steps in an unrestricted update before the controllers' discrete
    updates; without it they read the state before it: one period more of delay, the
    hardware split's (the controller answers the status of t_k, its command acts from
    t_k+1)."""
    m, k, c = model.mass, model.contact_stiffness, model.contact_damping
    h, kp, kd, ki = model.period, model.kp, model.kd, model.ki
    gain = model.gamma * model.kp  # Gamma K
    den = m + h * c + h * h * k
    v_next = np.array([-h * k, m, h, 0.0, 0.0, 0.0]) / den
    z_next = np.array([1.0, 0, 0, 0, 0, 0]) + h * v_next
    # What the controllers read: z and v now, or after the step.
    z_read = z_next if after_step else np.array([1.0, 0, 0, 0, 0, 0])
    v_read = v_next if after_step else np.array([0.0, 1.0, 0, 0, 0, 0])
    error = -(k * z_read + c * v_read)  # E = -(k z + c v)
    u_next = -kp * z_read - kd * v_read + np.array([0.0, 0.0, 0.0, ki, 0.0, kp])
    w_next = -h * z_read + np.array([0.0, 0.0, 0.0, 1.0, 0.0, h])
    xr_next = gain * (np.array([0, 0, 0, 0, 1.0, 0]) + model.alpha * error)
    zi_next = np.array([0, 0, 0, 0, 1.0, 0]) + h * error
    A = np.vstack([z_next, v_next, u_next, w_next, zi_next, xr_next])
    if model.ki == 0.0:  # w feeds nothing: its eigenvalue 1 would hide the loop's
        keep = [index for index, name in enumerate(STATE_NAMES) if name != "w"]
        A = A[np.ix_(keep, keep)]
    return A


def state_names(model: NormalModel) -> list[str]:
    """The names of normal_map's states (w only with Ki > 0)."""
    return [name for name in STATE_NAMES if name != "w" or model.ki != 0.0]


def routh_critical_gamma(model: NormalModel) -> float | None:
    """Gamma at which the CONTINUOUS loop (h -> 0, Ki = 0, alpha = 0) loses stability.

    m s^3 + (Kd + c) s^2 + (Kp + k + g c) s + g k = 0 with g = Gamma Kp^2 (Xr' = Gamma K E,
    K = Kp) is Hurwitz while (Kd + c)(Kp + k + g c) > m g k (Routh):
    Gamma_c = (Kd + c)(Kp + k) / (Kp^2 (m k - (Kd + c) c)); None when m k <= (Kd + c) c
    (stable at every Gamma).
    """
    m, k, c = model.mass, model.contact_stiffness, model.contact_damping
    damping = model.kd + c
    margin = m * k - damping * c
    if margin <= 0:
        return None
    return damping * (model.kp + k) / (model.kp**2 * margin)


def apparent_mass(plant, plant_context) -> dict:
    """The tool tip's apparent mass along the control frame's z at the plant's state, kg:
    Lambda_zz of Lambda = (J M^-1 J^T)^-1 (6-D, the other axes held) and 1 / (J_z M^-1
    J_z^T) (the other axes free)."""
    tip = plant.GetFrameByName(TOOL_TIP_FRAME)
    frame_E = plant.GetFrameByName(CONTROL_FRAME)
    J = plant.CalcJacobianSpatialVelocity(
        plant_context, JacobianWrtVariable.kV, tip, np.zeros(3), frame_E, frame_E
    )
    mass_matrix = plant.CalcMassMatrix(plant_context)
    row = 3 + NORMAL_AXIS  # spatial velocity rows: [w; v]
    Lambda = np.linalg.inv(J @ np.linalg.solve(mass_matrix, J.T))
    return {
        "held": float(Lambda[row, row]),
        "free": contact_model.apparent_mass(mass_matrix, J[row]),
    }


def check_reducible(scenario: SpatialScenario) -> None:
    """Raises ScenarioError (one line) unless the analysis covers `scenario`: the paper's
    law with the ideal sensor, without the safety layer or injected faults."""
    if scenario.controller.kind != "optimal_admittance":
        raise ScenarioError(
            f"controller.kind: the stability analysis reads the paper's law "
            f"(optimal_admittance), got {scenario.controller.kind!r}"
        )
    if scenario.sensor.kind != "ideal":
        raise ScenarioError(
            f"sensor.kind: the reduced model reads the ideal sensor, got {scenario.sensor.kind!r}"
        )
    if scenario.safety.enabled:
        raise ScenarioError(
            "safety.enabled: the stability analysis reads the loop without the safety layer "
            "(its observer integrates between the plant's steps); set it to false"
        )
    if scenario.faults:
        raise ScenarioError(
            "faults: the stability analysis reads the loop at its contact equilibrium, "
            "without injected faults; remove them"
        )


def normal_model(scenario: SpatialScenario, positions, *, plant=None) -> tuple[NormalModel, dict]:
    """The reduced model of `scenario` with the arm at joint positions `positions` (on
    `plant`, the scenario's own, when the caller has one built).

    Raises:
        ScenarioError: the controller or the sensor is one the model does not cover.
    """
    check_reducible(scenario)
    plant = plant if plant is not None else BuildSpatialLoop(scenario).plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.asarray(positions))
    masses = apparent_mass(plant, context)
    axis = NORMAL_AXIS
    model = NormalModel(
        mass=masses["held"],
        contact_stiffness=scenario.surface.stiffness,
        contact_damping=scenario.surface.dissipation * scenario.force_reference,
        kp=float(scenario.pid.kp[axis]),
        kd=float(scenario.pid.kd[axis]),
        ki=float(scenario.pid.ki[axis]),
        gamma=scenario.admittance.gamma,
        alpha=scenario.admittance.alpha,
        period=scenario.time_step,
    )
    return model, masses


def spatial_critical_gamma(
    model: NormalModel, low: float = 1e-8, high: float = 1e-2, *, after_step: bool = False
):
    """The smallest Gamma at which the sampled map's spectral radius reaches 1 (with the
    controllers reading the state before the plant's step, or `after_step`)."""
    return critical_gain(
        lambda gamma: normal_map(model.with_gamma(gamma), after_step=after_step),
        low,
        high,
        period=model.period,
    )


def _with_gamma(scenario: SpatialScenario, gamma: float) -> SpatialScenario:
    varied = copy.deepcopy(scenario)
    varied.admittance.gamma = gamma
    return varied


def _amplitude(result: SpatialResult, start: float, end: float) -> float:
    window = (result.time >= start) & (result.time < end)
    return float(np.max(np.abs(result.force[window] - result.force_reference[window])))


def confirm_spatial_critical_gamma(
    scenario: SpatialScenario, critical: float, factors=(0.8, 1.25)
) -> list[dict]:
    """The scenario's nonlinear runs at factor x the critical Gamma, from its start.

    A run is STABLE when the force error's amplitude over its last second is under 5 % of
    Fr and below that over the second before (the oscillation decays; or under 0.1 % of
    Fr), with no contact lost in the last second; otherwise (diverged, growing, or a
    limit cycle that loses contact) it is unstable. A scenario with a slide runs as a
    press (no slide, 3 s past the slide's start): the slide's own disturbance is not
    the loop's instability.
    """
    outcomes = []
    if scenario.trajectory.slide_distance > 0:
        scenario = copy.deepcopy(scenario)
        scenario.trajectory.slide_distance = 0.0
        scenario.duration = scenario.slide_start + 3.0
    end = scenario.duration
    for factor in factors:
        gamma = factor * critical
        try:
            result = run_spatial(_with_gamma(scenario, gamma))
        except SimulationDivergedError:
            outcomes.append({"factor": factor, "gamma": gamma, "stable": False, "diverged": True})
            continue
        earlier, last = _amplitude(result, end - 2, end - 1), _amplitude(result, end - 1, end)
        lost = bool(np.any(result.force[result.time >= end - 1] < 0.05 * scenario.force_reference))
        decays = last < earlier or last < 1e-3 * scenario.force_reference
        small = last < 0.05 * scenario.force_reference
        outcomes.append(
            {
                "factor": factor,
                "gamma": gamma,
                "stable": bool(decays and small and not lost),
                "diverged": False,
                "amplitude_second_to_last_s": earlier,
                "amplitude_last_s": last,
                "contact_lost_last_s": lost,
                "contact_losses": result.metrics["contact_losses"],
                "peak_force": result.metrics["peak_force"],
            }
        )
    return outcomes


def _silent(stage: str) -> None:
    pass


def analyse_spatial_stability(
    scenario: SpatialScenario,
    *,
    confirm: bool = True,
    progress: Callable[[str], None] = _silent,
) -> dict:
    """The reduced loop at the contact equilibrium: modes, P > 0, the critical Gamma (and
    its confirmation by nonlinear runs). A JSON-serialisable dict (P as a list)."""
    check_reducible(scenario)
    progress("the scenario's run to its contact equilibrium")
    step_map = loop_step_map(scenario)
    plant = step_map.loop.plant
    settled = plant.GetPositions(plant.GetMyContextFromRoot(step_map.context))
    progress("the whole loop's step linearized through AutoDiffXd")
    whole = whole_loop_summary(scenario, step_map, confirm=confirm)
    model, masses = normal_model(scenario, settled, plant=plant)
    A = normal_map(model)
    modes = modal_summary(A, period=model.period)
    certificate = lyapunov_certificate(A, discrete=True)
    if "P" in certificate:
        certificate["P"] = certificate["P"].tolist()
    progress("the critical Gamma (bisection on the spectral radius)")
    critical = spatial_critical_gamma(model)
    summary = {
        "scenario": scenario.name,
        "period": model.period,
        "states": state_names(model),
        "equilibrium": {
            "force": equilibrium_force(step_map),
            "force_reference": scenario.force_reference,
            "joint_positions": settled.tolist(),
        },
        "model": dict(model.__dict__),
        "apparent_mass": masses,
        "A": A.tolist(),
        "modes": modes,
        "lyapunov": certificate,
        "critical_gamma": critical,
        "margin": critical / model.gamma if critical else math.inf,
        "continuous_critical_gamma": routh_critical_gamma(model),
        "after_step_critical_gamma": spatial_critical_gamma(model, after_step=True),
    }
    summary["whole_loop"] = whole
    if confirm and critical is not None:
        progress("nonlinear runs at 0.8 and 1.25 x the critical Gamma")
        summary["confirmation"] = confirm_spatial_critical_gamma(scenario, critical)
    return summary


def whole_loop_summary(
    scenario: SpatialScenario, step_map: LoopStepMap | None = None, *, confirm: bool = True
) -> dict:
    """The whole loop's one-step map at its equilibrium (spatial_step_map; `step_map` if
    given): its size, the states left out, its modes, P > 0, its critical Gamma and (with
    `confirm`) the local nonlinear runs at 0.95 and 1.05 x that Gamma. JSON-serialisable."""
    step_map = step_map if step_map is not None else loop_step_map(scenario)
    modes = modal_summary(step_map.A, period=step_map.period)
    certificate = lyapunov_certificate(step_map.A, discrete=True)
    certificate.pop("P", None)
    gamma = scenario.admittance.gamma
    critical = loop_critical_gamma(scenario, step_map, 0.01 * gamma, 20.0 * gamma)
    whole = {
        "states": len(step_map.names),
        "left_out": step_map.left_out,
        "fixed_point_residual": step_map.residual,
        "spectral_radius": modes["spectral_radius"],
        "stable": modes["stable"],
        "lyapunov": certificate,
        "critical_gamma": critical,
        "margin": critical / gamma if critical else math.inf,
    }
    if confirm and critical is not None:
        whole["confirmation"] = confirm_loop_critical_gamma(
            scenario, step_map, critical, factors=(0.95, 1.05)
        )
    return whole
