"""The spatial arm's whole loop linearized at its contact equilibrium, through AutoDiffXd.

The reduced model of diagrams/robots/spatial_arm/analysis.py keeps the normal alone. This module
checks it against the loop as it runs: the diagram that `admittance simulate` steps (the
arm's seven joints, the table through Drake's contact engine, the 6-D PID with its
integrals and held torques, the law with its integral and held Xr), with its noise held at
zero. Its state x (every discrete state of the diagram) moves by one step h of Drake's
Simulator, x[k+1] = F(x[k]), and its linearization at the equilibrium x* = F(x*) is

    A = dF/dx (x*),

the gradient of one step of the diagram converted to AutoDiffXd, stepped by
Simulator_[AutoDiffXd] from x* seeded with the identity (Drake's contact solver
differentiates its own step). Its value agrees with the double diagram's step to 4e-13
(tests/test_spatial_analysis.py).

Why a step of the Simulator and not Drake's Linearize: the discrete plant keeps its last
step's results in an abstract state (its sampled output ports) and so steps in an
unrestricted update, which the Simulator runs before the controllers' discrete updates:
at each tick the plant steps first and the PID and the law then read the new state and the
force of the step just taken. Linearize takes a system with one periodic discrete update
(Drake 1.51 stops on this diagram with a failed check that aborts the process); one step
of the Simulator is the map the nonlinear runs take, in the same order. The abstract state
needs no seed: the plant's step rewrites it before anything reads it.

A state that feeds nothing (its column of A is the unit vector: the PID's integral on an
axis with Ki = 0, which the reduced model drops too) has the eigenvalue 1 and no effect on
the loop; it is left out of the map, and named in the result.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import Context

from admittance.diagrams.analysis.linear import critical_gain
from admittance.diagrams.robots.spatial_arm.loop import (
    BuildSpatialLoop,
    SetSpatialInitialConditions,
    SpatialLoop,
)
from admittance.diagrams.robots.spatial_arm.plant import NORMAL_AXIS
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.scenario.schema import ScenarioError

__all__ = [
    "LoopStepMap",
    "confirm_loop_critical_gamma",
    "equilibrium_force",
    "loop_step_map",
    "loop_critical_gamma",
    "settle_spatial_loop",
]

# Newton steps on x = F(x) until max |F(x) - x| is below this share of max(|x|, 1).
FIXED_POINT_TOLERANCE = 1e-12


@dataclass
class LoopStepMap:
    """The loop's one-step map at its contact equilibrium."""

    loop: SpatialLoop
    context: Context  # at the equilibrium
    names: list[str]  # the kept states, in A's order
    left_out: list[str]  # the states that feed nothing
    A: np.ndarray
    residual: float  # max |F(x*) - x*| over the kept states
    period: float


def _state_names(loop: SpatialLoop, context: Context) -> list[str]:
    """'system[i]' for every discrete state, in the diagram's order; the plant's by name."""
    names = []
    plant_names = list(loop.plant.GetStateNames(False))
    for system in loop.diagram.GetSystems():
        sub = system.GetMyContextFromRoot(context)
        for group in range(sub.num_discrete_state_groups()):
            size = sub.get_discrete_state(group).size()
            if system is loop.plant:
                names += plant_names
            else:
                names += [f"{system.get_name()}.{group}[{i}]" for i in range(size)]
    return names


