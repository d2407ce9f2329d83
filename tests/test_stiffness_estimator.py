"""The stiffness estimator (systems/stiffness_estimator.py) on a known wall, by hand."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.planar_kinematics import PLANAR_COORDINATES
from admittance.systems.stiffness_estimator import (
    GAIN_DOWN,
    LOADING_TIME,
    StiffnessEstimator,
    StiffnessEstimatorParams,
    update_estimate,
)

PRIOR = 1e6
CONTACT = 0.5
INFORMATIVE = 1.0
WALL = 0.2  # Xe, m
# The fingertip, X = (x, y, theta) in world, the wall's normal x.
TIP = ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0)
ESTIMATOR = StiffnessEstimatorParams(
    period=0.005, prior_stiffness=PRIOR, contact_force=CONTACT, informative_force=INFORMATIVE
)


def _run(samples, stiffness, log_estimate=None, wall=WALL, period=0.005):
    """Feeds (force) samples, one per period, on a static linear wall: x = Xe + F / Ke."""
    anchor = None
    log_estimate = math.log(PRIOR) if log_estimate is None else log_estimate
    for k, force in enumerate(samples):
        position = wall + max(force, 0.0) / stiffness
        log_estimate, anchor = update_estimate(
            log_estimate,
            anchor,
            position,
            force,
            k * period,
            contact_force=CONTACT,
            informative_force=INFORMATIVE,
        )
    return math.exp(log_estimate), anchor


def test_the_secant_of_a_known_wall_from_the_prior_by_hand():
    """Ke = 2e4 N/m, Xe unknown to the estimator. Forces 0.2 (free), 0.6 (anchor), 1.7,
    2.8, 3.9 N: three informative secants, each exactly 2e4. From the prior 1e6 each moves
    ln k by 3/4 of the way: ln(1e6 / 2e4) = 3.912 shrinks to 3.912 / 64 = 0.0611, so
    k_hat = 2e4 exp(0.0611) = 2.126e4."""
    assert GAIN_DOWN == 0.75
    estimate, _ = _run([0.2, 0.6, 1.7, 2.8, 3.9], 2e4)
    assert estimate == pytest.approx(2e4 * math.exp(math.log(50) / 64), rel=1e-9)
    assert estimate == pytest.approx(2.126e4, rel=1e-3)


def test_the_wall_position_does_not_matter():
    near, _ = _run([0.6, 1.7, 2.8, 3.9], 5e4, wall=0.145)
    far, _ = _run([0.6, 1.7, 2.8, 3.9], 5e4, wall=0.155)
    assert near == pytest.approx(far, rel=1e-6)


def test_small_changes_keep_the_anchor_and_leave_the_estimate():
    estimate, anchor = _run([0.6, 0.9, 1.2, 1.5], 2e4)
    assert estimate == pytest.approx(PRIOR, rel=1e-12)  # no change of 1 N from 0.6 N
    assert anchor[1] == 0.6


def test_a_stiffer_wall_is_adopted_at_most_doubling_per_sample():
    """From k_hat = 1e4 on a wall of 1e6: the secant says 1e6, each sample allows 2x."""
    estimate, _ = _run([0.6, 1.7, 2.8, 3.9], 1e6, log_estimate=math.log(1e4))
    assert estimate == pytest.approx(8e4, rel=1e-9)


def test_force_and_motion_of_opposite_signs_are_not_a_spring():
    """The force falls by 2 N while the tip moves 1 mm into the wall (a receding wall):
    no update, and the sample becomes the anchor."""
    log_estimate, anchor = update_estimate(
        math.log(5e4),
        (0.2, 5.0, 0.0),
        0.201,
        3.0,
        0.1,
        contact_force=CONTACT,
        informative_force=1.0,
    )
    assert log_estimate == math.log(5e4)
    assert anchor == (0.201, 3.0, 0.0)


def test_after_the_loading_the_estimate_only_rises():
    """A receding wall that stops, 4 s into a contact: the tip travelled 20 mm at 5 N, the
    force then rises 2 N; the secant 2 / 0.02 = 100 N/m is the wall's travel, not its
    stiffness, and must not lower an estimate of 1e5. Inside the first 0.5 s it would."""
    assert LOADING_TIME == 0.5
    for time, expected in ((4.0, math.log(1e5)), (0.3, math.log(1e5) + 0.75 * math.log(1e-3))):
        log_estimate, _ = update_estimate(
            math.log(1e5),
            (0.15, 5.0, 0.0),
            0.17,
            7.0,
            time,
            contact_force=CONTACT,
            informative_force=1.0,
        )
        assert log_estimate == pytest.approx(expected)


def test_free_motion_and_untrusted_readings_drop_the_anchor():
    for force, trusted in ((0.3, True), (5.0, False), (math.nan, True)):
        log_estimate, anchor = update_estimate(
            math.log(5e4),
            (0.2, 2.0, 0.0),
            0.2001,
            force,
            0.1,
            contact_force=CONTACT,
            informative_force=1.0,
            trusted=trusted,
        )
        assert anchor is None and log_estimate == math.log(5e4)


def _estimator(arm_plant, **extra):
    estimator = StiffnessEstimator(
        arm_plant, contact=TIP, params=dataclasses.replace(ESTIMATOR, **extra)
    )
    context = estimator.CreateDefaultContext()
    estimator.sensor_fault_input.FixValue(context, [0.0])
    return estimator, context


def _sample(arm_plant, estimator, context, force, seed, fault=0.0):
    """One sample with the tip on the wall at 0.2 m, Ke = 5e4: x = 0.2 + F / 5e4."""
    seed = SolvePlanarInverseKinematics(
        arm_plant,
        "fingertip",
        [WALL + force / 5e4, -0.25, math.pi / 2],
        seed,
        coordinates=PLANAR_COORDINATES,
    )
    estimator.estimated_state_input.FixValue(context, np.concatenate([seed, np.zeros(3)]))
    estimator.measured_force_input.FixValue(context, [force])
    estimator.sensor_fault_input.FixValue(context, [fault])
    update = estimator.EvalUniquePeriodicDiscreteUpdate(context)
    context.get_mutable_discrete_state().SetFrom(update)
    return seed


def test_the_system_samples_the_tip_from_the_plant(arm_plant):
    """The block reads x from the plant's state: tip poses on a wall at 0.2 m, Ke = 5e4."""
    estimator, context = _estimator(arm_plant)
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(PRIOR)
    seed = [-0.45, 1.66, 0.36]
    for force in (0.6, 1.7, 2.8, 3.9, 5.0):
        seed = _sample(arm_plant, estimator, context, force, seed)
    # Four secants of 5e4 (to the IK's 1e-10 m): ln(20) / 256 from the wall.
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(
        5e4 * math.exp(math.log(20) / 256), rel=1e-4
    )


