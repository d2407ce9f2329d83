"""The safety layer's numbers that do not depend on the law's state: the safe law's given
numbers (``SafeAdmittanceParams``), those it derives from them at a state of the arm
(``derived_numbers``: the apparent mass of a task axis, the injected damper, the speeds
toward the wall and the critical gain), and the speeds toward a wall reported stiffer
than stated (docs/evidence/safety.md).

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

import math
from dataclasses import dataclass, fields

import numpy as np

from admittance.systems import contact_model
from admittance.systems.sampled_loop import SampledContactLoop

__all__ = [
    "SafeAdmittanceParams",
    "SafetyNumbers",
    "backed_off",
    "derived_numbers",
    "task_apparent_mass",
]

# The numbers that must be finite and > 0, and finite and >= 0, in this order.
_POSITIVE = (
    "gamma",
    "stiffness",
    "pid_kp",
    "max_force",
    "force_bound_gain",
    "max_push",
    "max_stiffness",
    "damping_ratio",
    "stability_margin",
    "contact_force",
    "detection_delay",
    "schedule_time_constant",
)
_NONNEGATIVE = ("alpha", "pid_kd", "filter_time_constant", "payload_mass", "period", "latency")


@dataclass(frozen=True)
class SafeAdmittanceParams:
    """The safe law's numbers (systems/safe_admittance.py, whose docstring derives each use).
    Every number is kept as a float, ``held_axes`` as a bool.

    Attributes:
        gamma, alpha, stiffness: Gamma, alpha and K of eq. 10 (K = the PID's Kp).
        pid_kp, pid_kd: the PID's gains along the normal, N/m and N s/m.
        max_force: Fmax, N (finite).
        force_bound_gain: mu of the force-bound penalty.
        max_push: the bound of Xr into the wall around Xd, m (the layer has no bound on
            the retract side: only the arm's reach).
        max_stiffness: Ke_max, the stated upper bound on the wall stiffness, N/m.
        damping_ratio: zeta_target of the contact mode at Ke_max.
        stability_margin: the factor between Gamma* and the scheduled Gamma.
        filter_time_constant: tau of the sensor's filter, s (0 = ideal sensor).
        contact_force: F_c, N.
        detection_delay: t_d, the fault detector's longest delay, s.
        schedule_time_constant: tau_g, s.
        payload_mass: m_p, an unmodelled payload or tool at the contact point, kg
            (>= 0): added to the plant's M(q) as a point mass there.
        period: h, the controller's period, s (0 = the continuous law).
        latency: L, how late the reading reaches the law, s (used with h > 0).
        backoff_stiffness: above this estimate (a wall reported stiffer than stated) the
            command moves toward the wall at most at v_f = v_max (Fmax - Fr) / Fmax, in
            contact and in free motion, N/m.
        held_axes: the apparent mass with the other task axes held, Lambda_nn of
            (J M^-1 J^T)^-1, rather than free, 1 / (j M^-1 j^T) (module docstring).
    """

    gamma: float
    alpha: float
    stiffness: float
    pid_kp: float
    pid_kd: float
    max_force: float
    force_bound_gain: float
    max_push: float
    max_stiffness: float
    damping_ratio: float
    stability_margin: float
    filter_time_constant: float
    contact_force: float
    detection_delay: float
    schedule_time_constant: float = 0.005
    payload_mass: float = 0.0
    period: float = 0.0
    latency: float = 0.0
    backoff_stiffness: float = math.inf
    held_axes: bool = False

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            kind = bool if field.name == "held_axes" else float
            object.__setattr__(self, field.name, kind(value))

    def check(self) -> None:
        """Raises ValueError naming the first number out of its range."""
        for name in _POSITIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        for name in _NONNEGATIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")


class SafetyNumbers(dict):
    """The derived numbers of the layer at one state (apparent mass, c, v_max, ...)."""


def backed_off(approach_speed, advance_speed, max_force, force_reference):
    """The command's speeds toward the wall once it is reported stiffer than stated
    (docs/evidence/safety-beyond-bounds.md, section 7): both at most v_f = v_max (Fmax - Fr) /
    Fmax, the speed
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


def derived_numbers(
    params: SafeAdmittanceParams,
    mass_matrix,
    jacobian,
    axis: int,
    *,
    translational_rows,
    stiffness_estimate: float,
    force_reference: float,
) -> SafetyNumbers:
    """The safe law's schedule at one state of the arm, from M(q) and J (float values):
    the apparent mass m along the normal row `axis` of J (with the payload), the injected
    damper c, the approach speed v_max, the advance speed v_adv, the critical Gamma* at
    `stiffness_estimate` and the schedule's target s* (systems/safe_admittance.py)."""
    mass = task_apparent_mass(
        mass_matrix,
        jacobian,
        axis,
        translational_rows=translational_rows,
        payload_mass=params.payload_mass,
        held_axes=params.held_axes,
    )
    kp, kd, max_force = params.pid_kp, params.pid_kd, params.max_force
    # Beyond the stated bound (docs/evidence/safety-beyond-bounds.md, section 7): on a wall the
    # estimate shows
    # stiffer than Ke_max, the approach speed is the estimate's (any re-contact peaks under
    # Fmax there); the damper stays Ke_max's.
    stiffest = max(params.max_stiffness, stiffness_estimate)
    damping = contact_model.injected_damping(
        mass, kp, kd, params.max_stiffness, params.damping_ratio
    )
    total_damping = kd + damping
    approach_speed = contact_model.safe_approach_speed(max_force, mass, kp, total_damping, stiffest)
    overshoot = contact_model.step_overshoot(
        contact_model.damping_ratio(mass, kp, total_damping, stiffest)
    )
    advance_speed = max(max_force - force_reference, 0.0) / (
        kp * (params.alpha + params.detection_delay) * (1.0 + overshoot)
    )
    if stiffness_estimate > params.backoff_stiffness:
        approach_speed, advance_speed = backed_off(
            approach_speed, advance_speed, max_force, force_reference
        )
    critical = _critical_gamma(params, mass, total_damping, stiffness_estimate)
    return SafetyNumbers(
        apparent_mass=mass,
        payload_mass=params.payload_mass,
        injected_damping=damping,
        approach_speed=approach_speed,
        advance_speed=advance_speed,
        critical_gamma=critical,
        schedule_target=min(1.0, critical / (params.stability_margin * params.gamma)),
    )


def _critical_gamma(params: SafeAdmittanceParams, mass, damping, stiffness_estimate) -> float:
    """Gamma* of the reduced loop on a wall of `stiffness_estimate`: the sampled loop's
    with the reading's latency at a period h > 0, Routh-Hurwitz's otherwise."""
    if params.period > 0:
        loop = SampledContactLoop(
            mass,
            params.pid_kp,
            damping,
            params.alpha,
            params.filter_time_constant,
            params.stiffness,
            params.period,
        )
        return loop.rounded().critical_gamma(float(f"{stiffness_estimate:.2e}"), params.latency)
    return contact_model.critical_gamma(
        stiffness_estimate,
        mass=mass,
        kp=params.pid_kp,
        kd=damping,
        alpha=params.alpha,
        filter_time_constant=params.filter_time_constant,
        admittance_stiffness=params.stiffness,
    )
