"""The stiffness estimator (systems/stiffness_estimator.py) on a known wall, by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.closed_loop import SolvePlanarInverseKinematics
from admittance.systems.stiffness_estimator import (
    GAIN_DOWN,
    LOADING_TIME,
    StiffnessEstimator,
    update_estimate,
)

PRIOR = 1e6
CONTACT = 0.5
INFORMATIVE = 1.0
WALL = 0.2  # Xe, m


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


def test_the_system_samples_the_tip_from_the_plant(arm_plant):
    """The block reads x from the plant's state: tip poses on a wall at 0.2 m, Ke = 5e4."""
    estimator = StiffnessEstimator(
        arm_plant,
        period=0.005,
        prior_stiffness=PRIOR,
        contact_force=CONTACT,
        informative_force=INFORMATIVE,
    )
    context = estimator.CreateDefaultContext()
    estimator.sensor_fault_input.FixValue(context, [0.0])
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(PRIOR)
    seed = [-0.45, 1.66, 0.36]
    for force in (0.6, 1.7, 2.8, 3.9, 5.0):
        seed = SolvePlanarInverseKinematics(
            arm_plant, "fingertip", [WALL + force / 5e4, -0.25, math.pi / 2], seed
        )
        estimator.estimated_state_input.FixValue(context, np.concatenate([seed, np.zeros(3)]))
        estimator.measured_force_input.FixValue(context, [force])
        update = estimator.EvalUniquePeriodicDiscreteUpdate(context)
        context.get_mutable_discrete_state().SetFrom(update)
    # Four secants of 5e4 (to the IK's 1e-10 m): ln(20) / 256 from the wall.
    assert estimator.stiffness_estimate_output.Eval(context)[0] == pytest.approx(
        5e4 * math.exp(math.log(20) / 256), rel=1e-4
    )


def test_the_frozen_estimator_has_no_state(arm_plant):
    frozen = StiffnessEstimator(
        arm_plant,
        period=0.005,
        prior_stiffness=PRIOR,
        contact_force=CONTACT,
        informative_force=INFORMATIVE,
        frozen_estimate=3e4,
    )
    context = frozen.CreateDefaultContext()
    assert context.num_total_states() == 0
    assert frozen.stiffness_estimate_output.Eval(context)[0] == 3e4
