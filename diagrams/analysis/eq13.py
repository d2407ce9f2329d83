"""The paper's eq. 12-13 re-derived symbolically for the corrected sign of eq. 10 (see
docs/evidence/paper-notes.md, section 2): V falls along the law, and would grow with the printed
sign.
"""

from __future__ import annotations

from pydrake.symbolic import Expression, Variable

__all__ = ["symbolic_eq13"]


def symbolic_eq13() -> dict:
    """Derives dI/dXr, the gradient flow and dV/dt of the paper's Section III symbolically.

    Per axis (the gains are diagonal), with the impedance model of eq. 5,
        E = D X'' + B X' + K (X - Xr),   dE/dt = D X''' + B X'' + K (X' - Xr'),
    I = V = 1/2 (E + alpha dE/dt)^2 (eq. 7, 11). As in eq. 12, V changes with Xr through E
    (dE/dXr = -K; dE/dt depends on Xr' only). The gradient flow Xr' = -Gamma dI/dXr gives
    dV/dt = (dI/dXr) Xr'.

    Returns:
        The expressions as strings and the checks: `corrected_identity` is True when
        dV/dt + (E + alpha E')^2 K Gamma K expands to 0 for the corrected law
        Xr' = +Gamma K (E + alpha E'); `printed_sign_grows` is True when the printed
        eq. 10 (Xr' = -Gamma K (E + alpha E')) gives dV/dt = +(E + alpha E')^2 K Gamma K.
    """
    X, X1, X2, X3 = (Variable(name) for name in ("X", "X1", "X2", "X3"))
    Xr, Xr1 = Variable("Xr"), Variable("Xr1")
    D, B, K, gamma, alpha = (Variable(n) for n in ("D", "B", "K", "Gamma", "alpha"))
    error = D * X2 + B * X1 + K * (X - Xr)
    error_rate = D * X3 + B * X2 + K * (X1 - Xr1)
    cost = 0.5 * (error + alpha * error_rate) ** 2
    gradient = cost.Differentiate(Xr)
    corrected_flow = -gamma * gradient
    printed_flow = -corrected_flow
    weighted = error + alpha * error_rate
    target = -(weighted * K * gamma * K * weighted)
    corrected_rate = gradient * corrected_flow
    printed_rate = gradient * printed_flow
    expected_gradient = -K * weighted
    return {
        "dI_dXr": str(gradient.Expand()),
        "dI_dXr_equals_minus_K_weighted_error": (gradient - expected_gradient)
        .Expand()
        .EqualTo(Expression(0.0)),
        "corrected_flow": "dXr/dt = Gamma K (E + alpha dE/dt)",
        "dV_dt_corrected": str(corrected_rate.Expand()),
        "corrected_identity": (corrected_rate - target).Expand().EqualTo(Expression(0.0)),
        "printed_sign_grows": (printed_rate + target).Expand().EqualTo(Expression(0.0)),
    }
