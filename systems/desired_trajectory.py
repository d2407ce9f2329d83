"""The desired end-effector trajectory of the paper (eq. 19)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["DesiredTrajectory", "DesiredTrajectory_"]


@TemplateSystem.define("DesiredTrajectory_", T_list=[float, AutoDiffXd, Expression])
def DesiredTrajectory_(T):
    class Impl(LeafSystem_[T]):
        """Xd(t) = center + amplitude * sin(2 pi frequency t), per axis (paper eq. 19).

        The paper's simulation uses center = (0.2, -0.25, pi/2), amplitude = (0, 0.025, 0) and
        frequency 0.1 Hz (yd = 0.025 sin(0.2 pi t) - 0.25). Both Xd and its exact time
        derivative are output; the derivative feeds the PID's rate term.

        .. pydrake_system::

            name: DesiredTrajectory
            output_ports:
            - desired_position
            - desired_velocity
        """

        def _construct(
            self,
            *,
            center: Sequence[float],
            amplitude: Sequence[float] = (0.0, 0.0, 0.0),
            frequency: float = 0.0,
            converter=None,
        ) -> None:
            """
            Args:
                center: (x m, y m, theta rad) about which the trajectory oscillates.
                amplitude: oscillation amplitude per axis, same units.
                frequency: oscillation frequency, Hz (>= 0).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            self._center = np.asarray(center, dtype=float).reshape(-1)
            self._amplitude = np.broadcast_to(
                np.asarray(amplitude, dtype=float), self._center.shape
            ).copy()
            if not (math.isfinite(frequency) and frequency >= 0):
                raise ValueError(f"frequency must be >= 0 Hz, got {frequency}")
            if not (np.all(np.isfinite(self._center)) and np.all(np.isfinite(self._amplitude))):
                raise ValueError("center and amplitude must be finite")
            self._frequency = float(frequency)
            self._omega = 2.0 * math.pi * self._frequency
            size = self._center.size
            self.desired_position_output = self.DeclareVectorOutputPort(
                "desired_position", size, self._CalcPosition, {self.time_ticket()}
            )
            self.desired_velocity_output = self.DeclareVectorOutputPort(
                "desired_velocity", size, self._CalcVelocity, {self.time_ticket()}
            )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                center=other._center,
                amplitude=other._amplitude,
                frequency=other._frequency,
                converter=converter,
            )

        def position_at(self, time: float) -> np.ndarray:
            """Xd(t) as floats."""
            return self._center + self._amplitude * math.sin(self._omega * time)

        def velocity_at(self, time: float) -> np.ndarray:
            """dXd/dt(t) as floats."""
            return self._amplitude * self._omega * math.cos(self._omega * time)

        def _CalcPosition(self, context, output) -> None:
            phase = self._omega * context.get_time()
            sine = math.sin(phase) if T is float else np.sin(phase)
            output.SetFromVector(self._center + self._amplitude * sine)

        def _CalcVelocity(self, context, output) -> None:
            phase = self._omega * context.get_time()
            cosine = math.cos(phase) if T is float else np.cos(phase)
            output.SetFromVector(self._amplitude * self._omega * cosine)

    return Impl


DesiredTrajectory = DesiredTrajectory_[None]
