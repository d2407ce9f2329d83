"""The safety layer's law (systems/safe_admittance.py) at fixed inputs, by hand: eq. 10 with
a scheduled gain in contact, the approach limit, the cap on the push, the fault hold and the
damping along the normal; and every system of the layer converts to AutoDiffXd."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff

from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.systems import contact_model as model
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import FaultDetectorParams, SensorFaultDetector
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.safety_numbers import SafeAdmittanceParams
from admittance.systems.stiffness_estimator import StiffnessEstimator, StiffnessEstimatorParams

GAMMA, ALPHA, KP, KD = 1e-5, 0.1, 2500.0, 50.0
FR, FMAX, MU = 5.0, 10.0, 4.0
FILTER = 1.0 / (2.0 * math.pi * 5000.0)
POSE = [0.2, -0.25, math.pi / 2]
# The fingertip's apparent mass along x at POSE (tests/test_safety_model.py).
MASS = 0.9217
# Kd + c = 2 zeta sqrt(m (Kp + Ke_max)) at zeta = 0.25, Ke_max = 1e6.
TOTAL_DAMPING = 0.5 * math.sqrt(MASS * (KP + 1e6))
# v_adv = (Fmax - Fr) / (Kp (alpha + t_d)(1 + os)), os = exp(-0.25 pi / sqrt(1 - 0.0625))
# = 0.4443 at zeta = 0.25, t_d = 20 ms: 5 / (2500 * 0.12 * 1.4443) = 11.539 mm/s.
ADVANCE = 5.0 / (2500.0 * 0.12 * (1.0 + math.exp(-0.25 * math.pi / math.sqrt(0.9375))))


# The fingertip, X = (x, y, theta) in world, the wall's normal x.
TIP = ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0)
LAW = SafeAdmittanceParams(
    gamma=GAMMA,
    alpha=ALPHA,
    stiffness=KP,
    pid_kp=KP,
    pid_kd=KD,
    max_force=FMAX,
    force_bound_gain=MU,
    max_push=0.01,
    max_stiffness=1e6,
    damping_ratio=0.25,
    stability_margin=3.0,
    filter_time_constant=FILTER,
    contact_force=0.5,
    detection_delay=0.02,
)


def _law(plant, **overrides):
    return SafeAdmittance(plant, contact=TIP, params=dataclasses.replace(LAW, **overrides))


@pytest.fixture
def law(arm_plant):
    system = _law(arm_plant)
    context = system.CreateDefaultContext()
    q = SolvePlanarInverseKinematics(
        arm_plant, "fingertip", POSE, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    system.estimated_state_input.FixValue(context, np.concatenate([q, np.zeros(3)]))
    system.desired_force_input.FixValue(context, [FR])
    system.desired_position_input.FixValue(context, POSE)
    system.desired_velocity_input.FixValue(context, [0.0, 0.0, 0.0])
    system.stiffness_estimate_input.FixValue(context, [5e4])
    system.sensor_fault_input.FixValue(context, [0.0])
    system.measured_force_input.FixValue(context, [FR])
    return system, context, q


def _evaluate(law, force, y=0.001, scale=1.0, **inputs):
    system, context, _ = law
    system.measured_force_input.FixValue(context, [force])
    for name, value in inputs.items():
        system.GetInputPort(name).FixValue(context, np.atleast_1d(value))
    context.SetContinuousState([y, scale])
    offset = system.reference_offset_output.Eval(context)[0]
    rates = system.EvalTimeDerivatives(context).CopyToVector()
    return offset, rates[0], rates[1]


def test_the_numbers_at_the_paper_s_pose(law):
    system, context, _ = law
    numbers = system.numbers(context)
    assert numbers["apparent_mass"] == pytest.approx(MASS, abs=5e-4)
    assert KD + numbers["injected_damping"] == pytest.approx(TOTAL_DAMPING, rel=1e-3)
    assert numbers["advance_speed"] == pytest.approx(ADVANCE, rel=1e-6)
    assert ADVANCE == pytest.approx(11.539e-3, rel=1e-4)


def test_in_contact_the_law_is_eq_10_with_the_scheduled_gain(law):
    """E = 0.2 N (inside the cap): Xr = y + Gamma K alpha E and dy/dt = Gamma K E, i.e.
    Xr = Gamma K [z + alpha E] of the paper, with Gamma K = 0.025 m/(N s)."""
    offset, y_rate, scale_rate = _evaluate(law, FR - 0.2)
    assert scale_rate == 0.0  # Gamma* at 5e4 N/m is far above 3 Gamma: s = 1
    assert offset == pytest.approx(0.001 + 0.025 * ALPHA * 0.2, rel=1e-12)
    assert y_rate == pytest.approx(0.025 * 0.2, rel=1e-12)


def test_a_changing_gain_keeps_the_gradient_flow_exact(law):
    """With s moving (ds/dt != 0) and E constant, d(Xr)/dt = dy/dt + Gamma K alpha E ds/dt
    must still be Gamma_s K E: the gradient flow of eq. 8-10 with the gain Gamma_s."""
    error = 0.2
    _, y_rate, scale_rate = _evaluate(law, FR - error, scale=0.5)
    assert scale_rate == pytest.approx((1.0 - 0.5) / 0.005)
    offset_rate = y_rate + GAMMA * KP * ALPHA * error * scale_rate
    assert offset_rate == pytest.approx(0.5 * GAMMA * KP * error, rel=1e-12)


def test_stiff_walls_scale_gamma_to_a_third_of_the_critical_one(law):
    system, context, _ = law
    system.stiffness_estimate_input.FixValue(context, [1e7])
    critical = model.critical_gamma(
        1e7,
        mass=MASS,
        kp=KP,
        kd=TOTAL_DAMPING,
        alpha=ALPHA,
        filter_time_constant=FILTER,
        admittance_stiffness=KP,
    )
    assert critical < 3 * GAMMA  # the schedule acts
    assert system.numbers(context)["schedule_target"] == pytest.approx(
        critical / (3 * GAMMA), rel=2e-3
    )


def test_free_motion_approaches_no_faster_than_the_impact_bound(law):
    """No contact (F < F_c): dy/dt = v_max - dXd/dt; v_max from Fmax, m, Kp, Kd + c and
    Ke_max (tests/test_safety_model.py checks the formula by hand)."""
    approach = model.safe_approach_speed(FMAX, MASS, KP, TOTAL_DAMPING, 1e6)
    assert approach == pytest.approx(9.27e-3, rel=2e-3)
    _, y_rate, _ = _evaluate(law, 0.0)
    assert y_rate == pytest.approx(approach, rel=2e-3)
    # A plan that moves toward the wall at 2 cm/s: the offset backs off, Xc keeps v_max.
    _, y_rate, _ = _evaluate(law, 0.0, desired_velocity=[0.02, 0.0, 0.0])
    assert 0.02 + y_rate == pytest.approx(approach, rel=2e-3)


def test_the_push_is_capped_in_contact_and_retreat_is_not(law):
    """F = 1 N: E = 4 N, beyond E_cap = v_adv / (Gamma K) = 0.46 N: dy/dt = v_adv and the
    proportional path pushes alpha v_adv. F = 9 N (above Fg = 7.5 N): E_b = -4 - 4 (1.5)
    = -10 N, uncapped: dy/dt = 0.025 (-10) = -0.25 m/s."""
    offset, y_rate, _ = _evaluate(law, 1.0)
    assert y_rate == pytest.approx(ADVANCE, rel=1e-6)
    assert offset == pytest.approx(0.001 + ALPHA * ADVANCE, rel=1e-9)
    offset, y_rate, _ = _evaluate(law, 9.0)
    assert y_rate == pytest.approx(-0.25, rel=1e-12)
    assert offset == pytest.approx(0.001 - 0.025 * ALPHA * 10.0, rel=1e-12)


def test_a_flagged_reading_holds_the_reference_but_lets_it_retreat(law):
    _, y_rate, _ = _evaluate(law, 1.0, sensor_fault=[1.0])
    assert y_rate == 0.0
    _, y_rate, _ = _evaluate(law, 6.0, sensor_fault=[1.0])
    assert y_rate == pytest.approx(0.025 * -1.0)


def test_the_reference_carries_a_damper_along_the_normal(arm_plant, law):
    """A tip moving at 1 cm/s along +x: Xr is lower by (c / Kp) 0.01 m, c = Kd_total - Kd:
    through the PID's spring, a force of -c x'."""
    system, context, q = law
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    v = np.linalg.solve(kinematics.jacobian(), [0.01, 0.0, 0.0])
    still, _, _ = _evaluate(law, FR - 0.2)
    moving, _, _ = _evaluate(law, FR - 0.2, estimated_state=np.concatenate([q, v]))
    c = system.numbers(context)["injected_damping"]
    assert c == pytest.approx(TOTAL_DAMPING - KD, rel=1e-3)
    assert moving - still == pytest.approx(-c / KP * 0.01, rel=1e-3)


def test_the_offset_is_pulled_below_its_push_bound_by_back_calculation_alone(law):
    """y = 0.02 m, E = 0.2 N in contact: y + P = 0.02 + 0.025 * 0.1 * 0.2 = 0.0205 m, past
    max_push = 0.01 m. No clamp of the output (a clamp would tie Xc to Xd): Xr = 0.0205 m,
    and dy/dt gains (0.01 - 0.0205) / 0.01 s = -1.05 m/s."""
    offset, y_rate, _ = _evaluate(law, FR - 0.2, y=0.02)
    assert offset == pytest.approx(0.0205, rel=1e-12)
    assert y_rate == pytest.approx(0.025 * 0.2 + (0.01 - 0.0205) / 0.01, rel=1e-12)


def test_a_run_starts_with_the_reference_at_the_tip(arm_plant, law):
    system, context, _ = law
    q = SolvePlanarInverseKinematics(
        arm_plant,
        "fingertip",
        [0.14, -0.25, POSE[2]],
        [-0.7, 1.7, 0.5],
        coordinates=PLANAR_COORDINATES,
    )
    system.estimated_state_input.FixValue(context, np.concatenate([q, np.zeros(3)]))
    system.measured_force_input.FixValue(context, [0.0])
    system.start_at_tip(context)
    # Xc = Xd + Xr = 0.2 + Xr = 0.14: the arm at rest is not pulled when the run starts.
    assert POSE[0] + system.reference_offset_output.Eval(context)[0] == pytest.approx(0.14)


def test_every_system_of_the_layer_converts_to_autodiff(arm_plant):
    """Linearize converts the whole loop: each block must convert and evaluate, and the
    law's rates carry derivatives with respect to its state and the tip's velocity."""
    observer = ContactForceObserver(arm_plant, contact=TIP)
    estimator = StiffnessEstimator(
        arm_plant,
        contact=TIP,
        params=StiffnessEstimatorParams(
            period=0.005, prior_stiffness=1e6, contact_force=0.5, informative_force=1.0
        ),
    )
    detector = SensorFaultDetector(
        arm_plant,
        contact=TIP,
        params=FaultDetectorParams(
            period=0.005,
            noise_std=0.02,
            saturation_force=111.0,
            contact_force=0.5,
            force_tolerance=1.1,
            observer_gain=100.0,
        ),
    )
    q = SolvePlanarInverseKinematics(
        arm_plant, "fingertip", POSE, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    state = InitializeAutoDiff(np.concatenate([q, [0.0, 0.0, 0.0]]))[:, 0]
    for system in (observer, estimator, detector, _law(arm_plant)):
        converted = system.ToAutoDiffXd()
        context = converted.CreateDefaultContext()
        for index in range(converted.num_input_ports()):
            port = converted.get_input_port(index)
            if port.get_name() == "estimated_state":
                port.FixValue(context, state)
            elif port.get_name() == "desired_position":
                port.FixValue(context, [AutoDiffXd(x) for x in POSE])
            else:
                port.FixValue(context, [AutoDiffXd(1.0)] * port.size())
        for index in range(converted.num_output_ports()):
            converted.get_output_port(index).Eval(context)
        if context.num_continuous_states():
            converted.EvalTimeDerivatives(context)
        if context.num_discrete_state_groups():
            # Twice: the first sample only records the reading (no previous one yet).
            update = converted.EvalUniquePeriodicDiscreteUpdate(context)
            context.get_mutable_discrete_state(0).SetFromVector(update.get_vector(0).CopyToVector())
            converted.EvalUniquePeriodicDiscreteUpdate(context)
    # The law: its offset depends on the joint velocities (the damper) with gradient
    # -(c / Kp) J_x.
    law = _law(arm_plant).ToAutoDiffXd()
    context = law.CreateDefaultContext()
    law.estimated_state_input.FixValue(context, state)
    law.desired_force_input.FixValue(context, [AutoDiffXd(FR)])
    law.desired_position_input.FixValue(context, [AutoDiffXd(x) for x in POSE])
    law.desired_velocity_input.FixValue(context, [AutoDiffXd(0.0)] * 3)
    law.stiffness_estimate_input.FixValue(context, [AutoDiffXd(5e4)])
    law.sensor_fault_input.FixValue(context, [AutoDiffXd(0.0)])
    law.measured_force_input.FixValue(context, [AutoDiffXd(FR)])
    gradient = law.reference_offset_output.Eval(context)[0].derivatives()
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    c = TOTAL_DAMPING - KD
    assert gradient[3:] == pytest.approx(-c / KP * kinematics.jacobian()[0], rel=1e-3)


def test_a_fresh_law_starts_at_no_offset_and_the_full_gain_and_outputs_its_scale(law):
    system, context, _ = law
    assert list(system.CreateDefaultContext().get_continuous_state_vector().CopyToVector()) == [
        0.0,
        1.0,
    ]
    _evaluate(law, FR - 0.2, scale=0.5)
    assert system.gain_scale_output.Eval(context)[0] == 0.5
    # Xr moves the normal axis only.
    assert list(system.reference_offset_output.Eval(context)[1:]) == [0.0, 0.0]


def test_a_reference_above_fmax_may_not_advance_at_all(law):
    """v_adv = max(Fmax - Fr, 0) / (...): with Fr = 12 N above Fmax = 10 N, zero."""
    system, context, _ = law
    system.desired_force_input.FixValue(context, [12.0])
    assert system.numbers(context)["advance_speed"] == 0.0


def test_contact_starts_at_f_c_and_free_motion_is_not_sped_up(law):
    """F = F_c = 0.5 N is contact (no approach limit). Below it, with Fr = 0.6 N, the law's
    own rate Gamma K E = 0.025 * 0.2 = 5 mm/s is below v_max = 9.27 mm/s: it is kept."""
    system, context, _ = law
    system.measured_force_input.FixValue(context, [0.5])
    assert system.numbers(context)["in_contact"]
    _, y_rate, _ = _evaluate(law, 0.4, desired_force=[0.6])
    assert y_rate == pytest.approx(0.025 * 0.2, rel=1e-12)


def test_the_force_bound_penalty_grows_with_the_excess_over_the_guard(law):
    """F = 16 N, guard Fg = (5 + 10) / 2 = 7.5 N: E_b = (5 - 16) - 4 (16 - 7.5) = -45 N, so
    dy/dt = 0.025 (-45) = -1.125 m/s and Xr = y + 0.025 * 0.1 * (-45) = 0.05 - 0.1125 m."""
    offset, y_rate, _ = _evaluate(law, 16.0, y=0.05)
    assert y_rate == pytest.approx(-1.125, rel=1e-12)
    assert offset == pytest.approx(0.05 - 0.1125, rel=1e-12)


def test_the_layer_has_no_retract_bound(law):
    """y = -0.2 m (twice the paper's default max_retract): Xr = y + 0.025 * 0.1 * 0.2 =
    -0.1995 m and dy/dt = 0.025 * 0.2 = 5 mm/s, the law's own: nothing pulls it back."""
    offset, y_rate, _ = _evaluate(law, FR - 0.2, y=-0.2)
    assert offset == pytest.approx(-0.1995, rel=1e-12)
    assert y_rate == pytest.approx(0.025 * 0.2, rel=1e-12)


# The plan moving into the wall at 20 mm/s; the PID's Kd / Kp = 50 / 2500 = 0.02 s.
PLAN_SPEED = 0.02
PLAN_SHIFT = 0.02 * PLAN_SPEED  # (Kd / Kp) dXd/dt = 0.4 mm


def test_the_approach_limit_acts_after_the_push_bound_s_back_calculation(law):
    """Free motion (F = 0), the plan at 20 mm/s toward the wall. E = Fr = 5 N is capped at
    E_cap = v_adv / (Gamma K): P = alpha v_adv = 1.1539 mm, Gamma K E_cap = v_adv.

    y = -0.15 m (past the paper's max_retract): dy/dt = v_max - 0.02 = -10.73 mm/s exactly,
    so that Xd + y approaches at v_max; before the fix the retract bound's back-calculation
    added (-0.1 - (y + P)) / 0.01 s = +4.88 m/s after the approach limit, and the clamped
    Xr = -0.1 m let Xc follow the plan at 20 mm/s. Xr = y + P - (Kd / Kp) dXd/dt.

    y = 0.02 m (past max_push): the back-calculation (0.01 - (y + P)) / 0.01 s = -1.1154 m/s
    is more negative than the approach limit, which keeps it: dy/dt = v_adv - 1.1154 m/s."""
    approach = model.safe_approach_speed(FMAX, MASS, KP, TOTAL_DAMPING, 1e6)
    assert approach == pytest.approx(9.27e-3, rel=2e-3)
    push = ALPHA * ADVANCE
    offset, y_rate, _ = _evaluate(law, 0.0, y=-0.15, desired_velocity=[PLAN_SPEED, 0.0, 0.0])
    assert y_rate == pytest.approx(approach - PLAN_SPEED, rel=2e-3)
    assert offset == pytest.approx(-0.15 + push - PLAN_SHIFT, rel=1e-9)
    offset, y_rate, _ = _evaluate(law, 0.0, y=0.02, desired_velocity=[PLAN_SPEED, 0.0, 0.0])
    assert y_rate == pytest.approx(ADVANCE + (0.01 - (0.02 + push)) / 0.01, rel=1e-9)
    assert offset == pytest.approx(0.02 + push - PLAN_SHIFT, rel=1e-9)


def test_in_contact_a_plan_advancing_into_the_wall_does_not_move_the_command(law):
    """F = 4.8 N (contact), the plan at 20 mm/s into the wall: dy/dt = 0.025 * 0.2 - 0.02 =
    -15 mm/s, so Xd + y advances at the law's 5 mm/s alone. A receding plan (-20 mm/s) is
    followed: dy/dt is the law's. A flagged reading with the plan advancing: dy/dt = -20
    mm/s (the command holds); with it receding, 0 (the command follows it out)."""
    _, y_rate, _ = _evaluate(law, FR - 0.2, desired_velocity=[PLAN_SPEED, 0.0, 0.0])
    assert y_rate == pytest.approx(0.025 * 0.2 - PLAN_SPEED, rel=1e-12)
    _, y_rate, _ = _evaluate(law, FR - 0.2, desired_velocity=[-PLAN_SPEED, 0.0, 0.0])
    assert y_rate == pytest.approx(0.025 * 0.2, rel=1e-12)
    _, y_rate, _ = _evaluate(
        law, FR - 0.2, desired_velocity=[PLAN_SPEED, 0.0, 0.0], sensor_fault=[1.0]
    )
    assert y_rate == pytest.approx(-PLAN_SPEED, rel=1e-12)
    _, y_rate, _ = _evaluate(
        law, FR - 0.2, desired_velocity=[-PLAN_SPEED, 0.0, 0.0], sensor_fault=[1.0]
    )
    assert y_rate == 0.0


def test_the_reference_cancels_the_pid_s_feedforward_of_the_plan_s_velocity(law):
    """The PID's D term is Kd (dXd/dt - x'): Xr carries -(Kd / Kp) dXd/dt, whose force
    through Kp is -Kd dXd/dt. At 20 mm/s: Xr lower by 0.02 * 0.02 = 0.4 mm."""
    still, _, _ = _evaluate(law, FR - 0.2)
    moving, _, _ = _evaluate(law, FR - 0.2, desired_velocity=[PLAN_SPEED, 0.0, 0.0])
    assert moving - still == pytest.approx(-PLAN_SHIFT, rel=1e-9)


def test_a_payload_adds_a_point_mass_at_the_fingertip(arm_plant, law):
    """m_p = 0.5 kg: M + m_p J_t^T J_t; the apparent mass along x grows by at least m_p
    (contact_model.apparent_mass), and the approach speed falls with it."""
    system, context, q = law
    loaded = _law(arm_plant, payload_mass=0.5)
    loaded_context = loaded.CreateDefaultContext()
    for index in range(system.num_input_ports()):
        port = system.get_input_port(index)
        if port.HasValue(context):  # the collision input is left open: no reflex
            loaded.get_input_port(index).FixValue(loaded_context, port.Eval(context))
    bare, heavy = system.numbers(context), loaded.numbers(loaded_context)
    assert heavy["payload_mass"] == 0.5
    assert heavy["apparent_mass"] >= bare["apparent_mass"] + 0.5
    assert heavy["apparent_mass"] < bare["apparent_mass"] + 0.5 * 1.01
    assert heavy["approach_speed"] < bare["approach_speed"]


def test_a_run_cannot_start_with_the_tip_beyond_the_push_bound(law):
    """The tip at x = 0.2 m and Xd 5 cm behind it (past max_push = 1 cm): the reference
    could not start at the tip. 15 cm ahead of it is a start (no retract bound)."""
    system, context, _ = law
    system.desired_position_input.FixValue(context, [POSE[0] - 0.05, POSE[1], POSE[2]])
    with pytest.raises(ValueError, match="beyond max_push"):
        system.start_at_tip(context)
    system.desired_position_input.FixValue(context, [POSE[0] + 0.15, POSE[1], POSE[2]])
    system.start_at_tip(context)
    assert POSE[0] + 0.15 + system.reference_offset_output.Eval(context)[0] == pytest.approx(
        POSE[0]
    )


def test_a_run_may_start_with_the_tip_exactly_at_the_push_bound(arm_plant, law):
    """A law whose max_push is exactly the tip's offset from Xd (tip - Xd, exact in floating
    point: Xd within a factor 2 of the tip's x) starts there."""
    _, context, q = law
    tip = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    tip.set_state(np.concatenate([q, np.zeros(3)]))
    x = tip.pose()[0]
    desired = x - 0.01
    bounds = dict(max_push=x - desired)
    system = _law(arm_plant, **bounds)
    context = system.CreateDefaultContext()
    system.estimated_state_input.FixValue(context, np.concatenate([q, np.zeros(3)]))
    system.desired_force_input.FixValue(context, [FR])
    system.desired_position_input.FixValue(context, [desired, POSE[1], POSE[2]])
    system.desired_velocity_input.FixValue(context, [0.0, 0.0, 0.0])
    system.stiffness_estimate_input.FixValue(context, [5e4])
    system.sensor_fault_input.FixValue(context, [0.0])
    system.measured_force_input.FixValue(context, [0.0])
    system.start_at_tip(context)
    assert desired + system.reference_offset_output.Eval(context)[0] == pytest.approx(x)


@pytest.mark.parametrize(
    "name, value, message",
    [
        ("gamma", 0.0, "gamma must be finite and > 0"),
        ("max_force", -2.0, "max_force must be finite and > 0"),
        ("stiffness", math.inf, "stiffness must be finite and > 0"),
        ("alpha", -0.5, "alpha must be finite and >= 0"),
        ("pid_kd", math.inf, "pid_kd must be finite and >= 0"),
        ("payload_mass", -0.5, "payload_mass must be finite and >= 0"),
    ],
)
def test_bad_arguments_name_the_argument(arm_plant, name, value, message):
    with pytest.raises(ValueError, match=message):
        _law(arm_plant, **{name: value})


def test_an_undamped_pid_an_ideal_sensor_and_no_alpha_are_accepted(arm_plant):
    _law(arm_plant, alpha=0.0, pid_kd=0.0, filter_time_constant=0.0)


def test_the_law_s_numbers_and_contact_are_structs_its_copies_keep(arm_plant):
    """SafeAdmittanceParams keeps every number as a float (held_axes a bool), a variant is
    dataclasses.replace of it, and the AutoDiffXd copy is built from the same structs."""
    variant = dataclasses.replace(LAW, payload_mass=1, held_axes=1)
    assert (variant.payload_mass, variant.held_axes) == (1.0, True)
    assert isinstance(variant.payload_mass, float) and LAW.payload_mass == 0.0
    system = _law(arm_plant, period=0.001)
    converted = system.ToAutoDiffXd()
    assert converted.params == system.params == dataclasses.replace(LAW, period=0.001)
    assert converted.reference_offset_output.size() == TIP.num_axes == 3


def test_the_contact_frame_checks_its_task_and_its_normal():
    assert ContactFrame("fingertip", ["x", "y"], 1).coordinates == ("x", "y")
    with pytest.raises(ValueError, match="normal_axis must index the coordinates"):
        ContactFrame("fingertip", PLANAR_COORDINATES, 3)
    with pytest.raises(ValueError, match="coordinates must be distinct names"):
        ContactFrame("fingertip", ("x", "q"), 0)
