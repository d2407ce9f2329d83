"""The sensor monitor (systems/fault_detector.py), one ADC sample at a time: each fault is
flagged after the number of samples its rule says, and the held value is the reading
before the fault."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import (
    FAULT_FLAGS,
    FaultDetectorParams,
    SensorFaultDetector,
    plausibility_allowance,
)
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

PERIOD = 0.005
NOISE = 0.02
FULL_SCALE = 111.03
TOLERANCE = 1.0 + 6 * NOISE  # 0.2 Fr + 6 sigma, as the layer sets it for Fr = 5 N
# The fingertip, X = (x, y, theta) in world, the wall's normal x.
TIP = ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0)
# The monitor of these tests: T = 5 ms, sigma = 0.02 N, F_c = 0.5 N, K_o = 100 1/s.
DETECTOR = FaultDetectorParams(
    period=PERIOD,
    noise_std=NOISE,
    saturation_force=FULL_SCALE,
    contact_force=0.5,
    force_tolerance=TOLERANCE,
    observer_gain=100.0,
)


def _detector(arm_plant, **overrides):
    """The monitor of these tests (DETECTOR), with `overrides`."""
    return SensorFaultDetector(
        arm_plant, contact=TIP, params=dataclasses.replace(DETECTOR, **overrides)
    )


def _at_the_pose(arm_plant, detector, tip_velocity=(0.0, 0.0, 0.0)):
    """A context of `detector` with the tip at (0.2, -0.25, pi/2) moving at `tip_velocity`
    (x, y, theta rates) and k_hat = 5e4 N/m."""
    context = detector.CreateDefaultContext()
    q = SolvePlanarInverseKinematics(
        arm_plant,
        "fingertip",
        [0.2, -0.25, math.pi / 2],
        [-0.45, 1.66, 0.36],
        coordinates=PLANAR_COORDINATES,
    )
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    v = np.linalg.solve(kinematics.jacobian(), tip_velocity)
    detector.estimated_state_input.FixValue(context, np.concatenate([q, v]))
    detector.stiffness_estimate_input.FixValue(context, [5e4])
    return context


@pytest.fixture
def monitor(arm_plant):
    detector = _detector(arm_plant)
    context = _at_the_pose(arm_plant, detector)  # at rest
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
    quiet = _detector(arm_plant, noise_std=0.0, force_tolerance=1.0)
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


def test_the_detection_delay_is_the_onset_and_three_samples_of_evidence(monitor):
    """The stuck and implausible rules flag at the third sample of evidence after the onset
    sample (the tests above): the longest delay the law must allow for is 4 T = 20 ms. The
    monitor samples at t = 0, T, 2T, ... (the ADC's clock)."""
    detector, _ = monitor
    assert detector.period == PERIOD
    assert detector.detection_delay == pytest.approx(4 * PERIOD, rel=1e-15)
    event = detector.GetUniquePeriodicDiscreteUpdateAttribute()
    assert (event.period_sec(), event.offset_sec()) == (PERIOD, 0.0)


@pytest.mark.parametrize(
    "name, value, message",
    [
        ("period", 0.0, "period must be > 0"),
        ("saturation_force", -0.5, "saturation_force must be > 0"),
        ("contact_force", math.inf, "contact_force must be > 0"),
        ("force_tolerance", 0.0, "force_tolerance must be > 0"),
        ("observer_gain", math.nan, "observer_gain must be > 0"),
        ("noise_std", -0.5, "noise_std must be >= 0 N"),
    ],
)
def test_bad_arguments_name_the_argument(arm_plant, name, value, message):
    with pytest.raises(ValueError, match=message):
        _detector(arm_plant, **{name: value})


def _quiet_moving(arm_plant, tip_velocity, noise_std=0.0):
    """A monitor that expects no noise (unless given, F_tol = 1 N), with the tip at the test
    pose moving at `tip_velocity` (x, y, theta rates) and k_hat = 5e4 N/m."""
    detector = _detector(arm_plant, noise_std=noise_std, force_tolerance=1.0)
    return detector, _at_the_pose(arm_plant, detector, tip_velocity)


@pytest.mark.parametrize(
    "tip_velocity, reading, observed, stuck",
    [
        # Into the wall at 1 cm/s: k_hat |x'| T = 5e4 * 0.01 * 0.005 = 2.5 N > F_tol per
        # sample, and the reading does not move: stuck, at the third sample.
        ([0.01, 0.0, 0.0], 5.0, 5.0, [False, False, True]),
        # Along the wall (y), or turning: no change of the normal force is predicted.
        ([0.0, 0.01, 0.0], 5.0, 5.0, [False] * 3),
        ([0.0, 0.0, 0.5], 5.0, 5.0, [False] * 3),
        # At 1 mm/s the predicted change, 0.25 N per sample, is within F_tol: plausible.
        ([0.001, 0.0, 0.0], 5.0, 5.0, [False] * 3),
        # Out of contact (reading and observer both below F_c = 0.5 N): nothing to see.
        ([0.01, 0.0, 0.0], 0.0, 0.0, [False] * 3),
        # In contact when either the reading or the arm's observer is at or above F_c: a
        # reading stuck at zero while the observer feels 5 N (or exactly F_c) is stuck, and
        # so is one at 5 N (or exactly F_c) that the observer does not confirm.
        ([0.01, 0.0, 0.0], 0.0, 5.0, [False, False, True]),
        ([0.01, 0.0, 0.0], 0.0, 0.5, [False, False, True]),
        ([0.01, 0.0, 0.0], 5.0, 0.0, [False, False, True]),
        ([0.01, 0.0, 0.0], 0.5, 0.0, [False, False, True]),
    ],
)
def test_a_constant_reading_is_stuck_when_the_tip_moves_in_contact(
    arm_plant, tip_velocity, reading, observed, stuck
):
    monitor = _quiet_moving(arm_plant, tip_velocity)
    monitor[0].set_reading(monitor[1], reading)
    assert [_sample(monitor, reading, observed)["stuck"] for _ in range(3)] == stuck


@pytest.mark.parametrize("step", [2.5, 1e-6])
def test_a_reading_that_follows_the_tip_into_the_wall_is_not_stuck(arm_plant, step):
    """The tip presses on at 1 cm/s and the reading rises with it (2.5 N per sample), as the
    observer does: a genuine change, neither stuck nor implausible. With no noise expected,
    any change above 1e-9 N is a change (1e-6 N per sample here)."""
    monitor = _quiet_moving(arm_plant, [0.01, 0.0, 0.0])
    monitor[0].set_reading(monitor[1], 5.0)
    for k in range(1, 6):
        assert not any(_sample(monitor, 5.0 + step * k, observed=5.0 + step * k).values())


def test_the_plausibility_allowance_by_hand():
    """(|dr| + |dF_hat|) / (T K_o): 0.1 N and 0.4 N of change in one 5 ms sample against
    K_o = 100 1/s is 0.5 / 0.5 = 1 N; the sign of either change does not matter."""
    assert plausibility_allowance(0.1, 0.4, PERIOD, 100.0) == pytest.approx(1.0, rel=1e-12)
    assert plausibility_allowance(-0.1, -0.4, PERIOD, 100.0) == pytest.approx(1.0, rel=1e-12)
    assert plausibility_allowance(0.0, 0.0, PERIOD, 100.0) == 0.0


@pytest.mark.parametrize("gap, flagged", [(5.9975, False), (6.0025, True)])
def test_the_plausibility_allowance_is_the_reading_s_rate_and_the_observer_s(
    arm_plant, gap, flagged
):
    """The tip still, the reading and the observer both rising 1.25 N per sample (250 N/s),
    the observer `gap` above the reading: the allowance F_tol + (250 + 250) / K_o = 6 N
    covers 5.9975 N and not 6.0025 N (2.5 mN either side, far above rounding). The first
    sample has no observer rate yet (allowance 3.5 N: one sample of evidence, not three)."""
    monitor = _quiet_moving(arm_plant, [0.0, 0.0, 0.0])
    monitor[0].set_reading(monitor[1], 5.0)
    flags = []
    for k in range(1, 7):
        reading = 5.0 + 1.25 * k
        flags.append(_sample(monitor, reading, observed=reading + gap)["implausible"])
    assert flags == ([False] * 6 if not flagged else [False, False, True, True, True, True])


def test_a_tip_following_a_moving_wall_does_not_widen_the_allowance(arm_plant):
    """The tip moving 1 cm/s along the normal at a constant force (a wall receding in
    front of it; k_hat |x'| / K_o = 5e4 * 0.01 / 100 = 5 N, the allowance of the tip's
    speed): a reading that agrees with the observer's 5 N is plausible, and a noisy one
    2 N below it (a dropout that keeps the noise) is implausible at the third sample after
    the onset, as on a static wall."""
    detector = _detector(arm_plant, force_tolerance=1.0)
    monitor = (detector, _at_the_pose(arm_plant, detector, [0.01, 0.0, 0.0]))
    detector.set_reading(monitor[1], 5.0)
    for reading in _noisy(20):
        assert not any(_sample(monitor, reading).values())
    flags = [_sample(monitor, r)["implausible"] for r in _noisy(5, seed=3, mean=3.0)]
    assert flags == [False, False, False, True, True]


@pytest.mark.parametrize("noise_std, change", [(NOISE, NOISE / 100.0), (0.0, 1e-9)])
def test_a_change_of_exactly_the_threshold_is_a_change(arm_plant, noise_std, change):
    """|r[k] - r[k-1]| < threshold is no change (sigma / 100, or 1e-9 N without noise); a
    reading that alternates by exactly the threshold (0 and the threshold: exact in
    floating point) is changing, never stuck, even with the tip moving in contact."""
    detector, context = _quiet_moving(arm_plant, [0.01, 0.0, 0.0], noise_std)
    detector.set_reading(context, 0.0)
    flags = [_sample((detector, context), change * (k % 2), observed=5.0) for k in range(1, 7)]
    assert not any(f["stuck"] for f in flags)


def test_a_change_below_sigma_over_100_counts_as_none(monitor):
    """The reading flickers by 1.99e-4 N against sigma / 100 = 2e-4 N: stuck, at the third
    such sample after the onset. A flicker of 2.01e-4 N is a changing reading (each 0.5 %
    from the threshold, far above rounding)."""
    for reading in _noisy(5):
        _sample(monitor, reading)
    flicker = [_sample(monitor, 4.9 + 1.99e-4 * (k % 2))["stuck"] for k in range(4)]
    assert flicker == [False, False, False, True]
    for reading in _noisy(5, seed=2):  # clears
        _sample(monitor, reading)
    assert not any(_sample(monitor, 4.9 + 2.01e-4 * (k % 2))["stuck"] for k in range(8))


def test_a_broken_or_saturated_sample_neither_counts_nor_breaks_the_evidence(monitor):
    """Stuck at 4.9 N for two samples of evidence, then a NaN and a saturated sample (no
    evidence either way: the counts stay), then a third unchanged sample: flagged."""
    for reading in _noisy(5):
        _sample(monitor, reading)
    flags = [_sample(monitor, r) for r in (4.9, 4.9, 4.9, math.nan, 0.99 * FULL_SCALE, 4.9)]
    assert [f["stuck"] for f in flags] == [False, False, False, False, False, True]
    assert flags[3]["nonfinite"] and flags[4]["saturated"]


def test_a_monitor_started_without_a_reading_trusts_its_first_finite_sample(arm_plant):
    """No set_reading: the first finite sample is the previous and the held reading. Before
    it, a NaN reading passes on a finite force (nothing has been trusted yet: 0 N)."""
    detector = _detector(arm_plant)
    monitor = (detector, _at_the_pose(arm_plant, detector))
    assert _sample(monitor, math.nan)["nonfinite"]
    assert _trusted(monitor) == 0.0
    assert not any(_sample(monitor, 5.0).values())
    assert _sample(monitor, math.nan)["nonfinite"]
    assert _trusted(monitor) == 5.0  # the first finite sample, held
    # From there on the rules run: stuck at 4.9 N after the onset and three samples.
    assert [_sample(monitor, 4.9)["stuck"] for _ in range(4)] == [False, False, False, True]


def test_set_reading_is_the_held_value_and_a_frozen_monitor_passes_the_reading_on(
    arm_plant, monitor
):
    detector, context = monitor
    detector.set_reading(context, 4.2)
    detector.measured_force_input.FixValue(context, [math.nan])
    assert _trusted(monitor) == 4.2
    frozen = _detector(arm_plant, frozen=True)
    frozen_context = frozen.CreateDefaultContext()
    assert frozen_context.num_discrete_state_groups() == 0
    frozen.set_reading(frozen_context, 4.2)  # nothing to set
    frozen.measured_force_input.FixValue(frozen_context, [3.0])
    assert frozen.trusted_force_output.Eval(frozen_context)[0] == 3.0
    assert not any(frozen.fault_flags_output.Eval(frozen_context))
    assert frozen.sensor_fault_output.Eval(frozen_context)[0] == 0.0


@pytest.mark.parametrize("kind", ["stuck", "implausible"])
def test_the_held_value_stays_the_pre_fault_reading_until_the_flag_clears(monitor, kind):
    """Stuck at 4.9 N, or implausible at 2 N against the observer's 5 N (as above), then
    good readings again: for the three samples before the flag clears, the trusted force is
    still the reading of the sample before the onset, exactly."""
    before = _noisy(5)
    for reading in before:
        _sample(monitor, reading)
    fault = [4.9] * 5 if kind == "stuck" else _noisy(5, seed=3, mean=2.0)
    assert [_sample(monitor, r)[kind] for r in fault][-1]
    for reading in _noisy(3, seed=5):
        assert _sample(monitor, reading)[kind]
        assert _trusted(monitor) == before[-1]
    assert not _sample(monitor, 5.0)[kind]
    assert _trusted(monitor) == 5.0


def test_evidence_is_strictly_beyond_the_tolerance(arm_plant):
    """The rules flag what lies beyond F_tol, not at it. A reading 1 N below the observer's
    with no change (allowance 0): exactly F_tol = 1 N off, plausible. The tip moving in
    contact at the speed whose predicted change k_hat |x'| T is F_tol itself (the tolerance
    set to that product, the same floats the monitor multiplies): not stuck."""
    monitor = _quiet_moving(arm_plant, [0.0, 0.0, 0.0])
    monitor[0].set_reading(monitor[1], 5.0)
    assert not any(_sample(monitor, 5.0, observed=6.0)["implausible"] for _ in range(4))
    detector, context = _quiet_moving(arm_plant, [0.01, 0.0, 0.0])
    state = detector.estimated_state_input.Eval(context)
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(state)
    speed = abs((kinematics.jacobian() @ state[3:])[0])
    edge = _detector(arm_plant, noise_std=0.0, force_tolerance=5e4 * speed * PERIOD)
    edge_context = edge.CreateDefaultContext()
    for port in ("estimated_state", "stiffness_estimate"):
        edge.GetInputPort(port).FixValue(edge_context, detector.GetInputPort(port).Eval(context))
    edge.set_reading(edge_context, 5.0)
    assert not any(_sample((edge, edge_context), 5.0)["stuck"] for _ in range(4))
