"""The desired end-effector trajectory of the paper (eq. 19)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, Sine

__all__ = ["DesiredTrajectory"]


class DesiredTrajectory(Diagram):
    """Xd(t) = center + amplitude * sin(2 pi frequency t), per axis (paper eq. 19).

    The paper's simulation uses center = (0.2, -0.25, pi/2), amplitude = (0, 0.025, 0) and
    frequency 0.1 Hz (yd = 0.025 sin(0.2 pi t) - 0.25). Both Xd and its exact time
    derivative dXd/dt = amplitude * 2 pi frequency * cos(2 pi frequency t) are output; the
    derivative feeds the PID's rate term.

    Built from Drake's primitives, so that no Python runs while it is evaluated: a ``Sine``
    of time (its value and its first derivative are the sinusoid and its rate) and the
    constant center added to the value. It converts to AutoDiffXd and symbolic Expression
    as its parts do.

    .. pydrake_system::

        name: DesiredTrajectory
        output_ports:
        - desired_position
        - desired_velocity
    """

    def __init__(
        self,
        *,
        center: Sequence[float],
        amplitude: float | Sequence[float] = 0.0,
        frequency: float = 0.0,
    ) -> None:
        """
        Args:
            center: the point of X (m, rad) about which the trajectory oscillates.
            amplitude: oscillation amplitude per axis, same units (one value: every axis).
            frequency: oscillation frequency, Hz (>= 0).
        """
        Diagram.__init__(self)
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

        builder = DiagramBuilder()
        sine = builder.AddNamedSystem(
            "sine",
            Sine(
                amplitudes=self._amplitude,
                frequencies=np.full(size, self._omega),
                phases=np.zeros(size),
                is_time_based=True,
            ),
        )
        center_source = builder.AddNamedSystem("center", ConstantVectorSource(self._center))
        position = builder.AddNamedSystem("position", Adder(2, size))
        builder.Connect(center_source.get_output_port(), position.get_input_port(0))
        builder.Connect(sine.get_output_port(0), position.get_input_port(1))
        builder.ExportOutput(position.get_output_port(), "desired_position")
        # Sine's second output is the value's first time derivative.
        builder.ExportOutput(sine.get_output_port(1), "desired_velocity")
        builder.BuildInto(self)
        self.desired_position_output = self.GetOutputPort("desired_position")
        self.desired_velocity_output = self.GetOutputPort("desired_velocity")

    def position_at(self, time: float) -> np.ndarray:
        """Xd(t) as floats."""
        return self._center + self._amplitude * math.sin(self._omega * time)

    def velocity_at(self, time: float) -> np.ndarray:
        """dXd/dt(t) as floats."""
        return self._amplitude * self._omega * math.cos(self._omega * time)
