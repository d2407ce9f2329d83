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
Gamma per finger is the generic bisection of ``stability.critical_gain`` over it, the
others keeping theirs.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context

from admittance.diagrams.analysis.linear import critical_gain, lyapunov_certificate, modal_summary
from admittance.diagrams.robots.planar_gripper.loop import (
    BuildGrasp,
    GraspLoop,
    SetGraspInitialConditions,
)
from admittance.diagrams.robots.planar_gripper.plant import (
    BRICK_JOINTS,
    FINGER_COORDINATES,
    NORMAL_AXIS,
    contact_frame,
    tip_centre_frame,
)
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GraspScenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = [
    "GraspEquilibrium",
    "FindGraspEquilibrium",
    "LinearizeGraspStep",
    "analyse_grasp",
    "confirm_gamma",
    "critical_finger_gammas",
    "get_discrete_state",
    "matrix_at_gammas",
    "offset_rows",
    "set_discrete_state",
    "static_grasp",
    "step_once",
    "stepped_forces",
    "without_near_neutral_modes",
]

# Time held after the force ramp before the state is taken as the equilibrium, s.
SETTLE_TIME = 1.0
# Newton steps on f(x) - x = 0 after settling (each needs one Jacobian, ~0.5 s).
POLISH_STEPS = 3
# Central differences: the step of state entry j is RELATIVE_STEP max(|x_j|, 1).
RELATIVE_STEP = 1e-6
# The method's resolution of a growth rate, 1/s: modes slower than 100 s (ten times the
# hold) are the hand's near-neutral directions (below); their sign is not resolved.
NEUTRAL_RESOLUTION = 0.01
# Bisection range of a finger's Gamma, and the factors of the nonlinear confirmation.
GAMMA_RANGE = (1e-7, 1e-2)
CONFIRMATION_FACTORS = (0.8, 1.25)


def static_grasp(scenario: GraspScenario) -> GraspScenario:
    """The grasp with everything that varies frozen: no sensor noise, no disturbance."""
    if scenario.time_step <= 0:
        raise ScenarioError(
            "time_step: the grasp's stability is analysed for the sampled loop that runs "
            "(time_step > 0); Drake cannot linearize the continuous plant's point contact"
        )
    if scenario.controller.kind != "optimal_admittance":
        raise ScenarioError(
            "controller.kind: the grasp's stability is analysed for optimal_admittance fingers"
        )
    frozen = copy.deepcopy(scenario)
    frozen.sensor.noise_std = 0.0
    frozen.disturbance.kind = "none"
    return frozen


def get_discrete_state(context: Context) -> np.ndarray:
    """Every numeric discrete state of a diagram's context, group after group."""
    state = context.get_discrete_state()
    return np.concatenate([state.get_vector(i).CopyToVector() for i in range(state.num_groups())])


def set_discrete_state(context: Context, x: np.ndarray) -> None:
    """The inverse of get_discrete_state."""
    state = context.get_mutable_discrete_state()
    start = 0
    for i in range(state.num_groups()):
        vector = state.get_mutable_vector(i)
        vector.SetFromVector(x[start : start + vector.size()])
        start += vector.size()


def step_once(loop: GraspLoop, context: Context, x: np.ndarray | None = None) -> np.ndarray:
    """f(x): the discrete state one period after `context` (at a sample time), with its
    discrete state replaced by `x` if given. `context` is not changed."""
    working = context.Clone()
    if x is not None:
        set_discrete_state(working, x)
    simulator = Simulator(loop.diagram, working)
    simulator.Initialize()
    simulator.AdvanceTo(working.get_time() + loop.scenario.time_step)
    return get_discrete_state(working)


def _jacobian(loop: GraspLoop, context: Context, relative_step: float) -> np.ndarray:
    x = get_discrete_state(context)
    A = np.empty((x.size, x.size))
    for j in range(x.size):
        delta = relative_step * max(abs(x[j]), 1.0)
        plus, minus = x.copy(), x.copy()
        plus[j] += delta
        minus[j] -= delta
        A[:, j] = (step_once(loop, context, plus) - step_once(loop, context, minus)) / (2 * delta)
    return A


