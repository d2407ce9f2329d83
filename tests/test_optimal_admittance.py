"""The optimal admittance block: the corrected sign of eq. 10, its derivative-free form, and
its sampled version, against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.analysis import Simulator

from admittance.systems.optimal_admittance import OptimalAdmittance, OptimalAdmittanceLaw

GAMMA, ALPHA, K = 1e-5, 0.1, 2500.0  # the paper's x-axis values (docs/evidence/paper-notes.md §4)


def _block(**kwargs):
    arguments = dict(gamma=GAMMA, alpha=ALPHA, stiffness=K, force_axes=[0], num_axes=3)
    arguments.update(kwargs)
    return OptimalAdmittance(**arguments)


def _context(block, measured, desired, *, integral=0.0, initial_error=None):
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [measured])
    block.desired_force_input.FixValue(context, [desired])
    block.set_integral(context, [integral])
    block.set_initial_force_error(
        context, [desired - measured if initial_error is None else initial_error]
    )
    return context


def _sampled_update(block, context):
    """The sampled block's next (integral, held offset): its two discrete state groups."""
    updated = block.EvalUniquePeriodicDiscreteUpdate(context)
    return (updated.get_vector(group).CopyToVector() for group in (0, 1))


def test_output_is_the_derivative_free_law():
    block = _block()
    # E = 5 - 3 = 2 N, E0 = 5 N, z = 0.4 N s:
    # Xr = Gamma K (z + alpha (E - E0)) = 0.025 * (0.4 + 0.1 * (2 - 5)) = 0.0025 m.
    context = _context(block, measured=3.0, desired=5.0, integral=0.4, initial_error=5.0)
    offset = block.reference_offset_output.Eval(context)
    np.testing.assert_allclose(offset, [0.0025, 0.0, 0.0], rtol=0, atol=1e-15)
    derivatives = block.EvalTimeDerivatives(context).CopyToVector()
    np.testing.assert_allclose(derivatives, [2.0])


@pytest.mark.parametrize(
    "measured, direction", [(2.0, +1.0), (8.0, -1.0)], ids=["below_Fr", "above_Fr"]
)
def test_sign_moves_reference_toward_the_wall_while_force_is_low(measured, direction):
    """docs/evidence/paper-notes.md §2: F < Fr => Xr grows along +x (into the wall); F > Fr => it
    recedes."""
    block = _block()
    context = _context(block, measured=measured, desired=5.0)
    simulator = Simulator(block, context)
    simulator.AdvanceTo(0.2)
    offset = block.reference_offset_output.Eval(context)[0]
    # Constant E with E0 = E: Xr(t) = Gamma K E t exactly.
    error = 5.0 - measured
    assert np.sign(offset) == direction
    assert offset == pytest.approx(GAMMA * K * error * 0.2, rel=1e-9)


def test_gradient_flow_rate_matches_eq_10_prime():
    """dXr/dt = Gamma K (E + alpha dE/dt) for a force that ramps (checked by AutoDiff)."""
    # The converted block is a plain Diagram (its ports by name, z the state of its
    # Integrator); E0, a constant, is left at its default: it does not enter dXr/dt.
    block = _block().ToAutoDiffXd()
    context = block.CreateDefaultContext()
    # Time-varying inputs as AutoDiff values with d/dt: F = 3 + 4 t, z = 0.4, dz/dt = E.
    measured = 3.0
    rate = 4.0  # dF/dt, so dE/dt = -4
    error = 5.0 - measured
    z = AutoDiffXd(0.4, [error])
    block.GetInputPort("measured_force").FixValue(context, [AutoDiffXd(measured, [rate])])
    block.GetInputPort("desired_force").FixValue(context, [AutoDiffXd(5.0, [0.0])])
    context.SetContinuousState([z])
    offset = block.GetOutputPort("reference_offset").Eval(context)[0]
    expected_rate = GAMMA * K * (error + ALPHA * (-rate))
    assert offset.derivatives()[0] == pytest.approx(expected_rate, rel=1e-12)


