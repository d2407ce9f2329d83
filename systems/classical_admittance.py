"""Classical admittance: a mass-damper(-spring) filter driven by the force error.

The position-based admittance controller found in most robot stacks (ROS 2's
``admittance_controller`` with a wrench reference; Siciliano and Villani, "Robot Force
Control", 1999, ch. 3): the reference offset obeys a virtual mass-damper-spring driven by
the difference between the desired and the measured force,

    M d2Xr/dt2 + D dXr/dt + Ks Xr = E,   E = Fr - F   (per force-controlled axis).

With Ks = 0 it integrates the force error through a lag, Xr = E / (s (M s + D)): the
steady state has E = 0 on a static wall. With Ks > 0 it is a compliance: the steady state
keeps an error E = Ks Xr. Unlike the paper's law it has no proportional path (a force change
moves Xr only through the mass), and nothing bounds the offset while the arm is in free
space, where E = Fr integrates without end.
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

__all__ = ["ClassicalAdmittance", "ClassicalAdmittance_"]


class _ClassicalAdmittance:
    """M Xr'' + D Xr' + Ks Xr = Fr - F per force axis; Xr = 0 on the other axes.

    State: (Xr, dXr/dt) per force axis. The output is the state (no feed-through). A
    measurement that is not finite counts as E = 0.

    .. pydrake_system::

        name: ClassicalAdmittance
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
        stiffness: float | Sequence[float] = 0.0,
        force_axes: Sequence[int],
        num_axes: int,
        converter=None,
    ) -> None:
        """
        Args:
            mass: M per force axis, kg (> 0).
            damping: D per force axis, N s/m (> 0).
            stiffness: Ks per force axis, N/m (>= 0; 0 = mass-damper).
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
        self._stiffness = per_axis("stiffness", stiffness, size, allow_zero=True)
        self.DeclareContinuousState(size, size, 0)  # Xr (q), dXr/dt (v)
        declare_force_ports(
            self,
            size,
            self._num_axes,
            offset_from_state(T, self._axes, self._num_axes),
            {self.xc_ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _ClassicalAdmittance._construct(
            self,
            mass=other._mass,
            damping=other._damping,
            stiffness=other._stiffness,
            force_axes=other._axes,
            num_axes=other._num_axes,
            converter=converter,
        )

    @property
    def gains(self) -> dict:
        """M, D and Ks per force axis."""
        return {
            "mass": self._mass.copy(),
            "damping": self._damping.copy(),
            "stiffness": self._stiffness.copy(),
        }

    def DoCalcTimeDerivatives(self, context, derivatives) -> None:
        size = len(self._axes)
        state = context.get_continuous_state_vector().CopyToVector()
        errors = force_error(
            self._T, self.desired_force_input.Eval(context), self.measured_force_input.Eval(context)
        )
        rates = list(state[size:])
        for i in range(size):
            rates.append(
                (errors[i] - self._damping[i] * state[size + i] - self._stiffness[i] * state[i])
                / self._mass[i]
            )
        derivatives.get_mutable_vector().SetFromVector(rates)


@TemplateSystem.define("ClassicalAdmittance_", T_list=[float, AutoDiffXd])
def ClassicalAdmittance_(T):
    class Impl(_ClassicalAdmittance, LeafSystem_[T]):
        __doc__ = _ClassicalAdmittance.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _ClassicalAdmittance._construct
        _construct_copy = _ClassicalAdmittance._construct_copy

    return Impl


ClassicalAdmittance = ClassicalAdmittance_[None]
