"""The collision check of the sensor monitor: the joint torque no contact force explains.

A contact force F along the normal at the contact point gives the external joint torque
r = -F j, j = J_n^T (the normal row of the point's Jacobian), whatever the sensor reads;
a contact that can also load other task axes (a tool on a table, with friction) gives
r = -R^T f for the rows R of those axes. So

    r_perp = r - (its projection on the span of j, or of the columns of R^T)

is zero for any contact force and any sensor fault (a fault changes the reading, never
r), and a torque on a link shows in it. The monitor (systems/fault_detector.py) takes
|r_perp| beyond the torque of a force error at its base tolerance F_tol as evidence of a
collision (docs/evidence/safety-collision.md, "The collision reflex", derives it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["collision_tolerance", "contact_torque_check", "unexplained_torque"]


def unexplained_torque(residual, normal_row) -> float:
    """|r_perp|, N m: the norm of the part of the external joint torque r that no force at
    the contact point along the normal explains (r minus its projection on j = J_x^T).

    `normal_row` may be several rows R of the task Jacobian (the force axes a contact at
    the point can load: a tool's x, y and z, friction included): r_perp is then r minus its
    projection on the columns of R^T."""
    return contact_torque_check(residual, normal_row, 0.0)[0]


def collision_tolerance(normal_row, force_tolerance: float) -> float:
    """|j| F_tol, N m: the largest joint torque a contact force within the plausibility
    check's base tolerance makes; |r_perp| beyond it is evidence of a collision. For
    several rows R, |R^T|_2 F_tol (the largest singular value: the force's worst
    direction)."""
    rows = np.asarray(normal_row, dtype=float)
    if rows.ndim == 1:
        return float(np.linalg.norm(rows)) * force_tolerance
    return float(np.linalg.svd(rows, compute_uv=False)[0]) * force_tolerance


def contact_torque_check(residual, normal_row, force_tolerance: float) -> tuple[float, float]:
    """(|r_perp|, the collision tolerance) of unexplained_torque and collision_tolerance
    at once: one row by its dot products, several by one SVD of R^T (its left singular
    vectors span the explained torques, its largest singular value is |R^T|_2), as the
    monitor evaluates them on every sample."""
    residual = np.asarray(residual, dtype=float)
    rows = np.asarray(normal_row, dtype=float)
    if rows.ndim == 1:
        squared = rows @ rows
        unexplained = residual - rows * (rows @ residual) / squared
        return float(np.linalg.norm(unexplained)), float(np.sqrt(squared)) * force_tolerance
    basis, singular, _ = np.linalg.svd(rows.T, full_matrices=False)
    unexplained = residual - basis @ (basis.T @ residual)
    return float(np.linalg.norm(unexplained)), float(singular[0]) * force_tolerance
