"""Tests of the FlexiForce A201 sensor system (systems/flexiforce.py).

Expected values are computed by hand from the default constants:
c = 6.0e-7 S/N, G0 = 5.0e-8 S, V_drive = -0.5 V, R_f = 150 kOhm, rail 5 V, f_c = 5 kHz, so
gain k = 0.5 * 150e3 * 6e-7 = 0.045 V/N, unloaded output V_offset = 0.5 * 150e3 * 5e-8 =
3.75e-3 V, tau = 1 / (2 pi 5000) s and saturation force (5 - 3.75e-3) / 0.045 N.
"""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Variable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Gain, Linearize

from admittance.systems.flexiforce import FlexiForceSensor

GAIN = 0.045  # V/N
V_OFFSET = 3.75e-3  # V
POLE = 2.0 * math.pi * 5000.0  # 1/s, the filter's pole at the default cut-off
TAU = 1.0 / POLE  # s
F_SAT = (5.0 - 3.75e-3) / 0.045  # N, = 111.0277... N


def _context(sensor, *, voltage=None, force=0.0, noise=0.0):
    """A context with fixed inputs and, if given, the filter state set to ``voltage``."""
    context = sensor.CreateDefaultContext()
    sensor.contact_force_input.FixValue(context, [force])
    sensor.noise_input.FixValue(context, [noise])
    if voltage is not None:
        context.SetContinuousState([voltage])
    return context


def _xdot(sensor, context):
    """The filter-state derivative dV/dt (of the system's scalar type)."""
    return sensor.EvalTimeDerivatives(context).get_vector().GetAtIndex(0)


def _measured(sensor, context) -> float:
    return float(sensor.measured_force_output.Eval(context)[0])


def test_default_constants():
    sensor = FlexiForceSensor()
    assert sensor.kind == "flexiforce"
    assert sensor.gain == pytest.approx(GAIN, rel=1e-12)
    assert sensor.unloaded_voltage == pytest.approx(V_OFFSET, rel=1e-12)
    assert sensor.filter_time_constant == pytest.approx(TAU, rel=1e-12)
    assert sensor.saturation_force == pytest.approx(F_SAT, rel=1e-12)
    # 100 N -> 0.00375 + 4.5 V, inside the 5 V swing.
    assert sensor.static_output_voltage(100.0) == pytest.approx(4.50375, rel=1e-12)


def test_unloaded_sensor_reads_zero_at_start():
    sensor = FlexiForceSensor()
    context = _context(sensor)
    assert context.get_continuous_state_vector().GetAtIndex(0) == pytest.approx(V_OFFSET)
    assert _measured(sensor, context) == pytest.approx(0.0, abs=1e-12)
    # And it stays there: zero derivative when unloaded.
    assert _xdot(sensor, context) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("force", np.linspace(0.0, 100.0, 21))
def test_static_calibration_is_exact_without_linearity_error(force):
    sensor = FlexiForceSensor()
    voltage = V_OFFSET + GAIN * force  # hand-computed steady state of the filter
    assert sensor.static_output_voltage(force) == pytest.approx(voltage, rel=1e-12, abs=1e-15)
    context = _context(sensor, voltage=voltage, force=force)
    assert _xdot(sensor, context) == pytest.approx(0.0, abs=1e-9)
    assert _measured(sensor, context) == pytest.approx(force, abs=1e-9)


def test_linearity_error_bows_at_mid_range():
    sensor = FlexiForceSensor(linearity_error=0.03)
    forces = np.array([0.0, 25.0, 50.0, 75.0, 100.0])
    readings = []
    for force in forces:
        context = _context(sensor, voltage=sensor.static_output_voltage(force), force=force)
        readings.append(_measured(sensor, context))
    errors = np.array(readings) - forces
    # Bow 0.03 * 100 N * 4 u (1 - u): 0, 2.25, 3, 2.25, 0 N.
    np.testing.assert_allclose(errors, [0.0, 2.25, 3.0, 2.25, 0.0], atol=1e-9)
    # The peak of the error over a fine grid is at 50 N, 3 N (= 3 % of full scale).
    grid = np.linspace(0.0, 100.0, 1001)
    grid_errors = sensor.calibrated_force(sensor.static_output_voltage(grid)) - grid
    assert grid[np.argmax(grid_errors)] == pytest.approx(50.0)
    assert grid_errors.max() == pytest.approx(3.0, abs=1e-9)
    # A negative linearity error sags instead.
    sagging = FlexiForceSensor(linearity_error=-0.02)
    assert sagging.calibrated_force(sagging.static_output_voltage(50.0)) == pytest.approx(48.0)


