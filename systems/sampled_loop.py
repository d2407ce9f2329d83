"""The reduced contact loop as a 1 kHz controller runs it: sampled, with a delayed reading.

systems/contact_model.py gives the continuous loop's critical Gamma (Routh-Hurwitz). A
digital controller differs in two ways that both add phase lag to the force path:

* **Sampling.** At each tick t_k = k h the Cartesian PID and the law read their inputs and
  hold the PID's force over [t_k, t_k+1) (zero-order hold). Along the normal, with the
  layer's damper c and Xr = Gamma_s K (y + alpha E) - (c / Kp) x', the held force on the
  apparent mass m is, in deviations from the contact equilibrium,

      P_k = Kp Gamma_s K y_k - Kp Gamma_s K alpha F_k - Kp x_k - (Kd + c) x'_k,
      y_k+1 = y_k - h F_k                 (z[k+1] = z[k] + h E[k], E = Fr - F)

  where F_k is the reading the law uses at t_k, while the wall's spring Ke acts between
  the ticks: m x'' = P_k - Ke x, and the sensor's filter tau F_f' = Ke x - F_f.
* **Latency.** The reading at t_k is the filter's output L = n h + r (0 <= r < h) earlier.
  Over one tick the state s = (Ke x, Ke x', F_f) moves exactly as s_k+1 = Phi(h) s_k +
  Gam(h) P_k (Drake's DiscreteTimeApproximation); the reading of t_k - L is then
  C s_k-n (r = 0) or C (Phi(h - r) s_k-n-1 + Gam(h - r) P_k-n-1) (r > 0), a value
  computed one or more ticks ago: the delay enters as N = n (r = 0) or n + 1 (r > 0)
  extra states, a shift register of those values.

The loop is then x_k+1 = M x_k on (s_k, y_k, the N held readings), and it is stable when
the spectral radius of M is below 1: SampledContactLoop.critical_gamma finds the Gamma
where it reaches 1, SampledContactLoop.tolerable_latency the latency where it does at a
given Gamma. As h -> 0 with L = 0 the critical Gamma tends to the Routh-Hurwitz one of
contact_model (1.6 % below it at h = 1 us; tests/test_safety_sampled.py).

The map from one tick to the next is exact for the reduced model (a piecewise-constant
input into a linear plant); what the model leaves out is what contact_model leaves out
(the PID's slow integral, the arm's other modes).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.primitives import LinearSystem

from admittance.systems import contact_model

__all__ = [
    "SampledContactLoop",
    "damper_gain",
    "delayed_damper_limit",
    "sampled_loop_matrix",
    "spectral_radius",
]


def _zero_order_hold(A: np.ndarray, B: np.ndarray, duration: float):
    """Phi(duration), Gam(duration) of ds/dt = A s + B u with u held (Drake's exact ZOH)."""
    if duration <= 0.0:
        return np.eye(A.shape[0]), np.zeros((A.shape[0], B.shape[1]))
    system = LinearSystem(A, B, np.zeros((1, A.shape[0])), np.zeros((1, B.shape[1])))
    discrete = DiscreteTimeApproximation(system, duration)
    return discrete.A(), discrete.B()


@dataclass(frozen=True)
class _HeldPlant:
    """One tick of the plant with its input held, and how the delayed reading is taken."""

    Phi: np.ndarray  # s_k+1 = Phi s_k + Gam u_k
    Gam: np.ndarray
    C: np.ndarray  # the reading F = C s
    taken_state: np.ndarray  # the value entering the delay line: taken_state s_k + ...
    taken_input: float  # ... + taken_input u_k
    waiting: int  # N, the values in the delay line
    period: float


def _held_plant(A, B, C, period: float, latency: float) -> _HeldPlant:
    A = np.atleast_2d(np.asarray(A, dtype=float))
    B = np.asarray(B, dtype=float).reshape(-1, 1)
    C = np.asarray(C, dtype=float).reshape(1, -1)
    h = float(period)
    delays = math.floor(latency / h + 1e-9)
    remainder = latency - delays * h
    fractional = remainder > 1e-9 * h
    Phi, Gam = _zero_order_hold(A, B, h)
    if fractional:
        # The value of C s(t_k + h - r), taken this tick and read N ticks later.
        Phi_r, Gam_r = _zero_order_hold(A, B, h - remainder)
        taken_state, taken_input = C @ Phi_r, float((C @ Gam_r)[0, 0])
    else:
        taken_state, taken_input = C, 0.0
    waiting = delays + 1 if fractional else delays
    return _HeldPlant(Phi, Gam, C, taken_state, taken_input, waiting, h)


def _closed_loop(
    plant: _HeldPlant, state_gain, measurement_gain: float, integral_gain: float
) -> np.ndarray:
    n_s = plant.Phi.shape[0]
    with_integral = integral_gain != 0.0
    size = n_s + int(with_integral) + plant.waiting
    # Row vectors over the state: F_k (the reading used at t_k) and u_k.
    reading = np.zeros(size)
    if plant.waiting:
        reading[size - 1] = 1.0
    else:
        reading[:n_s] = plant.C[0]
    control = np.zeros(size)
    control[:n_s] = np.asarray(state_gain, dtype=float)
    if with_integral:
        control[n_s] = integral_gain
    control = control + measurement_gain * reading

    M = np.zeros((size, size))
    M[:n_s, :n_s] = plant.Phi
    M[:n_s] += plant.Gam[:, [0]] * control[np.newaxis, :]
    if with_integral:
        M[n_s] = -plant.period * reading
        M[n_s, n_s] += 1.0
    if plant.waiting:
        first = n_s + int(with_integral)
        M[first, :n_s] = plant.taken_state[0]
        M[first] += plant.taken_input * control
        for index in range(first + 1, size):
            M[index, index - 1] = 1.0
    return M


def sampled_loop_matrix(
    A,
    B,
    C,
    *,
    period: float,
    latency: float,
    state_gain,
    measurement_gain: float,
    integral_gain: float = 0.0,
) -> np.ndarray:
    """M of the sampled loop x_k+1 = M x_k (single input u, single reading F).

    The plant ds/dt = A s + B u holds u over each period h; the reading F = C s reaches
    the controller `latency` L late; the controller at t_k sets

        u_k = state_gain . s_k + measurement_gain F_k + integral_gain y_k,
        y_k+1 = y_k - h F_k         (only when integral_gain != 0)

    with F_k the reading of t_k - L. The state is (s_k, [y_k], the N values waiting in
    the delay line, oldest last) (module docstring).
    """
    plant = _held_plant(A, B, C, period, latency)
    return _closed_loop(plant, state_gain, measurement_gain, integral_gain)


def spectral_radius(M: np.ndarray) -> float:
    """max |eig(M)|: the loop is stable below 1."""
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def _significant(value: float, digits: int = 3) -> float:
    """`value` to `digits` significant digits."""
    return float(f"{value:.{digits - 1}e}") if value != 0.0 else 0.0


@dataclass(frozen=True)
class SampledContactLoop:
    """The reduced contact loop of one arm and gain set, sampled at `period` (module
    docstring). `damping` is the total damping along the normal, Kd + c, N s/m."""

    mass: float
    kp: float
    damping: float
    alpha: float
    filter_time_constant: float
    admittance_stiffness: float
    period: float

    def rounded(self) -> SampledContactLoop:
        """The loop with its mass and damping to 3 significant digits: a key for the cache
        of critical_gamma (the layer asks at every evaluation, with M(q) moving slowly;
        0.1 % moves Gamma* by about as much, far less than its margin)."""
        return SampledContactLoop(
            _significant(self.mass),
            self.kp,
            _significant(self.damping),
            self.alpha,
            self.filter_time_constant,
            self.admittance_stiffness,
            self.period,
        )

    @functools.lru_cache(maxsize=1024)  # noqa: B019 (the instances are small and frozen)
    def _held(self, stiffness: float, latency: float) -> _HeldPlant:
        """The plant over one tick on a wall of `stiffness`, states scaled to forces
        (Ke x, Ke x', F_f): well conditioned from Ke = 1e2 to 1e8 N/m."""
        ke, tau, mass = float(stiffness), self.filter_time_constant, self.mass
        # d(Ke x)/dt = Ke x'; d(Ke x')/dt = (Ke / m) (P - Ke x).
        mechanics = np.array([[0.0, 1.0], [-ke / mass, 0.0]])
        if tau > 0.0:
            A = np.zeros((3, 3))
            A[:2, :2] = mechanics
            A[2] = [1.0 / tau, 0.0, -1.0 / tau]
            C = [0.0, 0.0, 1.0]
        else:
            A, C = mechanics, [1.0, 0.0]
        B = np.zeros(A.shape[0])
        B[1] = ke / mass
        return _held_plant(A, B, C, self.period, latency)

    def matrix(self, gamma: float, stiffness: float, latency: float) -> np.ndarray:
        """M of the loop at Gamma on a wall of `stiffness` with the reading `latency` late."""
        plant = self._held(float(stiffness), float(latency))
        ke = float(stiffness)
        # P = -Kp x - (Kd + c) x' + ...: in the scaled states, -Kp / Ke and -(Kd + c) / Ke.
        state_gain = np.zeros(plant.Phi.shape[0])
        state_gain[:2] = [-self.kp / ke, -self.damping / ke]
        law_gain = self.kp * gamma * self.admittance_stiffness
        # The integral state is Gamma K times the integral of E, N s.
        return _closed_loop(plant, state_gain, -law_gain * self.alpha, law_gain)

    def continuous_critical_gamma(self, stiffness: float) -> float:
        """Gamma* of the same loop run continuously, without latency (Routh-Hurwitz,
        contact_model.critical_gamma)."""
        return contact_model.critical_gamma(
            stiffness,
            mass=self.mass,
            kp=self.kp,
            kd=self.damping,
            alpha=self.alpha,
            filter_time_constant=self.filter_time_constant,
            admittance_stiffness=self.admittance_stiffness,
        )

    def stable(self, gamma: float, stiffness: float, latency: float) -> bool:
        """Spectral radius below 1."""
        return spectral_radius(self.matrix(gamma, stiffness, latency)) < 1.0

    @functools.lru_cache(maxsize=4096)  # noqa: B019 (the instances are small and frozen)
    def critical_gamma(self, stiffness: float, latency: float) -> float:
        """The smallest Gamma at which the loop loses stability (its spectral radius
        reaches 1; log bisection to 0.05 %), inf if none up to 10, 0.0 if the loop is
        unstable already at Gamma = 1e-12 (the sampled PD on that wall: no Gamma helps)."""
        low, high = 1e-12, 10.0
        if not self.stable(low, stiffness, latency):
            return 0.0
        if self.stable(high, stiffness, latency):
            return math.inf
        while high / low > 1.0005:
            middle = math.sqrt(low * high)
            low, high = (middle, high) if self.stable(middle, stiffness, latency) else (low, middle)
        return math.sqrt(low * high)

    def tolerable_latency(self, gamma: float, stiffness: float, longest: float = 0.1):
        """The shortest latency at which the loop at `gamma` loses stability, s: the first
        crossing on a grid (steps of h / 4 up to 4 h, then of 10 %), refined by bisection;
        None if it is stable up to `longest`, 0.0 if it is unstable without latency."""
        if not self.stable(gamma, stiffness, 0.0):
            return 0.0
        low, h = 0.0, self.period
        while low < longest:
            high = min(low + 0.25 * h if low < 4.0 * h else 1.1 * low, longest)
            if not self.stable(gamma, stiffness, high):
                for _ in range(40):
                    middle = 0.5 * (low + high)
                    stable = self.stable(gamma, stiffness, middle)
                    low, high = (middle, high) if stable else (low, middle)
                return 0.5 * (low + high)
            low = high
        return None


def damper_gain(jacobian, mass_matrix, kd, period: float) -> float:
    """h max eig(J M^-1 J^T Kd): the sampled PID's damping on the arm, per period.

    The sampled PID holds its damping force -Kd dX/dt over each period h. On the arm's
    task-space inertia Lambda = (J M^-1 J^T)^-1 that force alone steps each of the task's
    velocity modes by -h lambda_i per period (lambda_i the eigenvalues of J M^-1 J^T Kd, real
    and positive for a diagonal Kd > 0); :func:`delayed_damper_limit` says how large h
    lambda may be when the force comes one or more periods late. A necessary condition:
    the stiffness and the contact take some of that room.
    """
    jacobian = np.atleast_2d(np.asarray(jacobian, dtype=float))
    mobility = jacobian @ np.linalg.solve(np.asarray(mass_matrix, dtype=float), jacobian.T)
    return float(period * np.max(np.linalg.eigvals(mobility @ np.diag(kd)).real))


@functools.lru_cache(maxsize=64)
def delayed_damper_limit(delay_periods: int) -> float:
    """The largest damper gain a = h lambda at which one velocity mode stays stable when
    its damping force is computed from the velocity `delay_periods` (N) periods old:
    v_k+1 = v_k - a v_k-N, the loop of :func:`sampled_loop_matrix` on an integrator
    (ds/dt = u, h = 1) with its reading N periods late; bisection on its spectral radius to
    1e-9. N = 0 gives 2 (the damper read at its own tick), N = 1 gives 1 (z^2 - z + a: its
    constant term a reaches 1), and it falls as 2 sin(pi / (2 (2 N + 1))) beyond.
    """
    if delay_periods < 0:
        raise ValueError(f"delay_periods must be >= 0, got {delay_periods}")

    def stable(gain: float) -> bool:
        loop = sampled_loop_matrix(
            [[0.0]],
            [[1.0]],
            [[1.0]],
            period=1.0,
            latency=float(delay_periods),
            state_gain=[0.0],
            measurement_gain=-gain,
        )
        return spectral_radius(loop) < 1.0 - 1e-12

    low, high = 0.0, 2.0 + 1e-6
    while high - low > 1e-9:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if stable(middle) else (low, middle)
    return 0.5 * (low + high)
