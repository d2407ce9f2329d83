"""The sensor monitor (systems/fault_detector.py), one ADC sample at a time: each fault is
flagged after the number of samples its rule says, and the held value is the reading
before the fault."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.closed_loop import SolvePlanarInverseKinematics
from admittance.systems.fault_detector import FAULT_FLAGS, SensorFaultDetector

PERIOD = 0.005
NOISE = 0.02
FULL_SCALE = 111.03
TOLERANCE = 1.0 + 6 * NOISE  # 0.2 Fr + 6 sigma, as the layer sets it for Fr = 5 N


@pytest.fixture
def monitor(arm_plant):
    detector = SensorFaultDetector(
        arm_plant,
        period=PERIOD,
        noise_std=NOISE,
        saturation_force=FULL_SCALE,
        contact_force=0.5,
        force_tolerance=TOLERANCE,
        observer_gain=100.0,
    )
    context = detector.CreateDefaultContext()
    q = SolvePlanarInverseKinematics(
        arm_plant, "fingertip", [0.2, -0.25, math.pi / 2], [-0.45, 1.66, 0.36]
    )
    detector.estimated_state_input.FixValue(context, np.concatenate([q, np.zeros(3)]))  # at rest
    detector.stiffness_estimate_input.FixValue(context, [5e4])
    detector.observed_force_input.FixValue(context, [5.0])
    detector.measured_force_input.FixValue(context, [5.0])
    detector.set_reading(context, 5.0)
    return detector, context


def _sample(monitor, reading, observed=5.0):
    """One ADC sample: the reading arrives, the periodic update runs; flags after it."""
    detector, context = monitor
    detector.measured_force_input.FixValue(context, [reading])
    detector.observed_force_input.FixValue(context, [observed])
    update = detector.EvalUniquePeriodicDiscreteUpdate(context)
    context.get_mutable_discrete_state().SetFrom(update)
    flags = detector.fault_flags_output.Eval(context)
    return dict(zip(FAULT_FLAGS, flags > 0.5, strict=True))


def _trusted(monitor) -> float:
    detector, context = monitor
    return detector.trusted_force_output.Eval(context)[0]


def _noisy(count, seed=1, mean=5.0):
    return mean + NOISE * np.random.default_rng(seed).standard_normal(count)


def test_a_noisy_reading_that_agrees_with_the_arm_raises_nothing(monitor):
    for reading in _noisy(2000):
        assert not any(_sample(monitor, reading).values())
        assert _trusted(monitor) == reading


def test_a_reading_that_is_not_finite_is_flagged_at_once_and_the_last_one_held(monitor):
    for reading in _noisy(3):
        _sample(monitor, reading)
    last = reading
    detector, context = monitor
    detector.measured_force_input.FixValue(context, [math.nan])
    flags = detector.fault_flags_output.Eval(context)
    assert flags[FAULT_FLAGS.index("nonfinite")] == 1.0
    assert detector.sensor_fault_output.Eval(context)[0] == 1.0
    # The held value is the reading of the sample before the last clean one.
    assert _trusted(monitor) in (last, *_noisy(3)[:2])
    assert math.isfinite(_trusted(monitor))


def test_saturated_is_98_percent_of_full_scale(monitor):
    detector, context = monitor
    detector.measured_force_input.FixValue(context, [0.98 * FULL_SCALE])
    assert detector.fault_flags_output.Eval(context)[FAULT_FLAGS.index("saturated")] == 1.0
    detector.measured_force_input.FixValue(context, [0.97 * FULL_SCALE])
    assert detector.sensor_fault_output.Eval(context)[0] == 0.0


def test_stuck_is_flagged_at_the_third_unchanged_sample_and_clears_after_four(monitor):
    """The onset sample jumps (no evidence); then three unchanged samples (each below
    sigma / 100 of change) flag it: 15 ms at T = 5 ms. Four varying samples clear it."""
    before = _noisy(5)
    for reading in before:
        _sample(monitor, reading)
    flagged = [_sample(monitor, 4.9)["stuck"] for _ in range(4)]
    assert flagged == [False, False, False, True]
    assert _trusted(monitor) == before[-1]  # the reading before the onset
    recovery = [_sample(monitor, reading)["stuck"] for reading in _noisy(5, seed=2)]
    assert recovery == [True, True, True, False, False]


def test_a_constant_reading_is_not_stuck_when_no_noise_is_expected_and_the_arm_is_still(
    arm_plant, monitor
):
    detector, context = monitor
    quiet = SensorFaultDetector(
        arm_plant,
        period=PERIOD,
        noise_std=0.0,
        saturation_force=FULL_SCALE,
        contact_force=0.5,
        force_tolerance=1.0,
        observer_gain=100.0,
    )
    quiet_context = quiet.CreateDefaultContext()
    for port in ("estimated_state", "stiffness_estimate", "observed_force"):
        quiet.GetInputPort(port).FixValue(quiet_context, detector.GetInputPort(port).Eval(context))
    quiet.set_reading(quiet_context, 5.0)
    flags = [_sample((quiet, quiet_context), 5.0) for _ in range(10)]
    assert not any(any(f.values()) for f in flags)


def test_implausible_is_flagged_three_samples_after_the_onset(monitor):
    """The reading varies like noise around 2 N while the arm's observer says 5 N: a
    discrepancy of 3 N against a tolerance of 1.12 N plus the lag allowance
    |dr| / (T K_o) (0.02-0.06 N here). The onset sample jumped by 3 N: its allowance,
    3 / (0.005 * 100) = 6 N, hides it; the next three are evidence."""
    for reading in _noisy(5):
        _sample(monitor, reading)
    flags = [_sample(monitor, r)["implausible"] for r in _noisy(5, seed=3, mean=2.0)]
    assert flags == [False, False, False, True, True]
    assert _trusted(monitor) == pytest.approx(5.0, abs=4 * NOISE)


def test_a_fast_genuine_change_is_allowed_by_its_own_rate(monitor):
    """A real force rising 2 N per sample (400 N/s, a stiff wall being loaded) while the
    observer lags 1/K_o = 10 ms behind (4 N): the allowance (2 / 0.005) / 100 = 4 N
    covers it."""
    for k, reading in enumerate(5.0 + 2.0 * np.arange(6)):
        assert not _sample(monitor, reading + NOISE * (-1) ** k, observed=reading - 4.0)[
            "implausible"
        ]


def test_a_modest_disagreement_beyond_the_tolerance_is_flagged(monitor):
    """1.5 N below the arm's estimate, with the noise's sample-to-sample changes (at most
    about 0.1 N here): 1.5 > 1.12 + 0.1 / (0.005 * 100) = 1.32 N, so it is caught; the lag
    allowance must not swallow it."""
    for reading in _noisy(5):
        _sample(monitor, reading)
    flags = [_sample(monitor, r)["implausible"] for r in _noisy(6, seed=4, mean=3.5)]
    assert flags[-1]
