"""The FlexiForce A201 circuit's constants: their values, their derivation and their ranges.

The sensor (systems/flexiforce.py) is the A201 read through Tekscan's recommended
inverting op-amp circuit and an analog low-pass (paper Section VI-B; the datasheet facts
are in docs/evidence/paper-notes.md, section 7). Each constant below is an argument of the
sensor, with this value by default, checked by ``circuit_constants``.

Default constants (all are constructor arguments):

* ``conductance_per_newton`` c = 6.0e-7 S/N. The A201 conductance 1/R is roughly linear in
  force (datasheet, "Force vs. conductance"), but Tekscan gives the curve only as a typical
  plot, not as a number per force range. c is chosen so that R = 1 / (G0 + c * 111 N) =
  15.0 kOhm at the rated 111 N (16.6 kOhm at 100 N), a plausible value in the 10-20 kOhm
  range typical of a loaded A201. The slope varies from sensor to sensor (the datasheet
  asks for a per-sensor calibration), so it is a representative value, not a measured one.
* ``unloaded_conductance`` G0 = 5.0e-8 S, i.e. 20 MOhm unloaded (datasheet: > 5 MOhm).
* ``drive_voltage`` V_drive = -0.5 V (Tekscan's recommended inverting circuit, "-V_T").
* ``feedback_resistance`` R_f = 150 kOhm. Derived so that the paper's full scale spans the
  op-amp's output swing: 100 N -> 4.5 V with 5 V rails gives
  R_f = 4.5 V / (0.5 V * (G0 + c * 100 N)) = 149.9 kOhm, rounded to the E12 value 150 kOhm.
  Then the gain is 0.045 V/N, the unloaded output 3.75 mV, 100 N reads 4.504 V and the
  output saturates at 5 V, i.e. at 111.03 N (the sensor's rated range).
* ``rail_voltage`` = 5.0 V, the op-amp's positive output limit (dual +-5 V supply).
* ``filter_cutoff_hz`` = 5 kHz first-order RC low-pass, tau = 1 / (2 pi 5 kHz) = 31.8 us.
  The paper leaves the cut-off open; its phase lag enters the force loop, and with the
  paper's gains the loop needs a cut-off above about 1.05 kHz (Ke = 5e4 N/m) or 2.1 kHz
  (Ke = 1e5 N/m) to stay stable (`admittance stability`), so 5 kHz is the default, the same
  as the scenarios' ``sensor.filter_cutoff``. The sensor's own response time (< 5 us,
  datasheet) is still negligible next to it.
"""

from __future__ import annotations

import math

__all__ = ["circuit_constants"]

# Datasheet bound on the unloaded resistance (> 5 MOhm), as a conductance bound in S.
_MAX_UNLOADED_CONDUCTANCE = 1.0 / 5.0e6

# The quadratic bow keeps the force-to-conductance map monotone while |linearity_error| < 1/4.
_MAX_ABS_LINEARITY_ERROR = 0.25


def _require_finite(name: str, value: float, allowed: str) -> float:
    """Returns ``value`` as a float, or raises ValueError naming ``name`` and ``allowed``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number {allowed}; got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite {allowed}; got {value!r}")
    return number


def _check(condition: bool, name: str, value: float, allowed: str) -> None:
    """Raises ValueError naming ``name`` and the ``allowed`` range unless ``condition``."""
    if not condition:
        raise ValueError(f"{name} must be {allowed}; got {value!r}")


def circuit_constants(
    *,
    conductance_per_newton,
    unloaded_conductance,
    drive_voltage,
    feedback_resistance,
    rail_voltage,
    filter_cutoff_hz,
    linearity_error,
    full_scale_force,
    period,
    hysteresis,
    drift,
) -> dict:
    """The circuit's constants as floats, each checked against its range (the arguments of
    systems/flexiforce.py's FlexiForceSensor but its kind).

    Raises:
        ValueError: an argument is outside its allowed range (the message names it and
            the range).
    """
    c = _require_finite("conductance_per_newton", conductance_per_newton, "> 0 S/N")
    _check(c > 0.0, "conductance_per_newton", conductance_per_newton, "> 0 S/N")
    g0_range = f"in [0, {_MAX_UNLOADED_CONDUCTANCE:g}] S (unloaded R >= 5 MOhm)"
    g0 = _require_finite("unloaded_conductance", unloaded_conductance, g0_range)
    _check(
        0.0 <= g0 <= _MAX_UNLOADED_CONDUCTANCE,
        "unloaded_conductance",
        unloaded_conductance,
        g0_range,
    )
    v_drive = _require_finite("drive_voltage", drive_voltage, "< 0 V")
    _check(v_drive < 0.0, "drive_voltage", drive_voltage, "< 0 V")
    r_f = _require_finite("feedback_resistance", feedback_resistance, "> 0 Ohm")
    _check(r_f > 0.0, "feedback_resistance", feedback_resistance, "> 0 Ohm")
    v_offset = -v_drive * r_f * g0
    rail_range = f"> the unloaded output voltage {v_offset:g} V"
    v_rail = _require_finite("rail_voltage", rail_voltage, rail_range)
    _check(v_rail > v_offset, "rail_voltage", rail_voltage, rail_range)
    f_c = _require_finite("filter_cutoff_hz", filter_cutoff_hz, "> 0 Hz")
    _check(f_c > 0.0, "filter_cutoff_hz", filter_cutoff_hz, "> 0 Hz")
    lin_range = f"in ({-_MAX_ABS_LINEARITY_ERROR:g}, {_MAX_ABS_LINEARITY_ERROR:g})"
    e_lin = _require_finite("linearity_error", linearity_error, lin_range)
    _check(abs(e_lin) < _MAX_ABS_LINEARITY_ERROR, "linearity_error", linearity_error, lin_range)
    f_fs = _require_finite("full_scale_force", full_scale_force, "> 0 N")
    _check(f_fs > 0.0, "full_scale_force", full_scale_force, "> 0 N")
    h = _require_finite("period", period, ">= 0 s (0 = continuous)")
    _check(h >= 0.0, "period", period, ">= 0 s (0 = continuous)")
    hys = _require_finite("hysteresis", hysteresis, "in [0, 0.1]")
    _check(0.0 <= hys <= 0.1, "hysteresis", hysteresis, "in [0, 0.1]")
    dri = _require_finite("drift", drift, "in [0, 0.1]")
    _check(0.0 <= dri <= 0.1, "drift", drift, "in [0, 0.1]")
    if h > 0.0 and (hys > 0.0 or dri > 0.0):
        raise ValueError(
            f"hysteresis and drift need the continuous filter (period 0); got {period!r}"
        )
    return dict(
        conductance_per_newton=c,
        unloaded_conductance=g0,
        drive_voltage=v_drive,
        feedback_resistance=r_f,
        rail_voltage=v_rail,
        filter_cutoff_hz=f_c,
        linearity_error=e_lin,
        full_scale_force=f_fs,
        period=h,
        hysteresis=hys,
        drift=dri,
    )
