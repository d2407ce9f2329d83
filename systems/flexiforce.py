"""FlexiForce A201 force sensor with its Tekscan conditioning circuit (paper Section VI-B).

The paper measures the tip force with a Tekscan FlexiForce A201 (0-111 N variant used over
the paper's 0-100 N range) read through "an operational amplifier and analog filter, as
recommended by the manufacturer". This module models that chain as one Drake system,
:class:`FlexiForceSensor` (``FlexiForceSensor_[T]`` for T in float, AutoDiffXd and symbolic
Expression), plus an ``ideal`` pass-through kind for comparisons. See
``docs/evidence/paper-notes.md`` section 7 for the datasheet facts.

The circuit's constants (the datasheet's and the derived ones, the defaults of the
constructor's arguments) and their ranges are systems/flexiforce_circuit.py's.
"""

from __future__ import annotations

import math

import numpy as np
import pydrake.math
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.flexiforce_circuit import circuit_constants

__all__ = ["FlexiForceSensor", "FlexiForceSensor_", "SENSOR_KINDS"]

#: The allowed values of the ``kind`` constructor argument.
SENSOR_KINDS = ("flexiforce", "ideal")

# Drift: the time scale t0 (s) of the time under load, the force F_on (N) above which the
# sensor counts as loaded, and 1 / ln 10.
_INV_DRIFT_TIME = 1.0 / 1.0
_INV_ONSET_FORCE = 1.0 / 1.0
_INV_LN10 = 1.0 / math.log(10.0)