def test_the_frozen_estimator_has_no_state(arm_plant):
    frozen = StiffnessEstimator(
        arm_plant, contact=TIP, params=dataclasses.replace(ESTIMATOR, frozen_estimate=3e4)
    )
    context = frozen.CreateDefaultContext()
    assert context.num_total_states() == 0
    assert frozen.stiffness_estimate_output.Eval(context)[0] == 3e4


def _update(log_estimate, anchor, position, force, time):
    return update_estimate(
        log_estimate,
        anchor,
        position,
        force,
        time,
        contact_force=CONTACT,
        informative_force=INFORMATIVE,
    )


def test_contact_starts_at_f_c_and_a_change_of_exactly_df_min_is_informative():
    """F >= F_c is contact (the first such sample anchors); |F - F_a| >= dF_min is taken:
    from the anchor (0.2 m, 1 N), 2 N at 0.2 + 1 / 2e4 m gives the secant 2e4 N/m, which
    lowers the prior by 3/4 of the way in log scale."""
    _, anchor = _update(math.log(PRIOR), None, 0.2, CONTACT, 0.0)
    assert anchor == (0.2, CONTACT, 0.0)
    log_estimate, anchor = _update(math.log(PRIOR), (0.2, 1.0, 0.0), 0.2 + 1.0 / 2e4, 2.0, 0.1)
    expected = math.log(PRIOR) + GAIN_DOWN * (math.log(2e4) - math.log(PRIOR))
    assert log_estimate == pytest.approx(expected, rel=1e-9)  # the secant to 1e-12
    assert anchor == (0.2 + 1.0 / 2e4, 2.0, 0.0)


def test_unloading_gives_the_same_secant():
    """From (0.2010 m, 10 N) to (0.2005 m, 5 N): both fall, the secant is 5 / 5e-4 = 1e4."""
    log_estimate, _ = _update(math.log(5e4), (0.2010, 10.0, 0.0), 0.2005, 5.0, 0.1)
    expected = math.log(5e4) + GAIN_DOWN * (math.log(1e4) - math.log(5e4))
    assert log_estimate == pytest.approx(expected, rel=1e-9)  # 0.2010 - 0.2005 to 1e-13


@pytest.mark.parametrize("position", [0.2, 0.199])
def test_a_force_rise_without_the_tip_going_deeper_is_no_spring(position):
    """5 to 8 N with the tip still (a stiffness jump at fixed penetration) or backing off
    1 mm: no secant; the sample becomes the anchor."""
    log_estimate, anchor = _update(math.log(5e4), (0.2, 5.0, 0.0), position, 8.0, 0.1)
    assert log_estimate == math.log(5e4)
    assert anchor == (position, 8.0, 0.0)


@pytest.mark.parametrize("stiffness", [1.5, 1.5e6])
def test_the_rise_is_limited_to_a_doubling_at_any_scale(stiffness):
    """A secant three times k_hat raises ln k_hat by ln 2 exactly, whatever the scale (the
    update is on ln k: 1.5 N/m and 1.5e6 N/m alike)."""
    log_estimate, _ = _update(math.log(stiffness), (0.0, 1.0, 0.0), 1.0 / stiffness, 4.0, 0.1)
    assert log_estimate == pytest.approx(math.log(2 * stiffness), rel=1e-12)


