"""The safety layer on a sampled controller with a delayed reading (docs/evidence/safety.md,
section 8): the `sensor.latency` key, the delay line, the discrete-time margins, and a
short closed-loop run."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource, ZeroOrderHold
from pydrake.trajectories import PiecewisePolynomial

from admittance.diagrams.app.cli import main
from admittance.diagrams.loop.point import AddLatency
from admittance.diagrams.robots.description import ForceLaw, ForcePoint, SensorChain
from admittance.systems import contact_model
from admittance.systems.planar_kinematics import PLANAR_COORDINATES
from admittance.systems.sampled_loop import (
    SampledContactLoop,
    sampled_loop_matrix,
    spectral_radius,
)

# --- the key --------------------------------------------------------------------------


@pytest.mark.parametrize("value", ["-0.001", "0.05"])
def test_latency_out_of_range_is_one_line_naming_the_key(tmp_path, capsys, value):
    status = main(
        [
            "simulate",
            "safe_contact",
            "--set",
            f"sensor.latency={value}",
            "--out",
            str(tmp_path / "r"),
        ]
    )
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert len(error.splitlines()) == 1
    assert "sensor.latency" in error and "[0, 0.02] s" in error
    assert not (tmp_path / "r").exists()


# --- the delay line -------------------------------------------------------------------


@pytest.mark.parametrize("latency", [0.00025, 0.0005, 0.001, 0.00125, 0.0025])
def test_a_sampled_controller_reads_the_force_of_latency_ago(latency):
    """A ramp u(t) = t through the line, read by a ZeroOrderHold at offset 0 (as the
    sampled law's update reads it): at t_k = k h it holds t_k - L, for L a fraction of h,
    one period, and more (hand derivation: the reading of t_k - L is t_k - L)."""
    period = 0.001
    point = ForcePoint(
        name="",
        frame="fingertip",
        coordinates=PLANAR_COORDINATES,
        force_axes=(0,),
        sensor=SensorChain(latency=latency, noise_period=0.005),
        law=ForceLaw(period=period),
    )
    builder = DiagramBuilder()
    ramp = builder.AddSystem(
        TrajectorySource(PiecewisePolynomial.FirstOrderHold([0.0, 1.0], [[0.0, 1.0]]))
    )
    delayed = AddLatency(builder, point, ramp.get_output_port())
    reader = builder.AddSystem(ZeroOrderHold(period, 1))
    builder.Connect(delayed, reader.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = reader.GetMyContextFromRoot(simulator.get_context())
    held = []
    for k in range(5, 12):
        simulator.AdvanceTo(k * period + 1e-9)
        held.append(k * period - reader.get_output_port().Eval(context)[0])
    np.testing.assert_allclose(held, latency, atol=1e-12)


# --- the discrete-time analysis -------------------------------------------------------


def _first_crossing(stable, low: float, high: float) -> float:
    """The gain in [low, high] where `stable` turns false (bisection, stable at low)."""
    assert stable(low) and not stable(high)
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if stable(middle) else (low, middle)
    return 0.5 * (low + high)


@pytest.mark.parametrize("latency_share", [0.0, 0.3, 0.7, 1.0])
def test_the_delay_line_against_a_first_order_loop_by_hand(latency_share):
    """x' = -a x + b u, u held over h, u_k = -g F_k with F_k = x(t_k - r), r in [0, h].

    By hand: x_k+1 = phi x_k + gam u_k (phi = e^(-a h), gam = b (1 - phi) / a) and
    F_k = phi' x_k-1 + gam' u_k-1 with phi' = e^(-a (h - r)), gam' = b (1 - phi') / a
    (r = 0: F_k = x_k, no delay state; r = h: phi' = 1, gam' = 0). Eliminating u gives
    z^2 + (g gam' - phi) z + g (gam phi' - phi gam') = 0, whose roots stay in the unit
    circle (Jury) while a0 = g (gam phi' - phi gam') < 1 and 1 - a1 + a0 > 0, i.e.
    g < min(1 / (gam phi' - phi gam'), (1 + phi) / (gam' + phi gam' - gam phi')) (the
    terms that are positive). With r = 0 the loop is first order, z - phi + g gam = 0:
    g* = (1 + phi) / gam."""
    a, b, h = 50.0, 2.0, 0.01
    r = latency_share * h
    phi = np.exp(-a * h)
    gam = b * (1.0 - phi) / a
    if r == 0.0:
        expected = (1.0 + phi) / gam
    else:
        phi_r = np.exp(-a * (h - r))
        gam_r = b * (1.0 - phi_r) / a
        bounds = []
        for numerator, denominator in (
            (1.0, gam * phi_r - phi * gam_r),
            (1.0 + phi, gam_r + phi * gam_r - gam * phi_r),
        ):
            if denominator > 0:
                bounds.append(numerator / denominator)
        expected = min(bounds)

    def stable(gain: float) -> bool:
        M = sampled_loop_matrix(
            [[-a]], [b], [1.0], period=h, latency=r, state_gain=[0.0], measurement_gain=-gain
        )
        return spectral_radius(M) < 1.0

    assert _first_crossing(stable, 1e-6, 10.0 * expected) == pytest.approx(expected, rel=1e-6)


# safe_contact's normal axis: Kp = K = 1200 N/m, Kd = 170 N s/m, alpha = 0.1 s, the 5 kHz
# filter; the rigid arm's apparent mass at the contact pose and Kd + c at zeta = 0.25,
# Ke_max = 1e6 N/m (c = 2 zeta sqrt(m (Kp + Ke_max)) - Kd).
MASS = 0.8207
FILTER = 1.0 / (2.0 * np.pi * 5000.0)
DAMPING = 0.5 * np.sqrt(MASS * (1200.0 + 1e6))


def _loop(period: float) -> SampledContactLoop:
    return SampledContactLoop(MASS, 1200.0, DAMPING, 0.1, FILTER, 1200.0, period)


@pytest.mark.parametrize("stiffness", [1e4, 1e6])
def test_a_fast_tick_without_latency_is_the_continuous_loop(stiffness):
    """As h -> 0 with L = 0 the sampled loop's critical Gamma tends to the Routh-Hurwitz
    one of the continuous loop (contact_model.critical_gamma, a closed form). The hold
    costs about h / 2 of delay: at h = 1 us, measured 1.6 % below at 1e4 and 1e6 N/m
    (tolerance 2 %)."""
    routh = contact_model.critical_gamma(
        stiffness,
        mass=MASS,
        kp=1200.0,
        kd=DAMPING,
        alpha=0.1,
        filter_time_constant=FILTER,
        admittance_stiffness=1200.0,
    )
    assert _loop(1e-6).critical_gamma(stiffness, 0.0) == pytest.approx(routh, rel=0.02)


def test_latency_lowers_the_critical_gamma_at_1_khz():
    """At h = 1 ms on a 1e6 N/m wall: no latency, 0.25 ms and 0.5 ms. Each step of latency
    lowers Gamma*, and all lie far below the continuous loop's 9.9e-5 (the
    Routh-Hurwitz bound) that the continuous layer scheduled from."""
    values = [_loop(1e-3).critical_gamma(1e6, latency) for latency in (0.0, 2.5e-4, 5e-4)]
    assert values[0] > values[1] > values[2]
    assert values[0] < 0.1 * 9.9e-5


def _sampled_law(plant, latency: float):
    from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
    from admittance.systems.contact_frame import ContactFrame
    from admittance.systems.safe_admittance import SafeAdmittance
    from admittance.systems.safety_numbers import SafeAdmittanceParams

    law = SafeAdmittance(
        plant,
        contact=ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0),
        params=SafeAdmittanceParams(
            gamma=1e-5,
            alpha=0.1,
            stiffness=1200.0,
            pid_kp=1200.0,
            pid_kd=170.0,
            max_force=10.0,
            force_bound_gain=4.0,
            max_push=0.01,
            max_stiffness=1e6,
            damping_ratio=0.25,
            stability_margin=3.0,
            filter_time_constant=FILTER,
            contact_force=0.5,
            detection_delay=0.02,
            period=1e-3,
            latency=latency,
        ),
    )
    pose = [0.15, -0.25, np.pi / 2]
    q = SolvePlanarInverseKinematics(
        plant, "fingertip", pose, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    return law, np.concatenate([q, np.zeros(3)])


def test_the_schedule_lowers_gamma_with_latency(arm_plant):
    """The layer at 1 kHz on the prior Ke_max = 1e6 N/m: its Gamma_s = s Gamma falls as
    the latency grows (0, 0.25, 0.5 ms), and 3 Gamma_s (the margin) sits on the sampled
    loop's stability boundary: the spectral radius of the reduced map there is 1 within
    the cache's rounding (0.3 %) and the bisection's (0.05 %)."""
    scheduled = []
    for latency in (0.0, 2.5e-4, 5e-4):
        law, state = _sampled_law(arm_plant, latency)
        numbers = law.numbers_at(state, 5.0, 1e6)
        gamma = numbers["schedule_target"] * 1e-5
        loop = SampledContactLoop(
            numbers["apparent_mass"],
            1200.0,
            170.0 + numbers["injected_damping"],
            0.1,
            FILTER,
            1200.0,
            1e-3,
        )
        assert numbers["schedule_target"] < 1.0
        assert spectral_radius(loop.matrix(0.99 * 3 * gamma, 1e6, latency)) < 1.0
        assert spectral_radius(loop.matrix(1.01 * 3 * gamma, 1e6, latency)) > 1.0
        scheduled.append(gamma)
    assert scheduled[0] > scheduled[1] > scheduled[2]


def test_the_report_s_margins_at_the_1_khz_settings():
    """`admittance stability safe_contact_1khz --set sensor.latency=0.0005` reads, on its
    1e5 N/m wall, a Gamma* below the one without latency and far below the continuous
    loop's; the scheduled Gamma keeps the margin of 3 (here the scenario's 1e-5, since
    Gamma* / 3 is above it); the loop is stable there and tolerates more than the 0.5 ms
    it has; on the stiffest walls the schedule lowers Gamma to Gamma* / 3."""
    from admittance.diagrams.robots.planar_arm.safety_margins import sampled_margins
    from admittance.diagrams.scenario.files import load_scenario

    margins = sampled_margins(load_scenario("safe_contact_1khz", ["sensor.latency=0.0005"]))
    assert margins["critical_gamma"] < margins["critical_gamma_without_latency"]
    assert margins["critical_gamma_without_latency"] < 0.1 * margins["critical_gamma_continuous"]
    assert margins["scheduled_gamma"] == min(1e-5, margins["critical_gamma"] / 3.0)
    assert margins["spectral_radius"] < 1.0
    assert margins["tolerable_latency"] > 0.0005
    for row in margins["table"]:
        assert row["scheduled_gamma"] <= row["critical_gamma"] / 3.0 * (1 + 1e-12)
        assert row["spectral_radius"] < 1.0


# --- the layer in the loop --------------------------------------------------------------

FR, FMAX = 5.0, 10.0


def _stiff_wall_run(latency: float, duration: float = 1.5):
    """safe_contact_1khz on a still 1e6 N/m wall (Ke_max), the tip 2 mm before it."""
    from admittance.diagrams.robots.planar_arm.run import run_scenario
    from admittance.diagrams.scenario.files import load_scenario

    return run_scenario(
        load_scenario(
            "safe_contact_1khz",
            [
                f"sensor.latency={latency}",
                "wall.stiffness=1e6",
                "wall.velocity=0",
                "arm.initial_position=[0.148,-0.25,1.5707963267948966]",
                f"duration={duration}",
            ],
        )
    )


def test_the_sampled_layer_holds_a_stiff_wall_with_half_a_tick_of_latency():
    """1 kHz, L = 0.5 ms, Ke = Ke_max = 1e6 N/m. The sampled loop's Gamma* there is
    5.0e-6 (docs/evidence/safety-sampled.md, section 8), below the scenario's Gamma = 1e-5, which
    the
    continuous schedule (Gamma* 1.5e-4) would keep: only the sampled schedule keeps the
    loop stable (spectral radius 0.998 at Gamma_s = 1.68e-6, 1.14 at 1e-5). The
    first contact peaks under Fmax (the approach bound), contact holds, and over the last
    0.3 s the force moves smoothly toward Fr: its deviation from a straight line stays
    under 0.05 N (the ADC noise is 0.02 N; a growing 115 Hz contact mode would not)."""
    result = _stiff_wall_run(0.0005)
    metrics = result.metrics
    assert metrics["contact_losses"] == 0
    assert metrics["peak_force"] <= FMAX
    last = result.time > result.time[-1] - 0.3
    time, force = result.time[last], result.force[last]
    trend = np.polyval(np.polyfit(time, force, 1), time)
    assert np.std(force - trend) < 0.05
    assert np.all(force > 0.5 * FR) and np.all(force < FMAX)


@pytest.mark.slow
@pytest.mark.parametrize("latency", [0.00025, 0.0005])
def test_safe_contact_at_1_khz_with_latency(latency):
    """The whole safe_contact at 1 kHz with the reading 0.25 ms and 0.5 ms late (8 s: the
    approach, the contact on the 1e5 N/m wall and its 5 mm/s retreat): the first contact
    under Fmax, no contact loss, the steady state within 2 % of Fr (docs/evidence/safety.md,
    section 8)."""
    from admittance.diagrams.robots.planar_arm.run import run_scenario
    from admittance.diagrams.scenario.files import load_scenario

    metrics = run_scenario(
        load_scenario("safe_contact_1khz", [f"sensor.latency={latency}"])
    ).metrics
    assert metrics["peak_force"] <= FMAX
    assert metrics["contact_losses"] == 0
    assert metrics["steady_state_force_error"] <= 0.02 * FR


# --- the sampled PID's damper ---------------------------------------------------------


def test_the_sampled_damper_gain_of_a_sliding_mass_by_hand():
    """A 2 kg block on a prismatic x joint: J M^-1 J^T = diag(1/m, 0, 0), so the gain is
    h Kd_x / m = 1e-3 * 300 / 2 = 0.15 exactly (y and theta do not move)."""
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import PrismaticJoint, SpatialInertia, UnitInertia

    from admittance.diagrams.robots.planar_arm.safety_layer import sampled_damper_gain

    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody(
        "block", SpatialInertia(2.0, np.zeros(3), UnitInertia.SolidSphere(0.05))
    )
    plant.AddJoint(PrismaticJoint("slide", plant.world_frame(), body.body_frame(), [1.0, 0.0, 0.0]))
    plant.Finalize()
    gain = sampled_damper_gain(plant, "block", [0.3, 0.0], [300.0, 50.0, 5.0], 1e-3)
    assert gain == pytest.approx(0.15, rel=1e-12)


def test_safe_contact_with_a_sampled_pid_too_damped_for_its_arm_is_refused(tmp_path, capsys):
    """safe_contact's Kd_theta = 5 on the rigid arm's light last link, held over 1 ms: h
    max eig(J M^-1 J^T Kd) is about 16 (the run bounces at 73 N with 86 contact losses
    when let through); the layer cannot bound that, so the run is refused in one line,
    naming the keys, and nothing is written. safe_contact_1khz (the motors' inertia,
    Kd_theta = 2) passes the same check: its runs are in section 8."""
    out = tmp_path / "r"
    status = main(
        [
            "simulate",
            "safe_contact",
            "--set",
            "admittance.period=0.001",
            "--set",
            "pid.period=0.001",
            "--set",
            "duration=0.05",
            "--out",
            str(out),
        ]
    )
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert len(error.splitlines()) == 1
    assert "pid.kd, pid.period" in error and "arm.reflected_inertia=true" in error
    assert not out.exists()
    assert main(["simulate", "safe_contact_1khz", "--set", "duration=0.05", "--out", str(out)]) == 0