class _FlexiForceSensor:
    """FlexiForce A201 force sensor, op-amp and analog low-pass filter (paper VI-B).

    Law (paper Section VI-B; Tekscan A201 datasheet, recommended circuit), for the
    ``"flexiforce"`` kind, with F the true compressive contact force in N::

        F+      = max(F, 0)                                       (no tension reading)
        F_eff   = F+ + b * u * (1 - u),  u = min(F+ / F_fs, 1),
                  b = 4 * linearity_error * F_fs                  (bow; 0 by default)
        G       = G0 + c * F_eff                                  (conductance, S)
        V_s     = min(-V_drive * R_f * G, V_rail)                 (inverting op-amp, V)
        dV/dt   = (V_s - V) / tau,  tau = 1 / (2 pi f_c)          (RC low-pass, state V)
        F_meas  = (V - V_offset) / k + n                          (ADC + calibration, N)

    with V_offset = -V_drive * R_f * G0 (unloaded output, V) and k = -V_drive * R_f * c
    (gain, V/N): the ideal linear calibration of a perfect sensor. With
    ``linearity_error`` e != 0 the reading is off by e * F_fs * 4 u (1 - u): zero at 0 and
    at full scale, e * F_fs at mid-range (the datasheet's linearity error is < 3 % FS).
    Above full scale the bow is zero. The reading saturates at
    ``saturation_force`` = (V_rail - V_offset) / k when the op-amp output hits its rail.
    The negative rail never binds (V_drive < 0, G >= 0 give V_s >= 0), so it is not
    modelled. Repeatability and temperature effects are not modelled.

    Hysteresis and drift (both 0 by default, and then neither state below exists, so
    the default sensor is unchanged), applied to F+ before the bow::

        F_h     = clamp(p, (1 - h/2) F+, (1 + h/2) F+)            (play band)
        dp/dt   = (F_h - p) / tau                                 (state p, N)
        D       = 1 + d * log10(1 + s / t0),  t0 = 1 s            (drift factor)
        ds/dt   = min(F_h / F_on, 1),  F_on = 1 N                 (state s, s)
        F+     <- F_h * D                                        (into the bow, G, V_s)

    h (``hysteresis``) is the width of the band between the loading and the unloading
    branch as a fraction of the force: on a rising force the reading trails at
    (1 - h/2) F, on a falling one it leads at (1 + h/2) F, and inside the band it holds
    (a play element whose edge p relaxes to with the filter's tau). The datasheet's
    hysteresis (< 4.5 % of full scale, the loading-unloading difference) is h = 0.045
    at full scale. d (``drift``) is the reading's rise per decade of the time under
    load s, the force held constant (datasheet: < 5 % per logarithmic time scale):
    s counts seconds loaded above F_on = 1 N (a lighter force counts in proportion),
    and it is not reset when the load is removed (the A201's recovery is not modelled).
    With t0 = 1 s the reading is (1 + d log10(1 + t)) F after t seconds under load:
    1 + d at 9 s, 1 + 2 d at 99 s. The continuous state is then [V, p, s] (the ones
    that exist, in that order); both are allowed only with the continuous filter.

    Noise: n is the ``noise`` input in N, added to the calibrated reading after the
    analog filter (it stands for ADC, wiring and sensor noise referred to force). So a
    ``noise_std`` in the project is the standard deviation of the measured-force noise,
    unaffected by the filter. The system itself is deterministic: feed ``noise`` from a
    RandomSource (through a Gain of noise_std) or fix it to zero.

    The continuous state is the filtered voltage V (V); its default value is the
    unloaded output V_offset, so an unloaded sensor reads 0 N at t = 0. The output
    depends only on the state and ``noise`` (no direct feed-through from
    ``contact_force``), which is declared so Drake sees no algebraic loop through the
    contact force.

    The ``"ideal"`` kind is an exact pass-through: ``measured_force = contact_force``,
    no state, ``noise`` ignored (it is still declared so diagrams wire either kind the
    same way). The analysis helpers (``static_output_voltage``, ``calibrated_force``,
    ``filter_time_constant``, ``saturation_force``) describe the FlexiForce circuit
    whatever the kind.

    Sampled readout (``period`` h > 0): the chain as a digital controller reads it, for
    loops that run in discrete time (a discrete MultibodyPlant whose contact force is
    held over each step). The state V is a discrete state, advanced at each sample k by
    the exact zero-order-hold solution of the RC low-pass over one period::

        V[k+1] = V_s(F[k]) + (V[k] - V_s(F[k])) exp(-h / tau)

    and the output is the calibrated reading of the held V[k] (plus the noise): the ADC
    sample at t_k, which sees the force up to the previous sample (one period of delay).
    The law is the same; only the integration of the filter differs.

    The constants are fixed at construction (not context parameters): the callbacks
    run tens of thousands of times per simulation and use precomputed Python floats.

    .. pydrake_system::

        name: FlexiForceSensor
        input_ports:
        - contact_force
        - noise
        output_ports:
        - measured_force
    """

    def _construct(
        self,
        *,
        kind: str = "flexiforce",
        conductance_per_newton: float = 6.0e-7,
        unloaded_conductance: float = 5.0e-8,
        drive_voltage: float = -0.5,
        feedback_resistance: float = 150.0e3,
        rail_voltage: float = 5.0,
        filter_cutoff_hz: float = 5000.0,
        linearity_error: float = 0.0,
        full_scale_force: float = 100.0,
        period: float = 0.0,
        hysteresis: float = 0.0,
        drift: float = 0.0,
        converter=None,
    ) -> None:
        """Declares the ports and the filter state.

        Args:
            kind: ``"flexiforce"`` (the full chain) or ``"ideal"`` (pass-through).
            conductance_per_newton: c, sensor conductance slope, S/N (> 0).
            unloaded_conductance: G0, sensor conductance at zero force, S
                (0 <= G0 <= 2e-7 S, i.e. unloaded resistance >= 5 MOhm).
            drive_voltage: V_drive, voltage driving the sensor into the inverting
                op-amp, V (< 0, so the output is positive).
            feedback_resistance: R_f, op-amp feedback resistor, Ohm (> 0).
            rail_voltage: positive output limit of the op-amp, V (greater than the
                unloaded output -V_drive * R_f * G0).
            filter_cutoff_hz: cut-off frequency of the first-order RC low-pass, Hz
                (> 0).
            linearity_error: bow of the force-to-conductance curve at mid-range, as a
                fraction of ``full_scale_force`` (-0.25 < e < 0.25; datasheet < 0.03).
            full_scale_force: F_fs, the calibrated range's full scale, N (> 0); only
                shapes the linearity bow.
            period: 0 for the continuous filter, otherwise the sampling period of the
                readout in s (the filter is then advanced exactly over each period).
            hysteresis: h, width of the loading-unloading band as a fraction of the
                force (0 <= h <= 0.1; datasheet < 0.045 of full scale).
            drift: d, rise of the reading per decade of time under load, as a
                fraction (0 <= d <= 0.1; datasheet < 0.05).
            converter: scalar converter, supplied by TemplateSystem.

        Raises:
            ValueError: an argument is outside its allowed range (the message names
                it and the range).
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        # Kept for _construct_copy (scalar conversion).
        if kind not in SENSOR_KINDS:
            raise ValueError(f"kind must be one of {SENSOR_KINDS}; got {kind!r}")
        self._construct_args = dict(kind=kind) | circuit_constants(
            conductance_per_newton=conductance_per_newton,
            unloaded_conductance=unloaded_conductance,
            drive_voltage=drive_voltage,
            feedback_resistance=feedback_resistance,
            rail_voltage=rail_voltage,
            filter_cutoff_hz=filter_cutoff_hz,
            linearity_error=linearity_error,
            full_scale_force=full_scale_force,
            period=period,
            hysteresis=hysteresis,
            drift=drift,
        )
        self._set_constants(self._construct_args)
        self._declare_ports()

    def _set_constants(self, arguments: dict) -> None:
        """The law's constants, precomputed as Python floats, from checked arguments."""
        c, g0 = arguments["conductance_per_newton"], arguments["unloaded_conductance"]
        v_drive, r_f = arguments["drive_voltage"], arguments["feedback_resistance"]
        f_c, e_lin = arguments["filter_cutoff_hz"], arguments["linearity_error"]
        f_fs, h = arguments["full_scale_force"], arguments["period"]
        self._kind = arguments["kind"]
        self._hysteresis = arguments["hysteresis"]
        self._drift = arguments["drift"]
        self._period = h
        self._v_offset = -v_drive * r_f * g0  # V, unloaded output
        self._gain = -v_drive * r_f * c  # V/N
        self._inv_gain = 1.0 / self._gain  # N/V
        self._v_rail = arguments["rail_voltage"]  # V
        self._tau = 1.0 / (2.0 * math.pi * f_c)  # s
        self._inv_tau = 2.0 * math.pi * f_c  # 1/s
        self._inv_full_scale = 1.0 / f_fs  # 1/N
        self._bow = 4.0 * e_lin * f_fs  # N, so the mid-range bow is e_lin * f_fs
        # Fraction of the filter's state left after one sampling period.
        self._decay = math.exp(-h * self._inv_tau) if h > 0 else 0.0
        if self._T is float:
            self._max, self._min, self._log = max, min, math.log
        else:
            self._max, self._min = pydrake.math.max, pydrake.math.min
            self._log = pydrake.math.log

    def _declare_ports(self) -> None:
        """The ports, and the filter's state for the kind and the readout."""
        T = self._T
        self.contact_force_input = self.DeclareVectorInputPort("contact_force", 1)
        self.noise_input = self.DeclareVectorInputPort("noise", 1)
        if self._kind == "ideal":
            self.measured_force_output = self.DeclareVectorOutputPort(
                "measured_force",
                1,
                self._calc_ideal_output,
                prerequisites_of_calc={self.contact_force_input.ticket()},
            )
            return
        if self._period > 0.0:
            self._state_index = self.DeclareDiscreteState(BasicVector_[T]([self._v_offset]))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._discrete_update
            )
            self.measured_force_output = self.DeclareVectorOutputPort(
                "measured_force",
                1,
                self._calc_sampled_output,
                prerequisites_of_calc={self.xd_ticket(), self.noise_input.ticket()},
            )
            return
        initial = [self._v_offset]
        # Indices of the play element's p and the time under load s in the state.
        hys, dri = self._hysteresis, self._drift
        self._play_index = len(initial) if hys > 0.0 else None
        initial += [0.0] if hys > 0.0 else []
        self._load_index = len(initial) if dri > 0.0 else None
        initial += [0.0] if dri > 0.0 else []
        self.DeclareContinuousState(BasicVector_[T](initial))
        if T is float:
            calc_output = self._calc_output_float
        else:
            calc_output = self._calc_output
        self.measured_force_output = self.DeclareVectorOutputPort(
            "measured_force",
            1,
            calc_output,
            prerequisites_of_calc={self.xc_ticket(), self.noise_input.ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        """Copies ``other``'s constants (scalar conversion)."""
        _FlexiForceSensor._construct(self, converter=converter, **other._construct_args)

    # ----------------------------------------------------------------- calcs
    def _static_voltage(self, force):
        """V_s for a force of scalar type T (no Python branch on its value)."""
        force = self._max(force, 0.0)
        if self._bow != 0.0:  # a constant, not a value of type T
            u = self._min(force * self._inv_full_scale, 1.0)
            force = force + self._bow * u * (1.0 - u)
        return self._min(self._v_offset + self._gain * force, self._v_rail)

    def DoCalcTimeDerivatives(self, context, derivatives) -> None:
        """dV/dt = (V_s(F) - V) / tau (the ideal kind and the sampled readout have no
        continuous state)."""
        if self._kind == "ideal" or self._period > 0.0:
            return
        if self._T is float:
            force = self.contact_force_input.Eval(context).item()
        else:
            force = self.contact_force_input.Eval(context)[0]
        state = context.get_continuous_state_vector()
        voltage = state.GetAtIndex(0)
        rates = derivatives.get_mutable_vector()
        if self._play_index is None and self._load_index is None:
            rates.SetAtIndex(0, (self._static_voltage(force) - voltage) * self._inv_tau)
            return
        force = self._max(force, 0.0)
        if self._play_index is not None:
            played = state.GetAtIndex(self._play_index)
            half = 0.5 * self._hysteresis
            edge = self._max(self._min(played, (1.0 + half) * force), (1.0 - half) * force)
            rates.SetAtIndex(self._play_index, (edge - played) * self._inv_tau)
            force = edge
        if self._load_index is not None:
            loaded = state.GetAtIndex(self._load_index)
            rates.SetAtIndex(self._load_index, self._min(force * _INV_ONSET_FORCE, 1.0))
            decades = self._log(1.0 + loaded * _INV_DRIFT_TIME) * _INV_LN10
            force = force * (1.0 + self._drift * decades)
        rates.SetAtIndex(0, (self._static_voltage(force) - voltage) * self._inv_tau)

    def _calc_output_float(self, context, output) -> None:
        """F_meas = (V - V_offset) / k + n, double-only fast path."""
        voltage = context.get_continuous_state_vector().GetAtIndex(0)
        noise = self.noise_input.Eval(context).item()
        output.SetAtIndex(0, (voltage - self._v_offset) * self._inv_gain + noise)

    def _calc_output(self, context, output) -> None:
        """F_meas = (V - V_offset) / k + n, for any scalar type."""
        voltage = context.get_continuous_state_vector().GetAtIndex(0)
        noise = self.noise_input.Eval(context)[0]
        output.SetAtIndex(0, (voltage - self._v_offset) * self._inv_gain + noise)

    def _discrete_update(self, context, discrete_state) -> None:
        """V[k+1] = V_s(F[k]) + (V[k] - V_s(F[k])) exp(-h / tau)."""
        force = self.contact_force_input.Eval(context)[0]
        voltage = context.get_discrete_state(self._state_index).GetAtIndex(0)
        static = self._static_voltage(force)
        discrete_state.get_mutable_vector(self._state_index).SetAtIndex(
            0, static + (voltage - static) * self._decay
        )

    def _calc_sampled_output(self, context, output) -> None:
        """F_meas = (V[k] - V_offset) / k + n."""
        voltage = context.get_discrete_state(self._state_index).GetAtIndex(0)
        noise = self.noise_input.Eval(context)[0]
        output.SetAtIndex(0, (voltage - self._v_offset) * self._inv_gain + noise)

    def _calc_ideal_output(self, context, output) -> None:
        """measured_force = contact_force."""
        output.SetFromVector(self.contact_force_input.Eval(context))

    # --------------------------------------------------- analysis helpers
    @property
    def kind(self) -> str:
        """``"flexiforce"`` or ``"ideal"``."""
        return self._kind

    @property
    def hysteresis(self) -> float:
        """Width h of the loading-unloading band, a fraction of the force."""
        return self._hysteresis

    @property
    def drift(self) -> float:
        """Rise d of the reading per decade of time under load, a fraction."""
        return self._drift

    @property
    def period(self) -> float:
        """Sampling period of the readout, s (0 = the continuous filter)."""
        return self._period

    @property
    def filter_time_constant(self) -> float:
        """Time constant tau = 1 / (2 pi f_c) of the analog low-pass, s."""
        return self._tau

    @property
    def saturation_force(self) -> float:
        """Largest reading (noise aside), N: the calibrated force at the op-amp rail."""
        return (self._v_rail - self._v_offset) * self._inv_gain

    @property
    def unloaded_voltage(self) -> float:
        """Op-amp output with no load, V_offset = -V_drive * R_f * G0, V."""
        return self._v_offset

    @property
    def gain(self) -> float:
        """Calibration gain k = -V_drive * R_f * c, V/N."""
        return self._gain

    def static_output_voltage(self, force: float | np.ndarray) -> float | np.ndarray:
        """Op-amp output before the filter, saturated at the rail, V.

        Args:
            force: true contact force(s), N (negative values read as 0).

        Returns:
            V_s, a float for a scalar force, an array for an array of forces.
        """
        force = np.maximum(np.asarray(force, dtype=float), 0.0)
        if self._bow != 0.0:
            u = np.minimum(force * self._inv_full_scale, 1.0)
            force = force + self._bow * u * (1.0 - u)
        voltage = np.minimum(self._v_offset + self._gain * force, self._v_rail)
        return float(voltage) if voltage.ndim == 0 else voltage

    def calibrated_force(self, voltage: float | np.ndarray) -> float | np.ndarray:
        """Ideal linear calibration (V - V_offset) / k of a voltage reading, N.

        Args:
            voltage: filtered op-amp voltage(s), V.

        Returns:
            The calibrated force, a float for a scalar voltage, else an array.
        """
        force = (np.asarray(voltage, dtype=float) - self._v_offset) * self._inv_gain
        return float(force) if force.ndim == 0 else force


@TemplateSystem.define("FlexiForceSensor_", T_list=[float, AutoDiffXd, Expression])
def FlexiForceSensor_(T):
    """Template of the FlexiForce A201 sensor system; see ``FlexiForceSensor``."""

    class Impl(_FlexiForceSensor, LeafSystem_[T]):
        __doc__ = _FlexiForceSensor.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _FlexiForceSensor._construct
        _construct_copy = _FlexiForceSensor._construct_copy

    return Impl


#: The double-valued FlexiForce sensor system (see ``FlexiForceSensor_``).
FlexiForceSensor = FlexiForceSensor_[None]