def test_default_block_controls_x_of_a_planar_pose():
    """Without force_axes and num_axes: the x axis of (x, y, theta), continuous."""
    block = OptimalAdmittance(gamma=GAMMA, alpha=ALPHA, stiffness=K, force_axes=(0,), num_axes=3)
    assert block.force_axes == [0] and block.period == 0.0
    context = _context(block, measured=3.0, desired=5.0, integral=0.4, initial_error=5.0)
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.0025, 0.0, 0.0])


def test_arguments_are_keyword_only():
    """Gamma, alpha and K are all numbers: a positional call could swap them unnoticed."""
    with pytest.raises(TypeError):
        OptimalAdmittance(GAMMA, ALPHA, K)
    # The law inside takes every argument by keyword too (it is public, and built alone
    # by whoever assembles their own Diagram around it).
    rest = dict(force_axes=[0], num_axes=3, period=0.0, max_push=1.0, max_retract=1.0)
    with pytest.raises(TypeError):
        OptimalAdmittanceLaw(GAMMA, ALPHA, K, **rest, max_force=math.inf, force_bound_gain=4.0)


def test_equivalent_pi_gains():
    block = _block()
    assert block.integral_gain[0] == pytest.approx(GAMMA * K)
    assert block.proportional_gain[0] == pytest.approx(GAMMA * K * ALPHA)


def test_only_force_axes_move():
    block = _block(force_axes=[1], gamma=[2e-5], alpha=[0.0], stiffness=[1000.0])
    context = _context(block, measured=0.0, desired=1.0, integral=3.0)
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.0, 0.06, 0.0])


def test_sampled_law_latches_and_integrates():
    period = 0.001
    block = _block(period=period)
    assert block.period == period
    context = _context(block, measured=3.0, desired=5.0, integral=0.2, initial_error=5.0)
    # Output is the held value (0 at start) and does not feed through the force.
    assert block.reference_offset_output.Eval(context)[0] == 0.0
    assert not block.HasDirectFeedthrough(
        block.measured_force_input.get_index(), block.reference_offset_output.get_index()
    )
    # No continuous state: nothing to integrate between samples.
    assert block.EvalTimeDerivatives(context).size() == 0
    integral, held = _sampled_update(block, context)
    # E = 2 N: z[k+1] = 0.2 + 0.001 * 2; Xr[k] = 0.025 * (0.2 + 0.1 * (2 - 5)) = -0.0025 on
    # axis x, held for the output port (the other axes hold 0).
    np.testing.assert_allclose(integral, [0.202], atol=1e-15)
    np.testing.assert_allclose(held, [-0.0025, 0.0, 0.0], atol=1e-15)


def test_sampled_law_latches_its_first_sample_at_t_0():
    """The first sample is taken at t = 0 (offset 0), then every period: after 1.5 periods
    the held Xr is the second sample's, Gamma K (z0 + h E + alpha (E - E0)). (30 ms: 1 s is
    no whole number of periods, so no other offset gives the same sample times.)"""
    period = 0.03
    block = _block(period=period)
    context = _context(block, measured=3.0, desired=5.0, integral=0.2, initial_error=5.0)
    Simulator(block, context).AdvanceTo(1.5 * period)
    expected = GAMMA * K * (0.2 + period * 2.0 + ALPHA * (2.0 - 5.0))
    assert block.reference_offset_output.Eval(context)[0] == pytest.approx(expected, rel=1e-12)


def test_sampled_law_on_three_axes_keeps_one_integral_and_one_held_offset_each():
    block = _block(
        force_axes=[0, 1, 2], gamma=[GAMMA] * 3, alpha=[ALPHA] * 3, stiffness=[K] * 3, period=0.001
    )
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [3.0, 4.0, 6.0])
    block.desired_force_input.FixValue(context, [5.0, 5.0, 5.0])
    integral, held = _sampled_update(block, context)
    errors = np.array([2.0, 1.0, -1.0])
    np.testing.assert_allclose(integral, 0.001 * errors)
    np.testing.assert_allclose(held, GAMMA * K * ALPHA * errors)


