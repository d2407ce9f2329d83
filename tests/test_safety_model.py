"""The reduced contact model of the safety layer (systems/contact_model.py) against hand
derivations, a direct integration of its ODE, and Drake's Linearize of the full loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from admittance.diagrams.robots.planar_arm.stability import critical_gamma as full_critical_gamma
from admittance.diagrams.scenario.files import load_scenario
from admittance.systems import contact_model as model
from admittance.systems.planar_kinematics import PLANAR_COORDINATES


def _integrate_impact(speed, mass, kp, kd, stiffness, duration, steps=200_000):
    """m x'' + Kd x' + Kp (x - L0) + Ke max(x, 0) = 0 by RK4, x(0) = 0, x'(0) = v.

    The PID's spring is loaded by the lead Kd v / Kp of the approach (the pre-load Kd v);
    the wall is unilateral, as in eq. 4. Returns (peak penetration, first minimum after the
    peak) in metres: an independent check of the closed forms.
    """
    lead = kd * speed / kp

    def acceleration(x, v):
        return (-kd * v - kp * (x - lead) - stiffness * max(x, 0.0)) / mass

    h = duration / steps
    x, v = 0.0, speed
    peak, minimum, falling = 0.0, math.inf, False
    for _ in range(steps):
        k1x, k1v = v, acceleration(x, v)
        k2x, k2v = v + 0.5 * h * k1v, acceleration(x + 0.5 * h * k1x, v + 0.5 * h * k1v)
        k3x, k3v = v + 0.5 * h * k2v, acceleration(x + 0.5 * h * k2x, v + 0.5 * h * k2v)
        k4x, k4v = v + h * k3v, acceleration(x + h * k3x, v + h * k3v)
        x += h * (k1x + 2 * k2x + 2 * k3x + k4x) / 6
        v += h * (k1v + 2 * k2v + 2 * k3v + k4v) / 6
        if not falling:
            peak = max(peak, x)
            falling = v < 0
        elif v < 0:
            minimum = min(minimum, x)
        else:
            break
    return peak, minimum


def test_apparent_mass_of_a_hand_two_by_two():
    # M = [[2, 0.5], [0.5, 1]], j = (1, 0): 1 / (M^-1)_00 = det M / M_11 = 1.75 kg.
    assert model.apparent_mass([[2.0, 0.5], [0.5, 1.0]], [1.0, 0.0]) == pytest.approx(1.75)
    # j = (1, 1): M^-1 = [[1, -0.5], [-0.5, 2]] / 1.75, j M^-1 j^T = 2 / 1.75.
    assert model.apparent_mass([[2.0, 0.5], [0.5, 1.0]], [1.0, 1.0]) == pytest.approx(0.875)


def test_a_payload_is_a_point_mass_at_the_fingertip_by_hand():
    """M = [[2, 0.5], [0.5, 1]], J_t = I, m_p = 1 kg: M + m_p J_t^T J_t = [[3, 0.5], [0.5, 2]],
    det 5.75, so 1 / (M'^-1)_xx = 5.75 / 2 = 2.875 kg, above 1.75 + 1 = 2.75 kg (the
    apparent mass grows by at least m_p); with M diagonal, exactly 2 + 1 = 3 kg."""
    mass = [[2.0, 0.5], [0.5, 1.0]]
    loaded = model.apparent_mass(
        mass, [1.0, 0.0], payload_mass=1.0, translational_jacobian=np.eye(2)
    )
    assert loaded == pytest.approx(2.875, rel=1e-12)
    diagonal = model.apparent_mass(
        [[2.0, 0.0], [0.0, 1.0]], [1.0, 0.0], payload_mass=1.0, translational_jacobian=np.eye(2)
    )
    assert diagonal == pytest.approx(3.0, rel=1e-12)


def test_undamped_impact_peaks_at_v_times_sqrt_of_m_ke():
    # Kp -> 0, Kd = 0: F_peak = Ke v / w = v sqrt(m Ke) = 0.01 sqrt(1 * 1e4) = 1 N.
    assert model.impact_peak_force(0.01, 1.0, 1e-9, 0.0, 1e4) == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("stiffness", [1e4, 1e5, 1e6])
def test_impact_peak_matches_the_integrated_ode(stiffness):
    """The moving-wall arm (m 0.84 kg, Kp 1200, Kd 170) at 1 cm/s: the closed form and a
    fine RK4 agree to 0.1 % (the RK4's step error is below 1e-6 of the peak)."""
    mass, kp, kd, speed = 0.84, 1200.0, 170.0, 0.01
    peak, _ = _integrate_impact(speed, mass, kp, kd, stiffness, duration=0.05)
    assert model.impact_peak_force(speed, mass, kp, kd, stiffness) == pytest.approx(
        stiffness * peak, rel=1e-3
    )


def test_first_contact_bounces_below_the_bounce_free_damping_ratio():
    """zeta* solves 2 zeta = exp(-zeta (2 pi - acos zeta) / sqrt(1 - zeta^2)) (0.1918); on
    a wall much stiffer than Kp the integrated tip leaves the wall 3 % below it and stays
    in contact 3 % above it."""
    assert model.BOUNCE_FREE_DAMPING_RATIO == pytest.approx(0.1918, abs=1e-4)
    mass, kp, stiffness, speed = 1.0, 1e-6, 1e6, 0.01
    for ratio, bounces in ((0.97, True), (1.03, False)):
        kd = ratio * model.BOUNCE_FREE_DAMPING_RATIO * 2.0 * math.sqrt(mass * stiffness)
        _, minimum = _integrate_impact(speed, mass, kp, kd, stiffness, duration=0.02)
        assert (minimum < 0) == bounces
        assert (model.bounce_minimum(speed, mass, kp, kd, stiffness) < 0) == bounces


def test_safe_approach_speed_of_the_moving_wall_arm_by_hand():
    """m = 0.84 kg, Kp = 1200 N/m, Ke_max = 1e6 N/m, zeta = 0.25, Fmax = 10 N:
    Kd + c = 2 (0.25) sqrt(0.84 (1001200)) = 458.6 N s/m; w = sqrt(1001200 / 0.84) =
    1091.7 rad/s, Ke / w = 916.0 N s/m; exp(-0.25 (pi - acos 0.25) / sqrt(1 - 0.0625)) =
    exp(-0.4708) = 0.6245; F / v = 916.0 (0.5 + 0.6245) = 1030.1 N s/m; v = 9.708 mm/s."""
    mass, kp, kd, max_stiffness = 0.84, 1200.0, 170.0, 1e6
    damping = model.injected_damping(mass, kp, kd, max_stiffness, 0.25)
    assert kd + damping == pytest.approx(458.6, abs=0.1)
    speed = model.safe_approach_speed(10.0, mass, kp, kd + damping, max_stiffness)
    assert speed == pytest.approx(9.708e-3, rel=1e-3)
    # Softer walls peak lower at that speed: the bound holds below Ke_max.
    for stiffness in (1e3, 1e4, 1e5):
        assert model.impact_peak_force(speed, mass, kp, kd + damping, stiffness) < 10.0


def test_critical_loop_gain_of_hand_polynomials():
    # m = Kd = Ke = 1, Kp = 1, alpha = tau = 0: s^3 + s^2 + 2 s + g, Routh: g < 2.
    assert model.critical_loop_gain(1.0, 1.0, 1.0, 1.0, 0.0, 0.0) == pytest.approx(2.0)
    # m = Kd = Ke = tau = 1, Kp = 0, alpha = 0: s^4 + 2 s^3 + 2 s^2 + s + g;
    # D2 = 2 * 2 - 1 * 1 = 3, D3 = 3 * 1 - 2^2 g > 0: g < 0.75.
    assert model.critical_loop_gain(1.0, 0.0, 1.0, 1.0, 0.0, 1.0) == pytest.approx(0.75)
    # Ideal sensor and m < Kd alpha: no limit (the README's "no critical Gamma").
    assert math.isinf(model.critical_loop_gain(0.9, 2500.0, 50.0, 1e5, 0.1, 0.0))


def test_reduced_critical_gamma_is_below_the_full_linearization():
    """At Ke = 1e5 N/m with the FlexiForce chain, Drake's Linearize of the whole loop puts
    the critical Gamma at 2.35e-5 (README); the reduced model must be below it (cautious)
    and within 20 % (measured: 11 % below, and 10-20 % from 1e3 to 1e7 N/m)."""
    scenario = load_scenario(
        "paper_stiffness_step", {"sensor.kind": "flexiforce", "wall.stiffness": 1e5}
    )
    full = full_critical_gamma(scenario)
    reduced = model.critical_gamma(
        1e5,
        mass=0.9218,  # the apparent mass at the equilibrium pose (x 0.2001, y -0.25)
        kp=2500.0,
        kd=50.0,
        alpha=0.1,
        filter_time_constant=1.0 / (2.0 * math.pi * 5000.0),
        admittance_stiffness=2500.0,
    )
    assert 0.8 * full < reduced < full
    assert full == pytest.approx(2.35e-5, rel=0.01)


def test_apparent_mass_of_the_arm_at_the_paper_s_pose(arm_plant):
    """The fingertip of the built-in arm at (0.2, -0.25, pi/2): 0.92 kg along x (the
    value the stability check above uses), from M(q) and J(q) of the plant."""
    from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
    from admittance.systems.planar_kinematics import PlanarFrameKinematics

    q = SolvePlanarInverseKinematics(
        arm_plant,
        "fingertip",
        [0.2, -0.25, math.pi / 2],
        [-0.45, 1.66, 0.36],
        coordinates=PLANAR_COORDINATES,
    )
    context = arm_plant.CreateDefaultContext()
    arm_plant.SetPositions(context, q)
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    mass = model.apparent_mass(arm_plant.CalcMassMatrix(context), kinematics.jacobian()[0])
    assert mass == pytest.approx(0.9217, abs=5e-4)


@pytest.mark.parametrize("ratio", [0.25, 0.3, 0.6])
def test_bounce_minimum_matches_the_integrated_ode(ratio):
    """x_min of the closed form against the RK4 of the impact (m 1 kg, Kp 2500, Ke 1e5,
    1 cm/s) above zeta* (below it the tip leaves the unilateral wall, which the closed form's
    linear spring does not: the sign test above covers that side). Measured agreement 1.4e-9
    of the peak; 1e-6 of it leaves room for the RK4's step error."""
    mass, kp, stiffness, speed = 1.0, 2500.0, 1e5, 0.01
    kd = ratio * 2.0 * math.sqrt(mass * (kp + stiffness))
    peak, minimum = _integrate_impact(speed, mass, kp, kd, stiffness, duration=0.1)
    assert model.bounce_minimum(speed, mass, kp, kd, stiffness) == pytest.approx(
        minimum, abs=1e-6 * peak
    )


@pytest.mark.parametrize("mass, kd", [(1.0, 40.0), (1.0, 80.0), (0.3, 80.0)])
def test_without_oscillation_the_tip_stays_at_the_pre_load_s_depth(mass, kd):
    """zeta >= 1 (Kp + Ke = 100 + 300 N/m, zeta = Kd / (2 sqrt(400 m)): exactly 1, 2 and
    3.65 here): the tip creeps to L = Kd v / (Kp + Ke) without overshoot, whatever m, so the
    peak force is Ke L and the first minimum is L itself (no bounce)."""
    kp, stiffness, speed = 100.0, 300.0, 0.01
    depth = kd * speed / (kp + stiffness)
    assert model.impact_peak_force(speed, mass, kp, kd, stiffness) == pytest.approx(
        stiffness * depth, rel=1e-12
    )
    assert model.bounce_minimum(speed, mass, kp, kd, stiffness) == pytest.approx(depth, rel=1e-12)


def test_a_damped_enough_pid_needs_no_injected_damping():
    """Kd = 1000 N s/m already exceeds 2 (0.25) sqrt(0.84 (1200 + 1e6)) = 458.6: c = 0."""
    assert model.injected_damping(0.84, 1200.0, 1000.0, 1e6, 0.25) == 0.0


@pytest.mark.parametrize(
    "ratio, overshoot", [(0.5, math.exp(-0.5 * math.pi / math.sqrt(0.75))), (1.0, 0.0), (1.5, 0.0)]
)
def test_step_overshoot_by_hand(ratio, overshoot):
    assert model.step_overshoot(ratio) == pytest.approx(overshoot, rel=1e-12)


def test_critical_loop_gain_with_a_filter_and_alpha_against_the_roots():
    """m = 1, Kp = 1, Kd = 2, Ke = 2, tau = 0.1, alpha = 0.2: the largest g for which every
    root of m tau s^4 + (m + Kd tau) s^3 + (Kd + Kt tau) s^2 + (Kt + alpha g) s + g has a
    negative real part, bisected on numpy's roots: 7.1202, the closed form agrees to 1.1e-15
    (measured); 1e-9 leaves room for the roots' accuracy near the imaginary axis."""
    coefficients = [0.1, 1.2, 2.3, 3.0, 0.0]

    def stable(gain):
        polynomial = np.array(coefficients) + [0.0, 0.0, 0.0, 0.2 * gain, gain]
        return np.roots(polynomial).real.max() < 0

    low, high = 1e-3, 1e3
    for _ in range(100):
        middle = math.sqrt(low * high)
        low, high = (middle, high) if stable(middle) else (low, middle)
    assert model.critical_loop_gain(1.0, 1.0, 2.0, 2.0, 0.2, 0.1) == pytest.approx(low, rel=1e-9)


@pytest.mark.parametrize("alpha", [0.5, 0.75])
def test_an_ideal_sensor_with_kd_alpha_at_or_above_m_has_no_limit(alpha):
    """tau = 0: m s^3 + Kd s^2 + (Kt + alpha g) s + g, Routh: Kd (Kt + alpha g) > m g, i.e.
    Kd Kt + g (Kd alpha - m) > 0 for every g once Kd alpha >= m (m = 1, Kd = 2: alpha =
    0.5 exactly at the edge, 0.75 above it)."""
    assert math.isinf(model.critical_loop_gain(1.0, 1.0, 2.0, 2.0, alpha, 0.0))


@pytest.mark.parametrize("reflected_inertia", [False, True])
def test_the_payload_allowance_is_the_mass_of_a_payload_welded_at_the_fingertip(
    reflected_inertia,
):
    """The layer's allowance (M + m_p J_t^T J_t) against Drake's own M(q) of the arm with a
    0.5 kg point mass welded at the fingertip (arm.payload_mass), at (0.2, -0.25, pi/2):
    the same apparent mass (1e-9), with and without the motors' reflected inertia, which
    raises the bare arm's 0.92 kg (test above) to 2.18 kg."""
    from pydrake.systems.framework import DiagramBuilder

    from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
    from admittance.diagrams.robots.planar_arm.plant import AddPlanarArm
    from admittance.diagrams.robots.planar_arm.scenario import URDF_DIR
    from admittance.systems.planar_kinematics import PlanarFrameKinematics

    def apparent(payload_in_plant: float, allowance: float) -> float:
        plant, _ = AddPlanarArm(
            DiagramBuilder(),
            URDF_DIR / "planar_arm.urdf",
            reflected_inertia=reflected_inertia,
            payload_mass=payload_in_plant,
        )
        q = SolvePlanarInverseKinematics(
            plant,
            "fingertip",
            [0.2, -0.25, math.pi / 2],
            [-0.45, 1.66, 0.36],
            coordinates=PLANAR_COORDINATES,
        )
        kinematics = PlanarFrameKinematics(plant, "fingertip", coordinates=PLANAR_COORDINATES)
        kinematics.set_state(np.concatenate([q, np.zeros(3)]))
        jacobian = kinematics.jacobian()
        return model.apparent_mass(
            plant.CalcMassMatrix(kinematics.context),
            jacobian[0],
            payload_mass=allowance,
            translational_jacobian=jacobian[:2],
        )

    bare = apparent(0.0, 0.0)
    assert bare == pytest.approx(2.18 if reflected_inertia else 0.9217, abs=5e-3)
    assert apparent(0.0, 0.5) == pytest.approx(apparent(0.5, 0.0), rel=1e-9)
    assert apparent(0.0, 0.5) >= bare + 0.5
