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


class _SensorFault:
    """Passes the measured force through, except during scheduled faults.

    Each fault is (kind, start s, end s, value) or (kind, start s, end s, value, noisy);
    during [start, end) the reading is replaced as SENSOR_FAULT_KINDS says. A noisy
    fault keeps the sensor's noise: the replaced reading plus the ADC's noise sample
    (N), read from the `noise` input, which exists when some fault is noisy (a real
    dropout or a stuck amplifier still shows the converter's noise; a noise-free
    constant is what a "stuck" rule catches at once). Outside every fault the output
    equals the input.

    .. pydrake_system::

        name: SensorFault
        input_ports:
        - measured_force
        - noise (when a fault is noisy)
        output_ports:
        - reported_force
    """

    def _construct(self, faults: Sequence[tuple] = (), converter=None) -> None:
        LeafSystem_[self._T].__init__(self, converter=converter)
        checked = []
        for fault in faults:
            kind, start, end, value = fault[:4]
            noisy = bool(fault[4]) if len(fault) > 4 else False
            if kind not in SENSOR_FAULT_KINDS:
                raise ValueError(
                    f"fault kind must be one of {', '.join(SENSOR_FAULT_KINDS)}, got {kind!r}"
                )
            if not (math.isfinite(start) and end > start):
                raise ValueError(f"fault {kind}: end ({end}) must be after start ({start})")
            if noisy and kind == "sensor_nan":
                raise ValueError("fault sensor_nan: a NaN reading has no noise to keep")
            checked.append((kind, float(start), float(end), float(value), noisy))
        self._faults = checked
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
        self.noise_input = (
            self.DeclareVectorInputPort("noise", 1) if any(f[4] for f in checked) else None
        )
        self.reported_force_output = self.DeclareVectorOutputPort(
            "reported_force", 1, self._CalcReported
        )

    def _construct_copy(self, other, converter=None) -> None:
        _SensorFault._construct(self, other._faults, converter=converter)

    def active_fault(self, time: float) -> tuple[str, float, float, float, bool] | None:
        """The fault active at `time` (the first listed if several overlap), or None."""
        for fault in self._faults:
            if fault[1] <= time < fault[2]:
                return fault
        return None

    def _CalcReported(self, context, output) -> None:
        T = self._T
        time = context.get_time()
        fault = self.active_fault(time if T is float else time.value())
        if fault is None:
            output.SetFromVector(self.measured_force_input.Eval(context))
            return
        kind, _, _, value, noisy = fault
        reading = T(
            {
                "sensor_nan": math.nan,
                "sensor_stuck": value,
                "sensor_zero": 0.0,
                "sensor_saturated": value,
            }[kind]
        )
        if noisy:
            reading = reading + self.noise_input.Eval(context)[0]
        output.SetFromVector([reading])


@TemplateSystem.define("SensorFault_", T_list=[float, AutoDiffXd])
def SensorFault_(T):
    class Impl(_SensorFault, LeafSystem_[T]):
        __doc__ = _SensorFault.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _SensorFault._construct
        _construct_copy = _SensorFault._construct_copy

    return Impl


SensorFault = SensorFault_[None]