@pytest.mark.parametrize("force", [112.0, 150.0, 500.0, 1e4])
def test_saturation_reads_saturation_force(force):
    sensor = FlexiForceSensor()
    assert sensor.static_output_voltage(force) == pytest.approx(5.0, abs=1e-12)
    context = _context(sensor, voltage=sensor.static_output_voltage(force), force=force)
    assert _measured(sensor, context) == pytest.approx(F_SAT, abs=1e-9)
    # Just below saturation the reading is still the force.
    context = _context(sensor, voltage=V_OFFSET + GAIN * 110.0, force=110.0)
    assert _measured(sensor, context) == pytest.approx(110.0, abs=1e-9)


def test_tension_drives_the_sensor_reading_to_zero_not_below():
    """A pulling (negative) contact force reads as no force: the filter is driven to the
    unloaded output V_offset, so the reading decays to 0 N and never goes negative."""
    sensor = FlexiForceSensor()
    # Unloaded and pulled at 20 N: the state stays at V_offset (dV/dt = 0), the reading 0 N.
    context = _context(sensor, voltage=V_OFFSET, force=-20.0)
    assert _xdot(sensor, context) == 0.0
    assert _measured(sensor, context) == pytest.approx(0.0, abs=1e-12)
    # Loaded (10 N on the filter state) and then pulled: dV/dt = (V_offset - V) / tau, the
    # decay towards V_offset, not towards V_offset + k (-20 N) = -0.896 V.
    loaded = V_OFFSET + GAIN * 10.0
    context = _context(sensor, voltage=loaded, force=-20.0)
    assert _xdot(sensor, context) == pytest.approx((V_OFFSET - loaded) * POLE, rel=1e-12)
    # Ten time constants later the reading is 10 N e^-10 = 0.45 mN above zero, not below.
    simulator = Simulator(sensor, context)
    simulator.get_mutable_integrator().set_target_accuracy(1e-9)
    simulator.AdvanceTo(10 * TAU)
    reading = _measured(sensor, context)
    assert reading == pytest.approx(10.0 * math.exp(-10.0), rel=1e-3)
    # The analysis helper describes the same law.
    assert sensor.static_output_voltage(-20.0) == pytest.approx(V_OFFSET, abs=1e-15)


def test_filter_derivative():
    sensor = FlexiForceSensor()
    context = _context(sensor, voltage=1.0, force=30.0, noise=0.4)
    # V_s = 0.00375 + 0.045 * 30 = 1.35375 V; dV/dt = (1.35375 - 1.0) * 2 pi 5000.
    expected = 0.35375 * POLE
    assert _xdot(sensor, context) == pytest.approx(expected, rel=1e-12)
    # Saturated: the filter is driven towards the 5 V rail, not beyond.
    context = _context(sensor, voltage=4.0, force=300.0)
    assert _xdot(sensor, context) == pytest.approx(1.0 * POLE, rel=1e-12)


def test_step_response_reaches_63_percent_at_tau():
    sensor = FlexiForceSensor()
    step = 50.0  # N, applied at t = 0 to an unloaded sensor
    simulator = Simulator(sensor)
    context = simulator.get_mutable_context()
    sensor.contact_force_input.FixValue(context, [step])
    sensor.noise_input.FixValue(context, [0.0])
    simulator.get_mutable_integrator().set_target_accuracy(1e-8)
    simulator.Initialize()
    assert _measured(sensor, context) == pytest.approx(0.0, abs=1e-12)
    simulator.AdvanceTo(TAU)
    fraction = _measured(sensor, context) / step
    assert fraction == pytest.approx(0.632, rel=0.01)
    assert fraction == pytest.approx(1.0 - math.exp(-1.0), rel=1e-4)
    simulator.AdvanceTo(10.0 * TAU)
    assert _measured(sensor, context) == pytest.approx(step * (1.0 - math.exp(-10.0)), rel=1e-4)