def test_continuous_law_on_three_axes_keeps_each_axis_to_its_own_integral():
    """Three force axes, one integral each: Xr_i = Gamma K (z_i + alpha (E_i - E0_i)) and
    dz_i/dt = E_i, with E0 = 0 (the default). By hand: E = (2, 1, -1) N, z = (0.1, 0.2, 0.3)
    N s, Gamma K = 0.025 m/(N s), alpha = 0.1 s."""
    block = _block(force_axes=[0, 1, 2], gamma=[GAMMA] * 3, alpha=[ALPHA] * 3, stiffness=[K] * 3)
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [3.0, 4.0, 6.0])
    block.desired_force_input.FixValue(context, [5.0, 5.0, 5.0])
    block.set_integral(context, [0.1, 0.2, 0.3])
    errors = np.array([2.0, 1.0, -1.0])
    expected = 0.025 * (np.array([0.1, 0.2, 0.3]) + 0.1 * errors)  # (5, 7.5, 5) mm
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), expected, rtol=1e-12)
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), errors)


def test_the_continuous_law_has_no_integral_state_to_set():
    """The continuous law's z is its input (the Integrator's state): setting it on the law
    alone is refused, and the block sets the Integrator's."""
    block = _block()
    with pytest.raises(ValueError, match="integral is its input"):
        block.law.set_integral(block.law.CreateDefaultContext(), [0.4])


def test_sampled_anti_windup_time_constant_is_five_periods():
    """Past max_push the sampled integral is pulled back at (Xr_clamped - Xr) / (Gamma K
    tau_aw) with tau_aw = max(10 ms, 5 periods): 50 ms at a 10 ms period."""
    period = 0.01
    block = _block(period=period, max_push=0.01)
    context = _context(block, measured=1.0, desired=5.0, integral=1.0, initial_error=4.0)
    integral, held = _sampled_update(block, context)
    unclamped = GAMMA * K * 1.0  # z = 1, E = E0: 0.025 m, past the 0.01 m bound
    rate = 4.0 + (0.01 - unclamped) / (GAMMA * K * 5 * period)
    np.testing.assert_allclose(integral, [1.0 + period * rate], rtol=1e-12)
    np.testing.assert_allclose(held, [0.01, 0.0, 0.0], rtol=1e-12)


def test_continuous_law_feeds_through_the_force():
    block = _block()
    assert block.HasDirectFeedthrough(
        block.measured_force_input.get_index(), block.reference_offset_output.get_index()
    )


def test_autodiff_gain_of_output_to_force():
    block = _block().ToAutoDiffXd()
    context = block.CreateDefaultContext()
    block.GetInputPort("measured_force").FixValue(context, [AutoDiffXd(3.0, [1.0])])
    block.GetInputPort("desired_force").FixValue(context, [AutoDiffXd(5.0, [0.0])])
    offset = block.GetOutputPort("reference_offset").Eval(context)[0]
    assert offset.derivatives()[0] == pytest.approx(-GAMMA * K * ALPHA)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(gamma=0.0), "gamma"),
        (dict(gamma=-1e-5), "gamma"),
        (dict(alpha=-0.1), "alpha"),
        (dict(stiffness=0.0), "stiffness"),
        (dict(force_axes=[3]), "force_axes"),
        (dict(force_axes=[]), "force_axes"),
        (dict(force_axes=[0, 0]), "force_axes must be distinct"),
        (dict(force_axes=[-1]), "force_axes must be distinct"),
        (dict(force_axes=[4]), r"force_axes must be distinct indices in \[0, 2\], got \[4\]"),
        (dict(gamma=math.inf), "gamma must be finite"),
        (dict(alpha=math.nan), "alpha must be finite"),
        (dict(period=-1.0), "period"),
        (dict(max_push=0.0), "max_push must be > 0"),
        (dict(max_push=-0.01), "max_push must be > 0"),
        (dict(max_push=math.nan), "max_push must be > 0"),
        (dict(max_retract=0.0), "max_retract must be > 0"),
        (dict(max_retract=math.nan), "max_retract must be > 0"),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _block(**kwargs)


