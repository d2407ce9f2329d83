"""Stability of the grasp: the sampled hand linearized over one period at its held grasp.

The grasp runs on a discrete plant (SAP, point contact) with every controller and sensor
readout sampled at the same ``time_step`` h. Drake's ``Linearize`` refuses that plant (its
sampled output ports are abstract state). The continuous build (time_step = 0) converts to
AutoDiffXd, but its Linearize stops in the point-contact forces (Drake 1.51 asks the
geometries' Hunt-Crossley dissipation as AutoDiffXd, stored as double), and it would not be
the loop that runs anyway: the sampling sets the critical Gamma. So the loop that actually
runs is linearized as what it is, a map over one period:

    x[k+1] = f(x[k]),   A = df/dx   (central finite differences of one simulator step),

where x is every numeric discrete state of the diagram (the plant's q and v, each PID's
integral and held torque, each FlexiForce readout, each admittance block's integral and held
offset). One step of Drake's Simulator applies the plant's step first (an unrestricted
update, which also refreshes its sampled contact results) and then every controller's
update on the new plant state, so f is a function of x alone: the sampled contact results
are recomputed inside the step and need not be part of x (``tests/test_grasp_stability.py``
checks that a different stored value changes nothing).

The equilibrium is the held grasp: the scenario frozen (no noise, no disturbance) is
simulated until the forces have settled and then polished by Newton steps on
f(x) - x = 0. With the regularized friction of SAP and finger3 pressing with more than the
brick's weight, the brick creeps upwards at a steady speed (tens of micrometres per
second): there is no exact fixed point, and the residual |f(x) - x| / h at the returned
state is reported with the brick's speed.

Each finger's Gamma enters f in one place: the held offset of its admittance block is
Xr[k+1] = Gamma K (z[k] + alpha (E[k] - E0)), linear in Gamma, and no other update reads
Gamma; the same physical equilibrium holds at any Gamma (only z = Xr / (Gamma K) changes,
and no row of A depends on z). So A at a finger's Gamma is A at the scenario's with that
finger's offset row scaled by Gamma / Gamma_scenario (``matrix_at_gammas``); the critical
Gamma per finger is the generic bisection of ``analysis.linear.critical_gain`` over it, the
others keeping theirs.

The steps are the package's: :mod:`.step_map` (f, A and the near-neutral modes) and
:mod:`.equilibrium` (the held grasp); this module finds the critical Gamma of each finger,
confirms it in nonlinear runs and gathers the report (``analyse_grasp``).
"""

from __future__ import annotations

import copy
import math

import numpy as np
from pydrake.systems.analysis import Simulator

from admittance.diagrams.analysis.linear import critical_gain, lyapunov_certificate, modal_summary
from admittance.diagrams.robots.planar_gripper.equilibrium import (
    FindGraspEquilibrium,
    GraspEquilibrium,
)
from admittance.diagrams.robots.planar_gripper.loop import BuildGrasp, SetGraspInitialConditions
from admittance.diagrams.robots.planar_gripper.plant import NORMAL_AXIS
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GraspScenario
from admittance.diagrams.robots.planar_gripper.step_map import (
    NEUTRAL_RESOLUTION,
    RELATIVE_STEP,
    get_discrete_state,
    matrix_at_gammas,
    offset_rows,
    set_discrete_state,
    without_near_neutral_modes,
)

__all__ = [
    "analyse_grasp",
    "confirm_gamma",
    "critical_finger_gammas",
]

# Bisection range of a finger's Gamma, and the factors of the nonlinear confirmation.
GAMMA_RANGE = (1e-7, 1e-2)
CONFIRMATION_FACTORS = (0.8, 1.25)


def critical_finger_gammas(equilibrium: GraspEquilibrium, A: np.ndarray | None = None) -> dict:
    """The critical Gamma of each finger (the others keeping the scenario's), and of all
    three scaled together, by the generic bisection: where a mode's growth rate
    ln|z| / h reaches +NEUTRAL_RESOLUTION (the near-neutral modes stay below it; the mode
    that Gamma destabilizes crosses it within 0.1 % of Gamma of crossing |z| = 1)."""
    A = equilibrium.jacobian if A is None else A
    gamma = equilibrium.loop.scenario.admittance.gamma
    criterion = {"period": equilibrium.loop.scenario.time_step, "threshold": NEUTRAL_RESOLUTION}
    rows = offset_rows(equilibrium.loop, equilibrium.context)
    result = {}
    for index, finger in enumerate(FINGERS):

        def matrix(value: float, index: int = index) -> np.ndarray:
            gammas = [gamma] * len(FINGERS)
            gammas[index] = value
            return matrix_at_gammas(A, rows, gammas, gamma)

        result[finger] = critical_gain(matrix, *GAMMA_RANGE, **criterion)
    result["all"] = critical_gain(
        lambda value: matrix_at_gammas(A, rows, [value] * len(FINGERS), gamma),
        *GAMMA_RANGE,
        **criterion,
    )
    return result


