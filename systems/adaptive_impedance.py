"""Adaptive force-tracking impedance (Jung, Hsia and Bonitz 2004), position-based.

S. Jung, T. C. Hsia and R. G. Bonitz, "Force tracking impedance control of robot
manipulators under unknown environment", IEEE Trans. Control Systems Technology 12(3),
474-483, 2004. With the environment's position and stiffness unknown, the impedance's spring
is dropped (k = 0, so no reference position inside the environment is needed) and an
adaptive term Phi, updated from the force error, is added to the damping term:

    m e'' + b (e' + Phi(t)) = f_e - f_d,
    Phi(t) = Phi(t - lambda) + eta (f_d(t - lambda) - f_e(t - lambda)) / b

(lambda: the controller's sampling period, eta: the update rate). Here the impedance acts
on the reference offset (position-based: e = Xd - Xc = -Xr with the PID tracking Xc) and
E = f_d - f_e = Fr - F, so

    m Xr'' + b Xr' = E + b Phi,   Phi' = (eta / lambda) E / b

where Phi' is the continuous-time limit (lambda -> 0 at a fixed eta / lambda, called the
adaptation rate) of the paper's update, which is its forward-Euler discretisation. Phi
integrates the force error and the mass-damper integrates again: two integrators, so the
force follows a wall moving at a constant speed without steady error (Phi -> the wall's
speed), the property the authors designed it for.
"""

from __future__ import annotations

from collections.abc import Sequence

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.force_axes import (
    check_axes,
    declare_force_ports,
    force_error,
    offset_from_state,
    per_axis,
)

__all__ = ["AdaptiveImpedance", "AdaptiveImpedance_"]


class _AdaptiveImpedance:
    """m Xr'' + b Xr' = E + b Phi, Phi' = rate E / b per force axis (Jung et al. 2004).

    State: (Xr, dXr/dt, Phi) per force axis; the output is Xr (no feed-through). A
    measurement that is not finite counts as E = 0 (Phi frozen).

    .. pydrake_system::

        name: AdaptiveImpedance
        input_ports:
        - measured_force
        - desired_force
        output_ports:
        - reference_offset
    """

    def _construct(
        self,
        *,
        mass: float | Sequence[float],
        damping: float | Sequence[float],
        adaptation_rate: float | Sequence[float],
        force_axes: Sequence[int],
        num_axes: int,
        converter=None,
    ) -> None:
        """
        Args:
            mass: m of the impedance per force axis, kg (> 0).
            damping: b of the impedance per force axis, N s/m (> 0).
            adaptation_rate: eta / lambda of the Phi update per force axis, 1/s (> 0).
            force_axes: indices of the force-controlled axes in X.
            num_axes: size of the reference offset output.
        """
        T = self._T
        LeafSystem_[T].__init__(self, converter=converter)
        self._axes = check_axes(force_axes, num_axes)
        self._num_axes = int(num_axes)
        size = len(self._axes)
        self._mass = per_axis("mass", mass, size, allow_zero=False)
        self._damping = per_axis("damping", damping, size, allow_zero=False)
        self._rate = per_axis("adaptation_rate", adaptation_rate, size, allow_zero=False)
        self.DeclareContinuousState(size, size, size)  # Xr (q), dXr/dt (v), Phi (z)
        declare_force_ports(
            self,
            size,
            self._num_axes,
            offset_from_state(T, self._axes, self._num_axes),
            {self.xc_ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _AdaptiveImpedance._construct(
            self,
            mass=other._mass,
            damping=other._damping,
            adaptation_rate=other._rate,
            force_axes=other._axes,
            num_axes=other._num_axes,
            converter=converter,
        )

    @property
    def gains(self) -> dict:
        """m, b and the adaptation rate eta / lambda per force axis."""
        return {
            "mass": self._mass.copy(),
            "damping": self._damping.copy(),
            "adaptation_rate": self._rate.copy(),
        }

    def DoCalcTimeDerivatives(self, context, derivatives) -> None:
        size = len(self._axes)
        state = context.get_continuous_state_vector().CopyToVector()
        errors = force_error(
            self._T, self.desired_force_input.Eval(context), self.measured_force_input.Eval(context)
        )
        velocity = state[size : 2 * size]
        phi = state[2 * size :]
        accelerations, phi_rates = [], []
        for i in range(size):
            b = self._damping[i]
            accelerations.append((errors[i] + b * phi[i] - b * velocity[i]) / self._mass[i])
            phi_rates.append(self._rate[i] * errors[i] / b)
        derivatives.get_mutable_vector().SetFromVector(list(velocity) + accelerations + phi_rates)


@TemplateSystem.define("AdaptiveImpedance_", T_list=[float, AutoDiffXd])
def AdaptiveImpedance_(T):
    class Impl(_AdaptiveImpedance, LeafSystem_[T]):
        __doc__ = _AdaptiveImpedance.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _AdaptiveImpedance._construct
        _construct_copy = _AdaptiveImpedance._construct_copy

    return Impl


AdaptiveImpedance = AdaptiveImpedance_[None]
