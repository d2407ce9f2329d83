"""The grasp's map over one period, x[k+1] = f(x[k]), and what is read off it.

x is every numeric discrete state of the grasp's diagram (``get_discrete_state``); f is one
step of Drake's Simulator from a context at a sample time (``step_once``), A = df/dx its
central differences (``step_jacobian``). Each finger's Gamma scales one row of A, its held
offset's (``offset_rows``, ``matrix_at_gammas``). The hand's near-neutral modes (the
brick's free directions, growth rates below NEUTRAL_RESOLUTION) are left out where their
sign is not resolved (``without_near_neutral_modes``). The method is described in the
package's :mod:`.analysis`.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context

from admittance.diagrams.robots.planar_gripper.loop import GraspLoop
from admittance.diagrams.robots.planar_gripper.plant import NORMAL_AXIS

__all__ = [
    "NEUTRAL_RESOLUTION",
    "RELATIVE_STEP",
    "get_discrete_state",
    "matrix_at_gammas",
    "offset_rows",
    "resolved_basis",
    "set_discrete_state",
    "step_jacobian",
    "step_once",
    "stepped_forces",
    "without_near_neutral_modes",
]

# Central differences: the step of state entry j is RELATIVE_STEP max(|x_j|, 1).
RELATIVE_STEP = 1e-6
# The method's resolution of a growth rate, 1/s: modes slower than 100 s (ten times the
# hold) are the hand's near-neutral directions (below); their sign is not resolved.
NEUTRAL_RESOLUTION = 0.01


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


def step_jacobian(loop: GraspLoop, context: Context, relative_step: float) -> np.ndarray:
    """A = df/dx at `context`'s discrete state: central differences of one step, the
    step of entry j relative_step max(|x_j|, 1)."""
    x = get_discrete_state(context)
    A = np.empty((x.size, x.size))
    for j in range(x.size):
        delta = relative_step * max(abs(x[j]), 1.0)
        plus, minus = x.copy(), x.copy()
        plus[j] += delta
        minus[j] -= delta
        A[:, j] = (step_once(loop, context, plus) - step_once(loop, context, minus)) / (2 * delta)
    return A


def stepped_forces(loop: GraspLoop, context: Context) -> np.ndarray:
    """The normal forces of the step from `context` (the plant's sampled contact results
    after it): at a fixed point, the forces of the held grasp."""
    working = context.Clone()
    simulator = Simulator(loop.diagram, working)
    simulator.Initialize()
    simulator.AdvanceTo(working.get_time() + loop.scenario.time_step)
    sensor = loop.contact_sensor
    return sensor.normal_force_output.Eval(sensor.GetMyContextFromRoot(working)).copy()


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


def _near_neutral(eigenvalues: np.ndarray, period: float) -> np.ndarray:
    """Which z have a growth rate |ln|z|| / period below NEUTRAL_RESOLUTION (a growing
    mode faster than that is not near-neutral: it stays in the analysis)."""
    magnitude = np.abs(eigenvalues)
    growth = np.full(magnitude.shape, np.inf)
    growth[magnitude > 0] = np.abs(np.log(magnitude[magnitude > 0])) / period
    return growth < NEUTRAL_RESOLUTION


def resolved_basis(A: np.ndarray, period: float) -> np.ndarray:
    """An orthonormal basis of the invariant subspace without the near-neutral modes."""
    eigenvalues, left = np.linalg.eig(A.T)
    neutral = _near_neutral(eigenvalues, period)
    if not np.any(neutral):
        return np.eye(A.shape[0])
    vectors = left[:, neutral]
    _, singular, rows = np.linalg.svd(np.vstack([vectors.real.T, vectors.imag.T]))
    rank = int(np.count_nonzero(singular > 1e-10 * singular[0]))
    return rows[rank:].T


def without_near_neutral_modes(A: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """A on the invariant subspace that leaves out its near-neutral modes (|ln|z|| / period
    below NEUTRAL_RESOLUTION), and their eigenvalues z.

    The subspace is the null space of those modes' left eigenvectors (Y^T A = Z Y^T, so
    Y^T x = 0 stays 0 under A); on an orthonormal basis U of it, A acts as U^T A U.
    """
    eigenvalues = np.linalg.eigvals(A)
    neutral = eigenvalues[_near_neutral(eigenvalues, period)]
    basis = resolved_basis(A, period)
    return basis.T @ A @ basis, neutral
