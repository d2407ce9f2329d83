"""The safety layer's numbers that do not depend on the law's state: the apparent mass of a
task axis, and the speeds toward a wall reported stiffer than stated (docs/safety.md).

**The apparent mass along the normal.** A force f along the normal row j of the task
Jacobian J meets one of two masses (contact_model.apparent_mass for the first):

* the free axes' mass, m_free = 1 / (j M^-1 j^T): the other task coordinates move freely
  under the impact (no controller holds them on its time scale);
* the held axes' mass, m_held = Lambda_nn, Lambda = (J M^-1 J^T)^-1 the task-space
  inertia: the other task coordinates are held rigidly while the normal one moves.

Holding the other coordinates only adds constraints, so m_held >= m_free (Lambda_nn is the
minimum of u^T Lambda u over e_n^T u = 1 without a constraint on the others, 1 /
(Lambda^-1)_nn, with them held at u = e_n). The impact bound v_max = Fmax / (F_peak / v)
falls as the mass grows (F_peak / v grows as sqrt(m) on a stiff wall), so m_held is the
cautious choice wherever the PID holds the other axes stiffly: the spatial arm's, whose
PID holds x, y and the orientation (Panda at its press: 6.64 kg held against 4.95 kg
free). The paper's planar arm keeps the free axes' mass (its x, y, theta all but pinned
by the wall's normal, and the layer's measured figures rest on it).

A payload m_p at the contact point adds m_p J_t^T J_t to M (J_t the point's translational
rows), in both.
"""

from __future__ import annotations

import numpy as np

from admittance.systems import contact_model

__all__ = ["SafetyNumbers", "backed_off", "task_apparent_mass"]


class SafetyNumbers(dict):
    """The derived numbers of the layer at one state (apparent mass, c, v_max, ...)."""


def backed_off(approach_speed, advance_speed, max_force, force_reference):
    """The command's speeds toward the wall once it is reported stiffer than stated
    (docs/safety.md, section 7): both at most v_f = v_max (Fmax - Fr) / Fmax, the speed
    whose impact, on top of Fr, peaks at Fmax on a wall of the estimate's stiffness."""
    follow = approach_speed * max(max_force - force_reference, 0.0) / max_force
    return min(approach_speed, follow), min(advance_speed, follow)


def task_apparent_mass(
    mass_matrix,
    jacobian,
    axis: int,
    *,
    translational_rows,
    payload_mass: float = 0.0,
    held_axes: bool = False,
) -> float:
    """The mass along task axis `axis`, kg: 1 / (j M^-1 j^T), or with `held_axes`
    Lambda_nn of Lambda = (J M^-1 J^T)^-1 (module docstring).

    Args:
        mass_matrix: M(q), nv x nv.
        jacobian: J, m x nv (float values).
        axis: the normal's row in J.
        translational_rows: the rows of J that are the point's translation (for m_p).
        payload_mass: m_p at the point, kg.
        held_axes: the other task axes held (Lambda_nn) rather than free.
    """
    jacobian = np.asarray(jacobian, dtype=float)
    rows = jacobian[list(translational_rows)]
    if not held_axes:
        return contact_model.apparent_mass(
            mass_matrix, jacobian[axis], payload_mass=payload_mass, translational_jacobian=rows
        )
    inertia = np.asarray(mass_matrix, dtype=float)
    if payload_mass > 0.0:
        inertia = inertia + payload_mass * rows.T @ rows
    mobility = jacobian @ np.linalg.solve(inertia, jacobian.T)
    return float(np.linalg.inv(mobility)[axis, axis])
