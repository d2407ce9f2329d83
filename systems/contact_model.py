"""The reduced contact model behind the safety layer: one mass on the wall's spring.

Along the wall normal the fingertip is a mass m (the arm's apparent mass at the fingertip,
from the plant's mass matrix M and Jacobian J: m = 1 / (j M^-1 j^T), j the normal row of J)
held by the Cartesian PID's spring Kp and damper Kd, pressing a wall of stiffness Ke:

    m x'' + Kd x' + (Kp + Ke) x = Kp Xc            (x the penetration, F = Ke x)

The PID's integral is slow (Kp / Ki >= 10 s here) and is left out. Three results of this
model set the safety layer's numbers (docs/evidence/safety.md derives and measures each):

**Impact (first contact).** A tip that approaches at speed v, with its reference moving at
v, leads the reference by Kd v / Kp (the D term acts on the tip's own speed: the PID's
commanded velocity is dXd/dt only), so it meets the wall with the pre-load Kd v. With
w = sqrt((Kp + Ke) / m) and zeta = Kd / (2 sqrt(m (Kp + Ke))) < 1, the penetration is

    x(t) = L [1 - e^(-zeta w t) (cos wd t + zeta w / wd sin wd t)] + v / wd e^(-zeta w t) sin wd t,

L = Kd v / (Kp + Ke) = 2 zeta v / w, wd = w sqrt(1 - zeta^2). Its first maximum is where
tan(wd t) = -sqrt(1 - zeta^2) / zeta, i.e. wd t* = pi - acos(zeta), and there

    F_peak = Ke x(t*) = v (Ke / w) [2 zeta + exp(-zeta (pi - acos zeta) / sqrt(1 - zeta^2))]

(for zeta >= 1 the tip creeps in without overshoot: F_peak = Ke L). F_peak / v grows with
Ke, so a bound Ke_max on the wall's stiffness bounds the impact of every softer wall, and

    v_max = Fmax / (F_peak / v at Ke_max)                           (safe_approach_speed)

is the fastest approach whose first contact stays under Fmax.

**Bounce.** The next minimum, at wd t = 2 pi - acos(zeta), is

    x_min = (v / w) [2 zeta - exp(-zeta (2 pi - acos zeta) / sqrt(1 - zeta^2))],

negative (the tip leaves the wall) below zeta* = 0.1918 whatever v is: on a stiff wall
the pre-load Kd v, which grows with v like the impact does, is too small a share of it. The
safety layer therefore adds damping c along the normal until zeta >= zeta_target > zeta*
at Ke_max (injected_damping); below Ke_max zeta is larger still.

**Stability of the force loop.** With the sensor's first-order filter (time constant tau)
and the admittance law Xr = Gamma K (1/s + alpha)(Fr - F_measured), the loop's
characteristic polynomial is

    s (m s^2 + Kd s + Kp + Ke)(tau s + 1) + g (alpha s + 1),    g = Gamma K Kp Ke,

and Routh-Hurwitz gives the largest stable loop gain g* in closed form (critical_loop_gain).
For Ke >> Kp its binding term is Kd > tau g alpha: Gamma_critical x Ke is constant, as the
full linearization finds. Against Drake's Linearize of the whole loop this reduced model's
critical Gamma is 10-20 % lower (more cautious) from Ke = 1e3 to 1e7 N/m, for both gain
sets of the built-in scenarios (tests/test_safety_model.py).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "BOUNCE_FREE_DAMPING_RATIO",
    "apparent_mass",
    "bounce_minimum",
    "critical_gamma",
    "critical_loop_gain",
    "damping_ratio",
    "impact_peak_force",
    "injected_damping",
    "safe_approach_speed",
    "step_overshoot",
]


def apparent_mass(
    mass_matrix, jacobian_row, *, payload_mass: float = 0.0, translational_jacobian=None
) -> float:
    """m = 1 / (j M^-1 j^T): the mass a force along the row's direction meets, kg.

    A payload m_p (a tool or a grasped part the plant does not model) is a point mass at
    the fingertip: its kinetic energy m_p |p'|^2 / 2 adds m_p J_t^T J_t to M, J_t the
    fingertip point's translational rows of J. The apparent mass then grows by at least
    m_p: 1 / (e^T A^-1 e) = min over e^T u = 1 of u^T A u (A the task-space inertia), which
    is superadditive, and the payload's own term is m_p (1 + u_y^2) >= m_p.

    Args:
        mass_matrix: the plant's M(q), nv x nv (symmetric positive definite).
        jacobian_row: j, the row of the task Jacobian along the wall normal (nv,).
        payload_mass: m_p, kg (>= 0).
        translational_jacobian: J_t (2 x nv or 3 x nv), needed when payload_mass > 0.
    """
    row = np.asarray(jacobian_row, dtype=float)
    inertia = np.asarray(mass_matrix, dtype=float)
    if payload_mass > 0.0:
        rows = np.asarray(translational_jacobian, dtype=float)
        inertia = inertia + payload_mass * rows.T @ rows
    return 1.0 / float(row @ np.linalg.solve(inertia, row))


def damping_ratio(mass: float, kp: float, kd: float, stiffness: float) -> float:
    """zeta = Kd / (2 sqrt(m (Kp + Ke))) of the contact mode."""
    return kd / (2.0 * math.sqrt(mass * (kp + stiffness)))


def _peak_per_speed(mass: float, kp: float, kd: float, stiffness: float) -> float:
    """x(t*) / v of the impact (module docstring), s."""
    omega = math.sqrt((kp + stiffness) / mass)
    zeta = damping_ratio(mass, kp, kd, stiffness)
    if zeta >= 1.0:
        return 2.0 * zeta / omega
    root = math.sqrt(1.0 - zeta * zeta)
    return (2.0 * zeta + math.exp(-zeta * (math.pi - math.acos(zeta)) / root)) / omega


def impact_peak_force(speed: float, mass: float, kp: float, kd: float, stiffness: float) -> float:
    """F_peak of a first contact at `speed` (m/s) on a wall of `stiffness` (N/m), N."""
    return stiffness * speed * _peak_per_speed(mass, kp, kd, stiffness)


def bounce_minimum(speed: float, mass: float, kp: float, kd: float, stiffness: float) -> float:
    """x_min, the penetration at the first minimum after the impact, m (< 0: a bounce)."""
    omega = math.sqrt((kp + stiffness) / mass)
    zeta = damping_ratio(mass, kp, kd, stiffness)
    if zeta >= 1.0:
        return 2.0 * zeta * speed / omega  # no oscillation: the tip stays at L
    root = math.sqrt(1.0 - zeta * zeta)
    decay = math.exp(-zeta * (2.0 * math.pi - math.acos(zeta)) / root)
    return speed / omega * (2.0 * zeta - decay)


def _bounce_free_damping_ratio() -> float:
    """zeta* where x_min = 0: 2 zeta = exp(-zeta (2 pi - acos zeta) / sqrt(1 - zeta^2))."""
    low, high = 0.01, 0.9
    for _ in range(100):
        middle = 0.5 * (low + high)
        root = math.sqrt(1.0 - middle * middle)
        excess = 2.0 * middle - math.exp(-middle * (2.0 * math.pi - math.acos(middle)) / root)
        low, high = (low, middle) if excess > 0 else (middle, high)
    return 0.5 * (low + high)


#: Below this damping ratio of the contact mode a first contact always bounces (0.1918).
BOUNCE_FREE_DAMPING_RATIO = _bounce_free_damping_ratio()


def injected_damping(
    mass: float, kp: float, kd: float, max_stiffness: float, target_ratio: float
) -> float:
    """c >= 0 such that (Kd + c) gives the contact mode `target_ratio` at Ke_max, N s/m."""
    return max(0.0, 2.0 * target_ratio * math.sqrt(mass * (kp + max_stiffness)) - kd)


def safe_approach_speed(
    max_force: float, mass: float, kp: float, kd: float, max_stiffness: float
) -> float:
    """v_max: the approach speed whose impact on a wall of Ke_max peaks at Fmax, m/s."""
    return max_force / (max_stiffness * _peak_per_speed(mass, kp, kd, max_stiffness))


def step_overshoot(ratio: float) -> float:
    """Overshoot of a second-order step response, exp(-zeta pi / sqrt(1 - zeta^2))."""
    if ratio >= 1.0:
        return 0.0
    return math.exp(-ratio * math.pi / math.sqrt(1.0 - ratio * ratio))


def critical_loop_gain(
    mass: float, kp: float, kd: float, stiffness: float, alpha: float, filter_time_constant: float
) -> float:
    """g* = (Gamma K Kp Ke)_critical of the reduced loop (Routh-Hurwitz), N/m per s.

    The coefficients of s (m s^2 + Kd s + Kt)(tau s + 1) + g (alpha s + 1), Kt = Kp + Ke,
    are a4 = m tau, a3 = m + Kd tau, a2 = Kd + Kt tau, a1 = Kt + alpha g, a0 = g; with
    A = a3 a2 - a4 Kt and B = a4 alpha the Hurwitz determinants are
    D2 = A - B g and D3 = D2 a1 - a3^2 g = -B alpha g^2 + (A alpha - B Kt - a3^2) g + A Kt.
    D3 > 0 implies D2 > 0, so g* is D3's positive root (inf if D3 never changes sign).
    """
    total = kp + stiffness
    tau = filter_time_constant
    a3 = mass + kd * tau
    a2 = kd + total * tau
    big_a = a3 * a2 - mass * tau * total
    big_b = mass * tau * alpha
    linear = big_a * alpha - big_b * total - a3 * a3
    quadratic = big_b * alpha
    if quadratic > 0:
        return (linear + math.sqrt(linear * linear + 4.0 * quadratic * big_a * total)) / (
            2.0 * quadratic
        )
    if linear >= 0:
        return math.inf
    return big_a * total / -linear


def critical_gamma(
    stiffness: float,
    *,
    mass: float,
    kp: float,
    kd: float,
    alpha: float,
    filter_time_constant: float,
    admittance_stiffness: float,
) -> float:
    """Gamma* = g* / (K Kp Ke) of the reduced loop (K = the law's K, usually Kp)."""
    gain = critical_loop_gain(mass, kp, kd, stiffness, alpha, filter_time_constant)
    return gain / (admittance_stiffness * kp * stiffness)
