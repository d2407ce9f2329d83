"""Linear analysis of a loop, whatever its robot: modes and time constants, Lyapunov
certificates (continuous and discrete), and the critical gain at which a linear loop
loses stability.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pydrake.math import RealContinuousLyapunovEquation, RealDiscreteLyapunovEquation

__all__ = ["critical_gain", "lyapunov_certificate", "modal_summary"]


def modal_summary(A: np.ndarray, *, period: float = 0.0) -> dict:
    """Eigenvalues of A with their time constants and damping ratios.

    With `period` > 0, A is a discrete map over one period: the eigenvalues z are read
    against the unit circle (`spectral_radius`, stable below 1) and the time constants,
    damping ratios and `max_real_part` are those of s = ln(z) / period; the eigenvalues at
    z = 0 (states that a sample overwrites) have no s and are counted in `zero_eigenvalues`.
    """
    if period > 0:
        return _discrete_modal_summary(A, period)
    eigenvalues = np.linalg.eigvals(A)
    order = np.argsort(-eigenvalues.real)
    eigenvalues = eigenvalues[order]
    magnitude = np.abs(eigenvalues)
    damping = np.where(magnitude > 0, -eigenvalues.real / np.where(magnitude > 0, magnitude, 1), 1)
    with np.errstate(divide="ignore"):
        time_constants = np.where(eigenvalues.real < 0, -1.0 / eigenvalues.real, np.inf)
    stable = bool(np.max(eigenvalues.real) < 0)
    return {
        "stable": stable,
        "max_real_part": float(np.max(eigenvalues.real)),
        "eigenvalues": [[float(e.real), float(e.imag)] for e in eigenvalues],
        "damping_ratios": [float(d) for d in damping],
        "slowest_time_constant": float(np.max(time_constants)),
        "fastest_time_constant": float(np.min(time_constants)),
        "least_damped_ratio": float(np.min(damping[np.abs(eigenvalues.imag) > 0]))
        if np.any(np.abs(eigenvalues.imag) > 0)
        else 1.0,
    }


def _discrete_modal_summary(A: np.ndarray, period: float) -> dict:
    eigenvalues = np.linalg.eigvals(A)
    magnitude = np.abs(eigenvalues)
    order = np.argsort(-magnitude)
    eigenvalues, magnitude = eigenvalues[order], magnitude[order]
    nonzero = magnitude > 1e-12 * max(1.0, float(np.max(magnitude)))
    equivalent = np.log(eigenvalues[nonzero].astype(complex)) / period
    summary = modal_summary(np.diag(equivalent)) if equivalent.size else {}
    radius = float(np.max(magnitude))
    summary.update(
        {
            "stable": bool(radius < 1.0),
            "spectral_radius": radius,
            "max_real_part": math.log(radius) / period if radius > 0 else -math.inf,
            "period": period,
            "eigenvalues": [[float(e.real), float(e.imag)] for e in eigenvalues],
            "equivalent_eigenvalues": summary.get("eigenvalues", []),
            "zero_eigenvalues": int(np.count_nonzero(~nonzero)),
        }
    )
    return summary


def lyapunov_certificate(
    A: np.ndarray, Q: np.ndarray | None = None, *, discrete: bool = False
) -> dict:
    """Solves A^T P + P A = -Q (Q = I by default): P > 0 certifies local stability.

    With `discrete`, A is a map over one period and the equation is A^T P A - P = -Q
    (RealDiscreteLyapunovEquation): P > 0 certifies that V = x^T P x falls at every step.
    """
    Q = np.eye(A.shape[0]) if Q is None else Q
    try:
        if discrete:
            P = RealDiscreteLyapunovEquation(A, Q)
        else:
            P = RealContinuousLyapunovEquation(A, Q)
    except RuntimeError as error:  # eigenvalues on or across the imaginary axis
        return {"positive_definite": False, "error": str(error).splitlines()[0]}
    P = 0.5 * (P + P.T)
    eigenvalues = np.linalg.eigvalsh(P)
    if discrete:
        residual = np.max(np.abs(A.T @ P @ A - P + Q))
    else:
        residual = np.max(np.abs(A.T @ P + P @ A + Q))
    return {
        "positive_definite": bool(eigenvalues[0] > 0),
        "min_eigenvalue": float(eigenvalues[0]),
        "max_eigenvalue": float(eigenvalues[-1]),
        "condition_number": float(eigenvalues[-1] / eigenvalues[0])
        if eigenvalues[0] > 0
        else math.inf,
        "residual": float(residual),
        "P": P,
    }


def critical_gain(
    matrix_of_gain: Callable[[float], np.ndarray],
    low: float,
    high: float,
    *,
    period: float = 0.0,
    threshold: float = 0.0,
    iterations: int = 40,
) -> float | None:
    """The smallest gain in [low, high] at which the linear loop A = matrix_of_gain(gain)
    loses stability (log bisection): its growth rate, the largest real part of A's
    eigenvalues, reaches `threshold` (1/s). With `period` > 0, A is a map over one period
    and its growth rate is ln(spectral radius) / period (the spectral radius reaches
    exp(threshold period)).

    Returns None if the loop is stable up to `high`.

    Raises:
        ValueError: the loop is unstable already at `low`.
    """

    def unstable(gain: float) -> bool:
        eigenvalues = np.linalg.eigvals(matrix_of_gain(gain))
        if period > 0:
            return float(np.max(np.abs(eigenvalues))) >= math.exp(threshold * period)
        return float(np.max(eigenvalues.real)) >= threshold

    if unstable(low):
        raise ValueError(f"the loop is unstable already at {low:g}")
    if not unstable(high):
        return None
    for _ in range(iterations):
        middle = math.sqrt(low * high)
        if unstable(middle):
            high = middle
        else:
            low = middle
        if high / low < 1.001:
            break
    return math.sqrt(low * high)
