"""Closed-loop runs of the paper's scenarios: force tracking, signs, bounds.

Tolerances are the acceptance criteria of the project (docs/evidence/results.md, "What the runs
show"): a
mean force error under 1 % of Fr at steady state, a return to within 5 % of Fr in under 1 s
after the stiffness doubles, no force above what the doubled stiffness gives at its instant,
no contact loss and the force lag predicted for the moving wall, and a PID-alone baseline
above 10 Fr; each is written with its measured value and margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.scenario.files import load_scenario


def _event(result, kind):
    (event,) = [e for e in result.metrics["events"] if e["kind"] == kind]
    return event


@pytest.fixture(scope="module")
def stiffness_step():
    return run_scenario(load_scenario("paper_stiffness_step", ["sensor.kind=ideal"]))


@pytest.fixture(scope="module")
def stiffness_step_other_values():
    overrides = [
        "sensor.kind=ideal",
        "force_reference=8",
        "wall.stiffness=2e4",
        "wall.position=0.19",
        "wall.stiffness_steps=[{time: 15, stiffness: 4.0e4}]",
    ]
    return run_scenario(load_scenario("paper_stiffness_step", overrides))


@pytest.fixture(scope="module")
def moving_wall():
    return run_scenario(load_scenario("paper_moving_wall"))


@pytest.fixture(scope="module")
def moving_wall_pid_only():
    return run_scenario(load_scenario("paper_moving_wall", ["admittance.enabled=false"]))


@pytest.mark.parametrize("run", ["stiffness_step", "stiffness_step_other_values"])
def test_force_tracking_through_a_stiffness_step(run, request):
    result = request.getfixturevalue(run)
    reference = result.force_reference
    metrics = result.metrics
    step = _event(result, "stiffness_step")
    assert step["time"] == 15.0
    # Settled before the step and at the end: mean |F - Fr| < 0.05 N, the project's 1 % of
    # Fr (measured 0.0009 N and 0.0036 N on the paper's run: the ideal sensor, a tracking
    # sine in y; a wrong sign or gain of the law leaves newtons).
    assert step["mean_abs_force_error_before"] < 0.05
    assert metrics["steady_state_force_error"] < 0.05
    # Back within 5 % of Fr in under 1 s after Ke jumps (measured 0.12 s; the quasi-static
    # time constant alpha + 1 / (Gamma K K_eff) is 0.11 s on 1e5 N/m, docs/evidence/paper-notes.md
    # §4).
    assert step["settling_time"] is not None and step["settling_time"] < 1.0
    # No excessive force after first contact. A stiffness jump at a fixed penetration
    # multiplies the force by the stiffness ratio (2 in both runs) at that instant, for any
    # controller; before it the force is within 0.05 N of Fr (above), after it the law only
    # lowers it. So the peak is 2 (Fr + 0.05 N) at most: 2 Fr + 1 % (measured 9.998 N of
    # 10 N on the paper's run). A contact transient or an overshoot after the step would
    # exceed it.
    assert metrics["peak_force"] <= 2.0 * reference * 1.01
    assert metrics["contact_losses"] == 0


def test_steady_state_matches_the_wall_model(stiffness_step):
    """At the end, F = Ke (x - Xe) (eq. 4) and the reference sits inside the wall (Xr > 0)."""
    result = stiffness_step
    last = -1
    penetration = result.pose[last, 0] - result.wall_position[last]
    assert result.force[last] == pytest.approx(1e5 * penetration, rel=1e-9)
    assert penetration == pytest.approx(result.force_reference / 1e5, rel=0.02)
    # The commanded position xc = xd + Xr lies at or beyond the tip: the arm presses.
    assert result.reference_offset[last, 0] > 0
    commanded = result.desired_position[last, 0] + result.reference_offset[last, 0]
    assert commanded >= result.pose[last, 0]


def test_the_tip_follows_eq_19_along_the_wall(stiffness_step):
    """The y motion along the wall keeps tracking (the paper's Fig. 5, above): the tip's y
    against eq. 19 written out here, yd = 0.025 sin(0.2 pi t) - 0.25 m."""
    result = stiffness_step
    after_transient = result.time > 1.0
    eq19 = 0.025 * np.sin(0.2 * np.pi * result.time) - 0.25
    y_error = eq19 - result.pose[:, 1]
    # Measured 7.1e-5 m after the first second (the PID's lag on a 0.1 Hz sine and the
    # force loop's coupling through the Jacobian); 2e-4 m leaves a factor of 3. A wrong
    # amplitude, phase or sign of eq. 19 errs by up to 5e-2 m.
    assert np.max(np.abs(y_error[after_transient])) < 2e-4  # m


def test_moving_wall_keeps_contact_and_the_predicted_force_lag(moving_wall):
    """A wall receding at v leaves the force lagging by v / (Gamma K) (docs/evidence/paper-notes.md
    §4: Xr must move at v, so dz/dt = v / (Gamma K) = E): 0.005 / (1e-5 * 1200) = 0.42 N."""
    result = moving_wall
    metrics = result.metrics
    reference = result.force_reference
    assert metrics["first_contact_time"] is not None and metrics["first_contact_time"] < 0.1
    assert metrics["contact_losses"] == 0
    lag = 0.005 / (1e-5 * 1200.0)
    # Once the lag has built up (the motion runs from 2.5 s to 6.5 s), the mean force is
    # Fr - lag: measured 4.595 N over 3.5-6.5 s against the predicted 4.583 N (the arm's
    # own dynamics add the 0.012 N). 0.05 N holds that with a factor of 4; a Gamma K off by
    # a third either way moves the mean by 0.14-0.2 N (measured).
    moving = (result.time > 3.5) & (result.time < 6.5)
    assert np.mean(result.force[moving]) == pytest.approx(reference - lag, abs=0.05)
    # The extremes while it moves: 4.49 N (the onset of the motion) to 5.03 N (measured);
    # 0.25 N beyond Fr - lag and Fr bounds them with a factor of 2.5 and more.
    assert reference - lag - 0.25 <= metrics["force_min_while_wall_moves"]
    assert metrics["force_max_while_wall_moves"] <= reference + 0.25
    # The wall really moved 20 mm and the tip followed it.
    assert result.wall_position[-1] - result.wall_position[0] == pytest.approx(0.02)
    assert result.pose[-1, 0] - result.pose[0, 0] == pytest.approx(0.02, abs=1e-3)


def test_pid_alone_presses_with_excessive_force(moving_wall_pid_only, moving_wall):
    assert moving_wall_pid_only.metrics["peak_force"] > 10 * moving_wall_pid_only.force_reference
    assert moving_wall.metrics["peak_force"] < moving_wall_pid_only.metrics["peak_force"] / 2


def _flexiforce_stiffness_step(duration, step_time):
    overrides = [
        "sensor.kind=flexiforce",
        "simulator.accuracy=1e-3",
        f"duration={duration}",
        f"wall.stiffness_steps=[{{time: {step_time}, stiffness: 1.0e5}}]",
    ]
    return run_scenario(load_scenario("paper_stiffness_step", overrides))


def _assert_tracks_with_the_flexiforce(result):
    """Within 2 % of Fr on average once settled, despite the sensor's noise and lag."""
    metrics = result.metrics
    reference = result.force_reference
    assert metrics["mean_abs_force_error_settled"] < 0.02 * reference
    assert metrics["steady_state_force_error"] < 0.02 * reference
    assert metrics["contact_losses"] == 0
    # The sensor reads the true force plus its noise: the noise is really there.
    settled = result.time > result.time[-1] - 1.0
    residual = result.force_measured[settled] - result.force[settled]
    assert 0.5 * 0.02 < np.std(residual) < 2 * 0.02


def test_flexiforce_stiffness_step_short():
    _assert_tracks_with_the_flexiforce(_flexiforce_stiffness_step(duration=6.0, step_time=3.0))


@pytest.mark.slow
def test_flexiforce_stiffness_step_full():
    _assert_tracks_with_the_flexiforce(_flexiforce_stiffness_step(duration=30.0, step_time=15.0))
