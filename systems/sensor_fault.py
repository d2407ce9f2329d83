"""Injected faults of the force measurement, scheduled in time (for reliability studies)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["SENSOR_FAULT_KINDS", "SensorFault", "SensorFault_"]

# kind -> what the reading becomes while the fault is active.
SENSOR_FAULT_KINDS = {
    "sensor_nan": "NaN (a broken cable or ADC error)",
    "sensor_stuck": "a constant value (value, N)",
    "sensor_zero": "0 N (the sensor drops out)",
    "sensor_saturated": "a constant full-scale reading (value, N)",
}


@TemplateSystem.define("SensorFault_", T_list=[float, AutoDiffXd])
def SensorFault_(T):
    class Impl(LeafSystem_[T]):
        """Passes the measured force through, except during scheduled faults.

        Each fault is (kind, start s, end s, value); during [start, end) the reading is
        replaced as SENSOR_FAULT_KINDS says. Outside every fault the output equals the input.

        .. pydrake_system::

            name: SensorFault
            input_ports:
            - measured_force
            output_ports:
            - reported_force
        """

        def _construct(
            self, faults: Sequence[tuple[str, float, float, float]] = (), converter=None
        ) -> None:
            LeafSystem_[T].__init__(self, converter=converter)
            checked = []
            for kind, start, end, value in faults:
                if kind not in SENSOR_FAULT_KINDS:
                    raise ValueError(
                        f"fault kind must be one of {', '.join(SENSOR_FAULT_KINDS)}, got {kind!r}"
                    )
                if not (math.isfinite(start) and end > start):
                    raise ValueError(f"fault {kind}: end ({end}) must be after start ({start})")
                checked.append((kind, float(start), float(end), float(value)))
            self._faults = checked
            self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
            self.reported_force_output = self.DeclareVectorOutputPort(
                "reported_force", 1, self._CalcReported
            )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(self, other._faults, converter=converter)

        def active_fault(self, time: float) -> tuple[str, float, float, float] | None:
            """The fault active at `time` (the first listed if several overlap), or None."""
            for fault in self._faults:
                if fault[1] <= time < fault[2]:
                    return fault
            return None

        def _CalcReported(self, context, output) -> None:
            time = context.get_time()
            fault = self.active_fault(time if T is float else time.value())
            if fault is None:
                output.SetFromVector(self.measured_force_input.Eval(context))
                return
            kind, _, _, value = fault
            reading = {
                "sensor_nan": math.nan,
                "sensor_stuck": value,
                "sensor_zero": 0.0,
                "sensor_saturated": value,
            }[kind]
            output.SetFromVector([T(reading)])

    return Impl


SensorFault = SensorFault_[None]