@dataclass
class GraspEquilibrium:
    """The held grasp: the analysis diagram, its context at a sample time, the residual."""

    loop: GraspLoop
    context: Context
    # max |f(x) - x| / h at the returned state (the state's rate over one period).
    residual: float
    # The brick's (y, z, theta) rates, from its velocity state (m/s, rad/s).
    brick_velocity: np.ndarray
    # The residual before the Newton polish, and the Jacobian at the returned state.
    settled_residual: float
    jacobian: np.ndarray | None = None

    def describe(self) -> dict:
        """Every finger's tip (its face frame), forces and offset; the brick's pose."""
        loop, context = self.loop, self.context
        plant = loop.plant
        plant_context = plant.GetMyContextFromRoot(context)
        state = plant.GetPositionsAndVelocities(plant_context)
        forces = stepped_forces(loop, context)
        fingers = []
        for index, finger in enumerate(loop.fingers):
            kinematics = PlanarFrameKinematics(
                plant,
                tip_centre_frame(finger.name),
                coordinates=FINGER_COORDINATES,
                expressed_in=contact_frame(finger.name),
            )
            kinematics.set_state(state)
            port = finger.measured_force_output
            measured = port.Eval(port.get_system().GetMyContextFromRoot(context))
            offset = finger.admittance.reference_offset_output.Eval(
                finger.admittance.GetMyContextFromRoot(context)
            )
            reference = loop.scenario.force_reference[index]
            fingers.append(
                {
                    "finger": finger.name,
                    "force_reference": float(reference),
                    "normal_force": float(forces[index]),
                    "force_error": float(forces[index] - reference),
                    "measured_force": float(measured[0]),
                    "tip_position": [float(v) for v in kinematics.pose()],
                    "reference_offset": float(offset[NORMAL_AXIS]),
                }
            )
        q = plant.GetPositions(plant_context)
        brick = [float(q[plant.GetJointByName(name).position_start()]) for name in BRICK_JOINTS]
        return {
            "time": float(context.get_time()),
            "residual": self.residual,
            "settled_residual": self.settled_residual,
            "brick_pose": brick,
            "brick_velocity": [float(v) for v in self.brick_velocity],
            "fingers": fingers,
        }


def _brick_velocity(loop: GraspLoop, context: Context) -> np.ndarray:
    plant = loop.plant
    v = plant.GetVelocities(plant.GetMyContextFromRoot(context))
    return np.array([v[plant.GetJointByName(name).velocity_start()] for name in BRICK_JOINTS])


def FindGraspEquilibrium(
    scenario: GraspScenario,
    *,
    settle_time: float = SETTLE_TIME,
    polish_steps: int = POLISH_STEPS,
    relative_step: float = RELATIVE_STEP,
) -> GraspEquilibrium:
    """The held grasp of the frozen scenario: simulated until `settle_time` after the force
    ramp, then polished by `polish_steps` Newton steps on f(x) = x within the modes that
    have a fixed point (the iterate of least residual is kept). The Jacobian at the
    returned state comes with it.

    Raises:
        ScenarioError: a continuous or position-only grasp, or no finger in contact.
    """
    frozen = static_grasp(scenario)
    loop = BuildGrasp(frozen)
    context = loop.diagram.CreateDefaultContext()
    SetGraspInitialConditions(loop, context)
    simulator = Simulator(loop.diagram, context)
    simulator.Initialize()
    h = frozen.time_step
    steps = int(round((frozen.force_ramp_end + settle_time) / h))
    simulator.AdvanceTo(steps * h)
    context = context.Clone()  # at a sample time, its update pending

    def residual(x: np.ndarray) -> float:
        return float(np.max(np.abs(step_once(loop, context, x) - x))) / h

    x = get_discrete_state(context)
    settled = residual(x)
    best, best_x = settled, x
    for _ in range(polish_steps):
        # Newton on f(x) = x within the modes that have a fixed point: the near-neutral
        # ones (the brick's free directions, where it creeps) are left out.
        jacobian = _jacobian(loop, context, relative_step)
        basis = _resolved_basis(jacobian, h)
        r = step_once(loop, context, x) - x
        reduced = basis.T @ (jacobian - np.eye(x.size)) @ basis
        x = x + basis @ np.linalg.solve(reduced, -basis.T @ r)
        set_discrete_state(context, x)
        value = residual(x)
        if value < best:
            best, best_x = value, x
    set_discrete_state(context, best_x)
    jacobian = _jacobian(loop, context, relative_step)
    forces = stepped_forces(loop, context)
    if not np.all(forces > 0):
        raise ScenarioError(f"scenario: the grasp does not hold (normal forces {forces} N)")
    return GraspEquilibrium(
        loop=loop,
        context=context,
        residual=best,
        brick_velocity=_brick_velocity(loop, context),
        settled_residual=settled,
        jacobian=jacobian,
    )