def test_force_bound_leaves_the_law_alone_below_the_guard_level():
    """Fmax = 10 N, Fr = 5 N: the guard level is 7.5 N; at 7 N the law is the paper's."""
    bounded, free = _block(max_force=10.0), _block()
    contexts = [
        _context(block, measured=7.0, desired=5.0, integral=0.3, initial_error=5.0)
        for block in (bounded, free)
    ]
    np.testing.assert_allclose(
        bounded.reference_offset_output.Eval(contexts[0]),
        free.reference_offset_output.Eval(contexts[1]),
    )
    np.testing.assert_allclose(bounded.EvalTimeDerivatives(contexts[0]).CopyToVector(), [-2.0])


@pytest.mark.parametrize("measured", [12.0, 20.0])
def test_force_bound_penalises_the_force_above_the_guard_level(measured):
    """Fmax = 10 N, Fr = 5 N, the default mu = 4: E_b = E - mu (F - Fg), Fg = 7.5 N, in both
    paths (at 12 N: -7 - 4 * 4.5 = -25 N; at 20 N: -15 - 4 * 12.5 = -65 N)."""
    block = _block(max_force=10.0)
    context = _context(block, measured=measured, desired=5.0, integral=0.3, initial_error=5.0)
    bounded_error = (5.0 - measured) - 4.0 * (measured - 7.5)
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [bounded_error])
    offset = block.reference_offset_output.Eval(context)[0]
    assert offset == pytest.approx(GAMMA * K * (0.3 + ALPHA * (bounded_error - 5.0)), rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(max_force=0.0), "max_force must be > 0"),
        (dict(max_force=-1.0), "max_force must be > 0"),
        (dict(max_force=math.nan), "max_force must be > 0"),
        (dict(force_bound_gain=0.0), "force_bound_gain must be > 0"),
        (dict(force_bound_gain=-1.0), "force_bound_gain must be > 0"),
        (dict(force_bound_gain=math.inf), "force_bound_gain must be > 0"),
    ],
)
def test_force_bound_arguments_are_checked(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _block(**kwargs)


def test_small_positive_force_bound_arguments_are_accepted():
    """The checks are > 0, not >= 1: a 0.5 N bound and a gain of 0.5 are valid."""
    block = _block(max_force=0.5, force_bound_gain=0.5)
    context = _context(block, measured=1.0, desired=0.25, integral=0.0, initial_error=0.0)
    # Fg = 0.375 N: E_b = -0.75 - 0.5 (1 - 0.375) = -1.0625 N.
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [-1.0625])


def test_autodiff_law_takes_a_broken_reading_as_zero_error():
    """NaN from the sensor in the AutoDiffXd law (what Linearize uses): E = 0, with no
    derivative, so the integral freezes and Xr holds, as in the float law (E0 = 0, the
    default)."""
    block = _block().ToAutoDiffXd()
    context = block.CreateDefaultContext()
    block.GetInputPort("measured_force").FixValue(context, [AutoDiffXd(math.nan, [1.0])])
    block.GetInputPort("desired_force").FixValue(context, [AutoDiffXd(5.0, [0.0])])
    context.SetContinuousState([AutoDiffXd(0.4, [0.0])])
    (rate,) = block.EvalTimeDerivatives(context).CopyToVector()
    assert rate.value() == 0.0
    np.testing.assert_array_equal(rate.derivatives(), 0.0)
    offset = block.GetOutputPort("reference_offset").Eval(context)[0]
    assert offset.value() == pytest.approx(GAMMA * K * 0.4, rel=1e-12)
