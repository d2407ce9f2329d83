"""An injected external torque on one joint, scheduled in time: a link hitting something.

During [start, end) the torque `value` N m acts on joint `joint`, summed with the
generalized force that reaches the plant's applied-generalized-force input (the wall's,
-F J_x^T). It stands in for a collision anywhere on the arm but the fingertip: the
contact sensor does not see it, the arm's own motion does (the momentum observer's
residual, systems/contact_force_observer.py; docs/evidence/safety-collision.md, "The collision
reflex").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["JointTorqueFault", "JointTorqueFault_"]


class _JointTorqueFault:
    """tau_out = tau_in + sum of the torques of the faults active at t (module docstring).

    .. pydrake_system::

        name: JointTorqueFault
        input_ports:
        - generalized_force
        output_ports:
        - generalized_force
    """

    def _construct(
        self,
        num_velocities: int,
        faults: Sequence[tuple[float, float, float, int]] = (),
        converter=None,
    ) -> None:
        """
        Args:
            num_velocities: nv of the plant.
            faults: (start s, end s, torque N m, joint index) of each fault.
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        checked = []
        for start, end, value, joint in faults:
            if not (math.isfinite(start) and end > start):
                raise ValueError(f"joint_torque: end ({end}) must be after start ({start})")
            if not math.isfinite(value):
                raise ValueError(f"joint_torque: value must be finite, got {value}")
            if not 0 <= int(joint) < num_velocities:
                raise ValueError(
                    f"joint_torque: joint must be in [0, {num_velocities - 1}], got {joint}"
                )
            checked.append((float(start), float(end), float(value), int(joint)))
        self._num_velocities = int(num_velocities)
        self._faults = checked
        self.generalized_force_input = self.DeclareVectorInputPort(
            "generalized_force", num_velocities
        )
        self.generalized_force_output = self.DeclareVectorOutputPort(
            "generalized_force", num_velocities, self._CalcForce
        )

    def _construct_copy(self, other, converter=None) -> None:
        _JointTorqueFault._construct(
            self, other._num_velocities, other._faults, converter=converter
        )

    def torque_at(self, time: float) -> np.ndarray:
        """The injected torque at `time` (N m per joint)."""
        torque = np.zeros(self._num_velocities)
        for start, end, value, joint in self._faults:
            if start <= time < end:
                torque[joint] += value
        return torque

    def _CalcForce(self, context, output) -> None:
        time = context.get_time()
        torque = self.torque_at(time if self._T is float else time.value())
        output.SetFromVector(self.generalized_force_input.Eval(context) + torque)


@TemplateSystem.define("JointTorqueFault_", T_list=[float, AutoDiffXd])
def JointTorqueFault_(T):
    class Impl(_JointTorqueFault, LeafSystem_[T]):
        __doc__ = _JointTorqueFault.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _JointTorqueFault._construct
        _construct_copy = _JointTorqueFault._construct_copy

    return Impl


JointTorqueFault = JointTorqueFault_[None]