class _Stepper:
    """F(x) and dF/dx: one step h of the loop converted to AutoDiffXd, from the discrete
    state x."""

    def __init__(self, loop: SpatialLoop, equilibrium: Context, period: float) -> None:
        self._time = equilibrium.get_time()
        self._period = period
        self._diagram = loop.diagram.ToAutoDiffXd()
        self._context = self._diagram.CreateDefaultContext()
        self._simulator = Simulator_[AutoDiffXd](self._diagram, self._context)
        self._groups = equilibrium.num_discrete_state_groups()
        self._sizes = [equilibrium.get_discrete_state(i).size() for i in range(self._groups)]

    def state(self, context: Context) -> np.ndarray:
        return np.concatenate(
            [context.get_discrete_state(i).CopyToVector() for i in range(self._groups)]
        )

    def set_state(self, context: Context, x) -> None:
        start = 0
        for group, size in enumerate(self._sizes):
            context.SetDiscreteState(group, x[start : start + size])
            start += size

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(F(x), dF/dx)."""
        self._context.SetTime(self._time)
        self.set_state(self._context, InitializeAutoDiff(np.asarray(x, dtype=float)).ravel())
        self._simulator.Initialize()
        self._simulator.AdvanceTo(self._time + self._period)
        following = self.state(self._context)
        return ExtractValue(following).ravel(), ExtractGradient(following)


def _with_gamma(scenario: SpatialScenario, gamma: float) -> SpatialScenario:
    varied = copy.deepcopy(scenario)
    varied.admittance.gamma = gamma
    return varied


def _at_rest(loop: SpatialLoop, context: Context, scenario: SpatialScenario) -> bool:
    """The arm still (joint speeds under 1e-3 rad/s) and pressing Fr (within 1 %)."""
    plant = loop.plant
    speeds = plant.GetVelocities(plant.GetMyContextFromRoot(context))
    table = loop.table_force
    force = table.contact_force_output.Eval(table.GetMyContextFromRoot(context))[0]
    return bool(
        np.all(np.isfinite(speeds))
        and np.max(np.abs(speeds)) < 1e-3
        and abs(force - scenario.force_reference) < 0.01 * scenario.force_reference
    )


def settle_spatial_loop(scenario: SpatialScenario) -> tuple[SpatialLoop, Context]:
    """The analysis loop of `scenario` near its contact equilibrium: the scenario run from
    its start to its end (the press holds its plan and Fr from the press's start on).

    The equilibrium does not depend on Gamma (F = Fr, the same Xr), so a run that does
    not come to rest (a Gamma past the critical one, whose linearization is wanted all
    the more) is run again at a quarter of its Gamma, and again, up to 1/1024, and its
    state carried to the scenario's Gamma.

    Raises:
        ScenarioError: no run comes to rest in contact.
    """
    gamma = scenario.admittance.gamma
    for divisor in (1, 4, 16, 64, 256, 1024):
        trial = _with_gamma(scenario, gamma / divisor)
        loop = BuildSpatialLoop(trial, analysis=True)
        context = loop.diagram.CreateDefaultContext()
        SetSpatialInitialConditions(loop, context)
        try:
            Simulator(loop.diagram, context).AdvanceTo(scenario.duration)
        except RuntimeError:  # the contact solver gave up on a diverging run
            continue
        if _at_rest(loop, context, trial):
            if divisor == 1:
                return loop, context
            return _transfer_state(loop, context, gamma / divisor, scenario, gamma)
    raise ScenarioError(
        f"scenario: the press does not come to rest in contact by duration = "
        f"{scenario.duration:g} s, at admittance.gamma or down to 1/1024 of it: no "
        "equilibrium to linearize at (a longer duration may let it settle)"
    )


def _feeds_nothing(A: np.ndarray) -> np.ndarray:
    """Indices j whose column of A is the unit vector e_j."""
    unit = np.eye(A.shape[0])
    return np.array([j for j in range(A.shape[1]) if np.allclose(A[:, j], unit[:, j], atol=0)])


def loop_step_map(
    scenario: SpatialScenario, *, start: tuple[SpatialLoop, Context] | None = None
) -> LoopStepMap:
    """The loop's one-step map at its contact equilibrium.

    The equilibrium is the scenario's own run to its end (or `start`, a loop and a context
    near it), polished by Newton steps on x = F(x) over the kept states.

    Raises:
        ScenarioError: no run comes to rest in contact, or Newton's steps do not converge.
    """
    loop, settled = start if start is not None else settle_spatial_loop(scenario)
    period = scenario.time_step
    stepper = _Stepper(loop, settled, period)
    x = stepper.state(settled)
    following, A = stepper(x)
    left_out = _feeds_nothing(A)
    kept = np.setdiff1d(np.arange(x.size), left_out)
    tolerance = FIXED_POINT_TOLERANCE * max(1.0, float(np.max(np.abs(x[kept]))))
    for _ in range(8):
        residual = float(np.max(np.abs((following - x)[kept])))
        if residual < tolerance:
            break
        block = A[np.ix_(kept, kept)] - np.eye(kept.size)
        x[kept] -= np.linalg.lstsq(block, (following - x)[kept], rcond=None)[0]
        following, A = stepper(x)
    residual = float(np.max(np.abs((following - x)[kept])))
    if not math.isfinite(residual) or residual > 1e-6 * max(1.0, float(np.max(np.abs(x)))):
        raise ScenarioError(
            f"scenario: Newton's steps found no contact equilibrium near the run's end (max "
            f"|F(x) - x| = {residual:.3g}): nothing to linearize at"
        )
    equilibrium = settled.Clone()
    stepper.set_state(equilibrium, x)
    names = _state_names(loop, settled)
    return LoopStepMap(
        loop=loop,
        context=equilibrium,
        names=[names[j] for j in kept],
        left_out=[names[j] for j in left_out],
        A=A[np.ix_(kept, kept)],
        residual=residual,
        period=period,
    )


def _transfer_state(
    source: SpatialLoop,
    source_context: Context,
    source_gamma: float,
    scenario: SpatialScenario,
    gamma: float,
) -> tuple[SpatialLoop, Context]:
    """The analysis loop of `scenario` at `gamma` with the state of `source` (a loop at
    `source_gamma`): the same Xr, so the law's integral z = Xr / (Gamma K) scales by
    source_gamma / gamma (alpha's term is zero at rest)."""
    loop = BuildSpatialLoop(_with_gamma(scenario, gamma), analysis=True)
    # A context of another diagram: its time and each system's discrete states, not its
    # geometry (its own SceneGraph's ids) nor the plant's memory of its last step (which
    # its first step rewrites before anything reads it).
    context = loop.diagram.CreateDefaultContext()
    context.SetTime(source_context.get_time())
    for system in loop.diagram.GetSystems():
        target = system.GetMyMutableContextFromRoot(context)
        if target.num_discrete_state_groups() == 0 or not source.diagram.HasSubsystemNamed(
            system.get_name()
        ):
            continue
        held = source.diagram.GetSubsystemByName(system.get_name()).GetMyContextFromRoot(
            source_context
        )
        for group in range(target.num_discrete_state_groups()):
            target.SetDiscreteState(group, held.get_discrete_state(group).CopyToVector())
    law_context = loop.admittance.GetMyMutableContextFromRoot(context)
    integral = law_context.get_discrete_state(0).CopyToVector()
    law_context.SetDiscreteState(0, integral * source_gamma / gamma)
    return loop, context


def _context_at_gamma(
    equilibrium: LoopStepMap, scenario: SpatialScenario, gamma: float
) -> tuple[SpatialLoop, Context]:
    """The analysis loop at `gamma` with the equilibrium's state (at the scenario's Gamma)."""
    return _transfer_state(
        equilibrium.loop, equilibrium.context, scenario.admittance.gamma, scenario, gamma
    )


def equilibrium_force(equilibrium: LoopStepMap) -> float:
    """The force along the planned normal over one step from the equilibrium, N."""
    context = equilibrium.context.Clone()
    simulator = Simulator(equilibrium.loop.diagram, context)
    simulator.AdvanceTo(context.get_time() + equilibrium.period)
    table = equilibrium.loop.table_force
    return float(table.contact_force_output.Eval(table.GetMyContextFromRoot(context))[0])


def loop_critical_gamma(
    scenario: SpatialScenario, equilibrium: LoopStepMap, low: float, high: float
) -> float | None:
    """The smallest Gamma in [low, high] at which the whole loop's map reaches spectral
    radius 1 (log bisection, analysis.linear.critical_gain), each map at its own equilibrium
    (the same forces and Xr; its Newton steps polish it)."""

    def matrix(gamma: float) -> np.ndarray:
        start = _context_at_gamma(equilibrium, scenario, gamma)
        return loop_step_map(_with_gamma(scenario, gamma), start=start).A

    return critical_gain(matrix, low, high, period=scenario.time_step)


def confirm_loop_critical_gamma(
    scenario: SpatialScenario,
    equilibrium: LoopStepMap,
    critical: float,
    factors=(0.95, 1.05),
    *,
    offset_step: float = 1e-4,
    duration: float = 2.0,
) -> list[dict]:
    """The nonlinear loop at factor x `critical`, started AT the contact equilibrium with
    the law's offset Xr stepped by `offset_step` (m): a local test, as the linearization
    is. (A run from the scenario's start tests more: its impact can throw the tool off the
    table into a bouncing cycle that no linearization at rest describes.)

    A run is STABLE when the force error's amplitude over its last quarter is below half
    of its first quarter's (the disturbance decays), otherwise unstable.
    """
    outcomes = []
    for factor in factors:
        gamma = factor * critical
        loop, context = _context_at_gamma(equilibrium, scenario, gamma)
        law_context = loop.admittance.GetMyMutableContextFromRoot(context)
        integral = law_context.get_discrete_state(0).CopyToVector()
        gain = gamma * float(scenario.pid.kp[NORMAL_AXIS])
        law_context.SetDiscreteState(0, integral + offset_step / gain)
        simulator = Simulator(loop.diagram, context)
        start, steps = context.get_time(), int(round(duration / scenario.time_step))
        force = np.empty(steps)
        table = loop.table_force
        for k in range(steps):
            simulator.AdvanceTo(start + (k + 1) * scenario.time_step)
            force[k] = table.contact_force_output.Eval(table.GetMyContextFromRoot(context))[0]
        error = np.abs(force - scenario.force_reference)
        quarter = steps // 4
        first, last = float(np.max(error[:quarter])), float(np.max(error[-quarter:]))
        outcomes.append(
            {
                "factor": factor,
                "gamma": gamma,
                "stable": bool(last < 0.5 * first),
                "amplitude_first_quarter": first,
                "amplitude_last_quarter": last,
            }
        )
    return outcomes