@pytest.mark.parametrize("time, falls", [(2.1, True), (2.5, True), (2.6, False)])
def test_the_loading_time_counts_from_the_contact_s_onset(time, falls):
    """The receding wall of the test above, in a contact that began at t = 2 s: the
    estimate may fall until t = 2.5 s (inclusive), not after."""
    log_estimate, _ = _update(math.log(1e5), (0.15, 5.0, 2.0), 0.17, 7.0, time)
    fallen = math.log(1e5) + GAIN_DOWN * math.log(1e-3)
    assert log_estimate == pytest.approx(fallen if falls else math.log(1e5))


def test_a_contact_late_in_a_run_is_still_a_loading(arm_plant):
    """The samples of the system test above, from t = 2 s: the onset is the contact's own
    time, so the estimate falls as it did from t = 0."""
    estimator, context = _estimator(arm_plant)
    seed = [-0.45, 1.66, 0.36]
    for k, force in enumerate((0.6, 1.7, 2.8, 3.9, 5.0)):
        context.SetTime(2.0 + 0.005 * k)
        seed = _sample(arm_plant, estimator, context, force, seed)
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(
        5e4 * math.exp(math.log(20) / 256), rel=1e-4
    )


def test_a_set_estimate_or_a_flagged_reading_leaves_no_anchor(arm_plant):
    """After set_estimate the first sample in contact only anchors; a flagged reading
    neither updates nor keeps the anchor, so the next trusted sample anchors again."""
    estimator, context = _estimator(arm_plant)
    assert (estimator.prior_stiffness, estimator.contact_force) == (PRIOR, CONTACT)
    event = estimator.GetUniquePeriodicDiscreteUpdateAttribute()
    assert (event.period_sec(), event.offset_sec()) == (0.005, 0.0)
    estimator.set_estimate(context, 1e5)
    seed = _sample(arm_plant, estimator, context, 3.0, [-0.45, 1.66, 0.36])
    seed = _sample(arm_plant, estimator, context, 5.0, seed, fault=1.0)
    seed = _sample(arm_plant, estimator, context, 7.0, seed)
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(1e5, rel=1e-12)


@pytest.mark.parametrize("name", ["period", "prior_stiffness", "contact_force"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.inf])
def test_bad_arguments_name_the_argument(arm_plant, name, value):
    params = dataclasses.replace(ESTIMATOR, informative_force=1.0, **{name: value})
    with pytest.raises(ValueError, match=f"{name} must be > 0"):
        StiffnessEstimator(arm_plant, contact=TIP, params=params)


def test_a_new_contact_starts_from_the_contact_start_value_and_a_floor_holds():
    """update_estimate by hand: the sample that anchors a new contact lifts ln k_hat to
    contact_start (a fall from an earlier contact is not carried over), never lowers it;
    a fall inside the loading stops at the floor."""
    start = math.log(PRIOR)

    def onset(log_estimate):
        return update_estimate(
            log_estimate,
            None,
            0.2,
            2.0,
            1.0,
            contact_force=CONTACT,
            informative_force=1.0,
            contact_start=start,
        )

    assert onset(math.log(2e4)) == (start, (0.2, 2.0, 1.0))
    assert onset(math.log(4e6))[0] == math.log(4e6)
    # A secant of 1e4 from 3e6 would fall to 3e6 (1e4 / 3e6)^0.75 = 4.1e4: the floor
    # ln 3e6 keeps it there.
    floored, _ = update_estimate(
        math.log(3e6),
        (0.2, 2.0, 1.0),
        0.2 + 2.0 / 1e4,
        4.0,
        1.1,
        contact_force=CONTACT,
        informative_force=1.0,
        floor=math.log(3e6),
    )
    assert floored == math.log(3e6)


def test_the_system_restarts_each_contact_at_the_prior_and_latches_above(arm_plant):
    """A soft wall (5e4) loads from the prior; after free motion (0.1 N < F_c) the next
    contact anchors at the prior again, 1e6, not at the soft wall's estimate. With a latch
    at 2e6, an estimate set above it (3e6) keeps its value on the soft secants."""
    estimator, context = _estimator(arm_plant)
    seed = [-0.45, 1.66, 0.36]
    for force in (0.6, 1.7, 2.8, 3.9, 5.0):
        seed = _sample(arm_plant, estimator, context, force, seed)
    assert estimator.stiffness_estimate_output.Eval(context)[0] < 6e4
    seed = _sample(arm_plant, estimator, context, 0.1, seed)
    seed = _sample(arm_plant, estimator, context, 0.6, seed)
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(PRIOR)

    latched, context = _estimator(arm_plant, latch_stiffness=2e6)
    latched.set_estimate(context, 3e6)
    for force in (0.6, 1.7, 2.8, 3.9, 5.0):
        seed = _sample(arm_plant, latched, context, force, seed)
    assert latched.stiffness_estimate_output.Eval(context)[0] == pytest.approx(3e6)