def test_noise_is_added_after_the_filter():
    sensor = FlexiForceSensor()
    voltage, noise = 2.0, 0.7
    context = _context(sensor, voltage=voltage, force=10.0, noise=noise)
    expected = (2.0 - 3.75e-3) / 0.045 + 0.7
    assert _measured(sensor, context) == pytest.approx(expected, rel=1e-12)
    assert _measured(sensor, context) == pytest.approx(
        sensor.calibrated_force(voltage) + noise, rel=1e-12
    )
    # Noise does not enter the filter.
    quiet = _context(sensor, voltage=voltage, force=10.0, noise=0.0)
    assert _xdot(sensor, context) == _xdot(sensor, quiet)


@pytest.mark.parametrize("force", [0.0, 3.25, 250.0, -1.5])
def test_ideal_kind_passes_through(force):
    sensor = FlexiForceSensor(kind="ideal")
    assert sensor.kind == "ideal"
    context = _context(sensor, force=force, noise=5.0)
    assert context.num_total_states() == 0
    assert sensor.num_continuous_states() == 0
    assert _measured(sensor, context) == force


def test_direct_feedthrough():
    flexiforce = FlexiForceSensor()
    force_in = flexiforce.contact_force_input.get_index()
    noise_in = flexiforce.noise_input.get_index()
    out = flexiforce.measured_force_output.get_index()
    assert not flexiforce.HasDirectFeedthrough(force_in, out)
    assert flexiforce.HasDirectFeedthrough(noise_in, out)
    ideal = FlexiForceSensor(kind="ideal")
    assert ideal.HasDirectFeedthrough(force_in, out)
    assert not ideal.HasDirectFeedthrough(noise_in, out)


def test_output_prerequisites_are_declared():
    """Declared, so Drake needs no symbolic analysis to see the (absent) feed-through."""
    flexiforce = FlexiForceSensor()
    entry = flexiforce.measured_force_output.cache_entry()
    assert not entry.has_default_prerequisites()
    assert entry.prerequisites() == {
        flexiforce.xc_ticket(),
        flexiforce.noise_input.ticket(),
    }
    # A new contact force leaves the reading's cached value valid; a new noise sample does not.
    context = _context(flexiforce, force=10.0)
    flexiforce.measured_force_output.Eval(context)
    flexiforce.contact_force_input.FixValue(context, [20.0])
    assert not entry.is_out_of_date(context)
    flexiforce.noise_input.FixValue(context, [0.1])
    assert entry.is_out_of_date(context)
    ideal = FlexiForceSensor(kind="ideal")
    assert ideal.measured_force_output.cache_entry().prerequisites() == {
        ideal.contact_force_input.ticket()
    }


@pytest.mark.parametrize("kind, loop_allowed", [("flexiforce", True), ("ideal", False)])
def test_feedback_through_contact_force(kind, loop_allowed):
    """measured_force -> contact_force is an algebraic loop only for the ideal kind."""
    builder = DiagramBuilder()
    sensor = builder.AddSystem(FlexiForceSensor(kind=kind))
    feedback = builder.AddSystem(Gain(1.0, 1))
    noise = builder.AddSystem(ConstantVectorSource([0.0]))
    builder.Connect(sensor.measured_force_output, feedback.get_input_port())
    builder.Connect(feedback.get_output_port(), sensor.contact_force_input)
    builder.Connect(noise.get_output_port(), sensor.noise_input)
    if loop_allowed:
        builder.Build()
    else:
        with pytest.raises(RuntimeError, match="algebraic loop"):
            builder.Build()


def test_autodiff_derivative_gain():
    sensor_ad = FlexiForceSensor().ToAutoDiffXd()
    context = sensor_ad.CreateDefaultContext()
    assert context.get_continuous_state_vector().GetAtIndex(0).value() == pytest.approx(V_OFFSET)
    sensor_ad.contact_force_input.FixValue(context, [AutoDiffXd(40.0, [1.0])])
    sensor_ad.noise_input.FixValue(context, [AutoDiffXd(0.0, [0.0])])
    xdot = _xdot(sensor_ad, context)
    # d(dV/dt)/dF = k / tau = 0.045 * 2 pi 5000 V/(N s).
    assert xdot.derivatives()[0] == pytest.approx(0.045 * POLE, rel=1e-12)
    # Saturated and in tension the slope is zero (an empty gradient also means zero).
    for force in (200.0, -5.0):
        sensor_ad.contact_force_input.FixValue(context, [AutoDiffXd(force, [1.0])])
        xdot = _xdot(sensor_ad, context)
        assert not np.any(xdot.derivatives())