def confirm_gamma(
    equilibrium: GraspEquilibrium, gamma: float, duration: float = 2.0, nudge: float = 5e-4
) -> dict:
    """A nonlinear run of the grasp with every finger at `gamma`, from `equilibrium` (its
    admittance integrals set to z = Xr / (Gamma K), the same offsets; exact for alpha = 0),
    every finger's held offset nudged by `nudge` m: does the force oscillation die out?

    `converges` is True when every force stays positive and the last fifth's peak error is
    below a tenth of the first fifth's (the arm's criterion, simulate_near_critical).
    """
    source = equilibrium.loop
    varied = copy.deepcopy(source.scenario)
    varied.admittance.gamma = gamma
    target = BuildGrasp(varied)
    context = target.diagram.CreateDefaultContext()
    SetGraspInitialConditions(target, context)  # E0, as in the run
    context.SetTime(equilibrium.context.get_time())
    x = get_discrete_state(equilibrium.context)
    for row in offset_rows(source, equilibrium.context):
        x[row] += nudge
    set_discrete_state(context, x)
    for before, finger in zip(source.fingers, target.fingers, strict=True):
        offset = before.admittance.reference_offset_output.Eval(
            before.admittance.GetMyContextFromRoot(equilibrium.context)
        )[NORMAL_AXIS]
        finger.admittance.set_integral(
            finger.admittance.GetMyMutableContextFromRoot(context),
            [offset / finger.admittance.integral_gain[0]],
        )
    simulator = Simulator(target.diagram, context)
    simulator.Initialize()
    h = varied.time_step
    start = context.get_time()
    sensor = target.contact_sensor
    references = np.asarray(varied.force_reference)
    errors = []
    lost = False
    for k in range(1, int(round(duration / h)) + 1):
        simulator.AdvanceTo(start + k * h)
        forces = sensor.normal_force_output.Eval(sensor.GetMyContextFromRoot(context))
        if not np.all(np.isfinite(forces)) or np.any(forces <= 0):
            lost = True
            break
        errors.append(float(np.max(np.abs(forces - references))))
    fifth = max(1, len(errors) // 5)
    first = max(errors[:fifth]) if errors else math.inf
    last = math.inf if lost else max(errors[-fifth:])
    return {
        "gamma": gamma,
        "peak_error_first_fifth": first,
        "peak_error_last_fifth": last,
        "contact_lost": lost,
        "converges": bool(not lost and last < 0.1 * first),
    }


def analyse_grasp(
    scenario: GraspScenario,
    *,
    confirm: bool = True,
    progress=None,
    equilibrium: GraspEquilibrium | None = None,
) -> dict:
    """Everything `admittance stability` reports for a grasp scenario (`equilibrium`: the
    held grasp of `scenario` if already found)."""
    progress = progress or (lambda stage: None)
    if equilibrium is None:
        progress("the held grasp: simulated until it settles, then polished")
        equilibrium = FindGraspEquilibrium(scenario)
    A = equilibrium.jacobian
    h = equilibrium.loop.scenario.time_step
    modes = modal_summary(A, period=h)
    reduced, neutral = without_near_neutral_modes(A, h)
    resolved = modal_summary(reduced, period=h)
    certificate = lyapunov_certificate(reduced, discrete=True)
    certificate.pop("P", None)
    certificate["num_states"] = int(reduced.shape[0])
    progress("the critical Gamma of each finger (bisection on the spectral radius)")
    critical = critical_finger_gammas(equilibrium, A)
    gamma = scenario.admittance.gamma
    summary = {
        "scenario": scenario.name,
        "kind": "grasp",
        "method": "discrete map over one period, central finite differences of one step",
        "time_step": h,
        "relative_step": RELATIVE_STEP,
        "num_states": int(A.shape[0]),
        "equilibrium": equilibrium.describe(),
        "modes": modes,
        "near_neutral_modes": {
            "resolution": NEUTRAL_RESOLUTION,
            "eigenvalues": [[float(z.real), float(z.imag)] for z in neutral],
            "growth_rates": [float(np.log(abs(z)) / h) for z in neutral],
        },
        "resolved_modes": {
            "stable": resolved["stable"],
            "spectral_radius": resolved["spectral_radius"],
            "max_real_part": resolved["max_real_part"],
            "slowest_time_constant": resolved.get("slowest_time_constant"),
            "least_damped_ratio": resolved.get("least_damped_ratio"),
        },
        "lyapunov": certificate,
        "gamma": gamma,
        "critical_gamma": {
            name: {
                "critical_gamma": value,
                "margin": None if value is None else value / gamma,
            }
            for name, value in critical.items()
        },
    }
    if confirm and critical["all"] is not None:
        progress("nonlinear runs either side of the critical Gamma of all fingers")
        summary["confirmation"] = {
            "below": confirm_gamma(equilibrium, CONFIRMATION_FACTORS[0] * critical["all"]),
            "above": confirm_gamma(equilibrium, CONFIRMATION_FACTORS[1] * critical["all"]),
        }
    return summary
