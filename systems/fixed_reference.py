"""The fixed reference of the paper's eq. 6: the force from a model of the wall.

With a wall of known position Xe and stiffness Ke, the position that produces the force Fr
is Xe + Fr / Ke, so the reference offset that makes the commanded position Xc = Xd + Xr land
there is (paper, eq. 6, on the wall-normal axis)

    Xr = Xe_est + Fr / Ke_est - Xd.

It needs no force measurement (the ``measured_force`` input is declared for the common
interface and not read), and it is exactly as good as the estimates: a wall-position error
dXe gives a force error Ke dXe (50 N for 1 mm on a 5e4 N/m wall), a stiffness step or a
moving wall is not seen at all. The baseline the paper argues against.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.force_axes import check_axes, per_axis, scatter

__all__ = ["FixedReference", "FixedReference_"]


class _FixedReference:
    """Xr = Xe_est + Fr / Ke_est - Xd per force axis (eq. 6); Xr = 0 on the other axes.

    Besides the common ports it reads the desired position Xd (the full Cartesian
    vector), which eq. 6 subtracts.

    .. pydrake_system::

        name: FixedReference
        input_ports:
        - measured_force
        - desired_force
        - desired_position
        output_ports:
        - reference_offset
    """

    def _construct(
        self,
        *,
        wall_position: float | Sequence[float],
        wall_stiffness: float | Sequence[float],
        force_axes: Sequence[int],
        num_axes: int,
        converter=None,
    ) -> None:
        """
        Args:
            wall_position: the estimate Xe_est of the wall surface per force axis, m.
            wall_stiffness: the estimate Ke_est per force axis, N/m (> 0).
            force_axes: indices of the force-controlled axes in X.
            num_axes: size of Xd and of the reference offset output.
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        self._axes = check_axes(force_axes, num_axes)
        self._num_axes = int(num_axes)
        size = len(self._axes)
        self._wall_position = np.broadcast_to(
            np.asarray(wall_position, dtype=float), (size,)
        ).copy()
        if not np.all(np.isfinite(self._wall_position)):
            raise ValueError(f"wall_position must be finite, got {self._wall_position}")
        self._wall_stiffness = per_axis("wall_stiffness", wall_stiffness, size, allow_zero=False)
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", size)
        self.desired_force_input = self.DeclareVectorInputPort("desired_force", size)
        self.desired_position_input = self.DeclareVectorInputPort(
            "desired_position", self._num_axes
        )
        self.reference_offset_output = self.DeclareVectorOutputPort(
            "reference_offset",
            self._num_axes,
            self._CalcOutput,
            prerequisites_of_calc={
                self.desired_force_input.ticket(),
                self.desired_position_input.ticket(),
            },
        )

    def _construct_copy(self, other, converter=None) -> None:
        _FixedReference._construct(
            self,
            wall_position=other._wall_position,
            wall_stiffness=other._wall_stiffness,
            force_axes=other._axes,
            num_axes=other._num_axes,
            converter=converter,
        )

    def _CalcOutput(self, context, output) -> None:
        desired_force = self.desired_force_input.Eval(context)
        desired_position = self.desired_position_input.Eval(context)
        offsets = [
            self._wall_position[i]
            + desired_force[i] / self._wall_stiffness[i]
            - desired_position[axis]
            for i, axis in enumerate(self._axes)
        ]
        output.SetFromVector(scatter(self._T, self._axes, self._num_axes, offsets))


@TemplateSystem.define("FixedReference_", T_list=[float, AutoDiffXd])
def FixedReference_(T):
    class Impl(_FixedReference, LeafSystem_[T]):
        __doc__ = _FixedReference.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _FixedReference._construct
        _construct_copy = _FixedReference._construct_copy

    return Impl


FixedReference = FixedReference_[None]