def test_autodiff_keeps_constants():
    sensor_ad = FlexiForceSensor(linearity_error=0.03, filter_cutoff_hz=20.0).ToAutoDiffXd()
    context = sensor_ad.CreateDefaultContext()
    sensor_ad.contact_force_input.FixValue(context, [AutoDiffXd(50.0, [1.0])])
    sensor_ad.noise_input.FixValue(context, [AutoDiffXd(0.0, [0.0])])
    xdot = _xdot(sensor_ad, context)
    # At mid-range the bow's slope 0.12 * (1 - 2 u) vanishes: slope k * 40 pi.
    assert xdot.derivatives()[0] == pytest.approx(0.045 * 40.0 * math.pi, rel=1e-12)
    # V_s(50 N) = 0.00375 + 0.045 * (50 + 3) V.
    expected = (0.00375 + 0.045 * 53.0 - 0.00375) * 40.0 * math.pi
    assert xdot.value() == pytest.approx(expected, rel=1e-12)


def test_symbolic_derivative():
    sensor_sym = FlexiForceSensor().ToSymbolic()
    context = sensor_sym.CreateDefaultContext()
    force = Variable("force")
    sensor_sym.contact_force_input.FixValue(context, [force])
    sensor_sym.noise_input.FixValue(context, [0.0])
    xdot = _xdot(sensor_sym, context)
    assert xdot.Evaluate({force: 30.0}) == pytest.approx((0.045 * 30.0) * POLE)
    assert xdot.Evaluate({force: 1e3}) == pytest.approx((5.0 - 3.75e-3) * POLE)


def test_linearize():
    sensor = FlexiForceSensor()
    context = _context(sensor, voltage=V_OFFSET + GAIN * 20.0, force=20.0)
    # Linearize (which converts to AutoDiffXd) uses the first input, contact_force.
    linear = Linearize(sensor, context)
    np.testing.assert_allclose(linear.A(), [[-POLE]], rtol=1e-12)
    np.testing.assert_allclose(linear.B(), [[0.045 * POLE]], rtol=1e-12)
    np.testing.assert_allclose(linear.C(), [[1.0 / 0.045]], rtol=1e-12)
    np.testing.assert_allclose(linear.D(), [[0.0]], atol=1e-15)


@pytest.mark.parametrize(
    "argument, value",
    [
        ("kind", "strain_gauge"),
        ("conductance_per_newton", 0.0),
        ("conductance_per_newton", -6e-7),
        ("conductance_per_newton", float("nan")),
        ("unloaded_conductance", -1e-9),
        ("unloaded_conductance", 1e-6),
        ("drive_voltage", 0.5),
        ("drive_voltage", 0.0),
        ("feedback_resistance", 0.0),
        ("feedback_resistance", float("inf")),
        ("rail_voltage", 1e-3),
        ("filter_cutoff_hz", 0.0),
        ("filter_cutoff_hz", -50.0),
        ("linearity_error", 0.25),
        ("linearity_error", -0.3),
        ("full_scale_force", 0.0),
        ("full_scale_force", "a lot"),
        ("full_scale_force", None),
        ("unloaded_conductance", float("inf")),
        ("rail_voltage", V_OFFSET),
        ("feedback_resistance", -150e3),
        ("full_scale_force", -100.0),
        # Just past the datasheet's 5 MOhm: 1 / 4.9999999 MOhm = 2.00000004e-7 S.
        ("unloaded_conductance", 1.0 / 4.9999999e6),
    ],
)
def test_bad_arguments_raise(argument, value):
    with pytest.raises(ValueError, match=argument):
        FlexiForceSensor(**{argument: value})


@pytest.mark.parametrize(
    "argument, value",
    [
        ("unloaded_conductance", 0.0),
        ("unloaded_conductance", 2e-7),
        ("linearity_error", 0.249),
        ("linearity_error", -0.249),
        ("rail_voltage", 0.01),
        ("conductance_per_newton", 1e-9),
        ("feedback_resistance", 0.5),
        ("filter_cutoff_hz", 0.5),
        ("full_scale_force", 0.5),
    ],
)
def test_arguments_at_the_edge_of_their_range_are_accepted(argument, value):
    """The allowed ranges include their closed ends (0 and 2e-7 S for G0) and stop just
    inside their open ones (|e| < 0.25, V_rail > V_offset, the other constants > 0)."""
    sensor = FlexiForceSensor(**{argument: value})
    context = _context(sensor, voltage=sensor.unloaded_voltage)
    assert _measured(sensor, context) == pytest.approx(0.0, abs=1e-12)