def stepped_forces(loop: GraspLoop, context: Context) -> np.ndarray:
    """The normal forces of the step from `context` (the plant's sampled contact results
    after it): at a fixed point, the forces of the held grasp."""
    working = context.Clone()
    simulator = Simulator(loop.diagram, working)
    simulator.Initialize()
    simulator.AdvanceTo(working.get_time() + loop.scenario.time_step)
    sensor = loop.contact_sensor
    return sensor.normal_force_output.Eval(sensor.GetMyContextFromRoot(working)).copy()


def _near_neutral(eigenvalues: np.ndarray, period: float) -> np.ndarray:
    """Which z have a growth rate |ln|z|| / period below NEUTRAL_RESOLUTION (a growing
    mode faster than that is not near-neutral: it stays in the analysis)."""
    magnitude = np.abs(eigenvalues)
    growth = np.full(magnitude.shape, np.inf)
    growth[magnitude > 0] = np.abs(np.log(magnitude[magnitude > 0])) / period
    return growth < NEUTRAL_RESOLUTION


def _resolved_basis(A: np.ndarray, period: float) -> np.ndarray:
    """An orthonormal basis of the invariant subspace without the near-neutral modes."""
    eigenvalues, left = np.linalg.eig(A.T)
    neutral = _near_neutral(eigenvalues, period)
    if not np.any(neutral):
        return np.eye(A.shape[0])
    vectors = left[:, neutral]
    _, singular, rows = np.linalg.svd(np.vstack([vectors.real.T, vectors.imag.T]))
    rank = int(np.count_nonzero(singular > 1e-10 * singular[0]))
    return rows[rank:].T


def LinearizeGraspStep(
    equilibrium: GraspEquilibrium, *, relative_step: float = RELATIVE_STEP
) -> np.ndarray:
    """A = df/dx over one period at the equilibrium (central differences, step
    relative_step max(|x_j|, 1) on entry j)."""
    return _jacobian(equilibrium.loop, equilibrium.context, relative_step)


def offset_rows(loop: GraspLoop, context: Context) -> list[int]:
    """Index in x of each finger's held offset on its normal axis (the row Gamma scales):
    the one entry of x that moves the block's reference_offset output one for one."""
    x = get_discrete_state(context)
    probe = context.Clone()
    rows = []
    for finger in loop.fingers:
        port = finger.admittance.reference_offset_output
        block_context = finger.admittance.GetMyContextFromRoot(probe)
        base = port.Eval(block_context)[NORMAL_AXIS]
        found = None
        for j in range(x.size):
            moved = x.copy()
            moved[j] += 1.0
            set_discrete_state(probe, moved)
            if abs(port.Eval(block_context)[NORMAL_AXIS] - base - 1.0) < 1e-9:
                found = j
                break
        set_discrete_state(probe, x)
        if found is None:  # pragma: no cover (a sampled block holds its offset as state)
            raise RuntimeError(f"{finger.name}: no held reference offset in the state")
        rows.append(found)
    return rows


def matrix_at_gammas(A: np.ndarray, rows: list[int], gammas, scenario_gamma: float) -> np.ndarray:
    """A with each finger's Gamma: its held offset's row scaled by Gamma / scenario Gamma."""
    scaled = A.copy()
    for row, gamma in zip(rows, gammas, strict=True):
        scaled[row] *= gamma / scenario_gamma
    return scaled


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


def without_near_neutral_modes(A: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """A on the invariant subspace that leaves out its near-neutral modes (|ln|z|| / period
    below NEUTRAL_RESOLUTION), and their eigenvalues z.

    The subspace is the null space of those modes' left eigenvectors (Y^T A = Z Y^T, so
    Y^T x = 0 stays 0 under A); on an orthonormal basis U of it, A acts as U^T A U.
    """
    eigenvalues = np.linalg.eigvals(A)
    neutral = eigenvalues[_near_neutral(eigenvalues, period)]
    basis = _resolved_basis(A, period)
    return basis.T @ A @ basis, neutral


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