def test_bow_vanishes_above_full_scale_in_the_system_and_the_helper():
    """u = min(F / F_fs, 1): above full scale (here 105 N, below saturation) the bow is zero,
    so the reading is exact again, in the sensor's own law and in the analysis helper."""
    sensor = FlexiForceSensor(linearity_error=0.03)
    voltage = sensor.static_output_voltage(105.0)
    assert voltage == pytest.approx(V_OFFSET + GAIN * 105.0, rel=1e-12)
    context = _context(sensor, voltage=voltage, force=105.0)
    assert _xdot(sensor, context) == pytest.approx(0.0, abs=1e-6)
    assert _measured(sensor, context) == pytest.approx(105.0, abs=1e-9)


@pytest.mark.parametrize("error", [0.0025, -0.0025, -0.03])
def test_the_bow_bends_the_sensor_law_and_the_helper_alike(error):
    """b = 4 e F_fs: +-1 N for e = +-0.0025 (a reading off by +-0.25 N at 50 N) and -12 N for
    a sagging e = -0.03 (-3 N at 50 N), in the filter's input and in the helper."""
    sensor = FlexiForceSensor(linearity_error=error)
    bowed = 50.0 + error * 100.0
    assert sensor.calibrated_force(sensor.static_output_voltage(50.0)) == pytest.approx(bowed)
    context = _context(sensor, voltage=V_OFFSET, force=50.0)
    assert _xdot(sensor, context) == pytest.approx(GAIN * bowed * POLE, rel=1e-12)


def test_arguments_are_keyword_only():
    """Nine numbers of different units: a positional call could swap them unnoticed."""
    with pytest.raises(TypeError):
        FlexiForceSensor("flexiforce", 6.0e-7)


def test_the_ideal_kind_has_no_state_to_integrate():
    # The kind is compared by value: a string built at run time (from a YAML file, say).
    sensor = FlexiForceSensor(kind="".join(["id", "eal"]))
    context = _context(sensor, force=3.0)
    assert sensor.EvalTimeDerivatives(context).size() == 0


def test_a_bad_linearity_error_message_gives_the_open_range():
    with pytest.raises(ValueError, match=r"linearity_error must be in \(-0.25, 0.25\); got 0.3"):
        FlexiForceSensor(linearity_error=0.3)


def test_the_helpers_return_a_float_for_a_float_and_an_array_for_an_array():
    sensor = FlexiForceSensor()
    assert isinstance(sensor.static_output_voltage(5.0), float)
    assert isinstance(sensor.calibrated_force(0.5), float)
    np.testing.assert_allclose(
        sensor.static_output_voltage(np.array([0.0, 10.0])), [V_OFFSET, V_OFFSET + GAIN * 10.0]
    )
    np.testing.assert_allclose(
        sensor.calibrated_force(np.array([V_OFFSET, 1.0])), [0.0, (1.0 - V_OFFSET) / GAIN]
    )


def test_autodiff_reading_is_the_calibrated_voltage_plus_the_noise():
    """The generic output law: dF_meas/dV = 1 / k and dF_meas/dn = 1."""
    sensor_ad = FlexiForceSensor().ToAutoDiffXd()
    context = sensor_ad.CreateDefaultContext()
    context.SetContinuousState([AutoDiffXd(2.0, [1.0, 0.0])])
    sensor_ad.contact_force_input.FixValue(context, [AutoDiffXd(10.0, [0.0, 0.0])])
    sensor_ad.noise_input.FixValue(context, [AutoDiffXd(0.7, [0.0, 1.0])])
    reading = sensor_ad.measured_force_output.Eval(context)[0]
    assert reading.value() == pytest.approx((2.0 - V_OFFSET) / GAIN + 0.7, rel=1e-12)
    np.testing.assert_allclose(reading.derivatives(), [1.0 / GAIN, 1.0], rtol=1e-12)
