"""Stability analysis: eq. 13, the linearized loop, Lyapunov, maps, critical Gamma.

The paper's own setting for these checks is the stiffness-step scenario with the FlexiForce
chain in the loop (the ideal, lag-free sensor has no critical Gamma: see test below).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from admittance.diagrams.analysis.eq13 import symbolic_eq13
from admittance.diagrams.analysis.linear import lyapunov_certificate, modal_summary
from admittance.diagrams.app.cli import main
from admittance.diagrams.results.folder import MARKER, marker_entries
from admittance.diagrams.robots.planar_arm.linearization import (
    FindContactEquilibrium,
    LinearizeAtEquilibrium,
)
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.stability import (
    critical_gamma,
    linear_versus_nonlinear,
    lyapunov_along_trajectory,
    max_real_part,
    sampled_spectral_radius,
    simulate_near_critical,
    stability_map,
    with_values,
)
from admittance.diagrams.scenario.files import load_scenario
from admittance.systems.optimal_admittance import OptimalAdmittance


@pytest.fixture(scope="module")
def paper_with_sensor():
    return load_scenario("paper_stiffness_step", ["sensor.kind=flexiforce"])


def test_eq12_gradient_of_the_cost_is_minus_K_times_the_weighted_error():
    """Symbolically, from eq. 5 and 7: dI/dXr = -K (E + alpha dE/dt), the factor that turns
    the gradient flow into eq. 10' and, with it, eq. 13 (checked on the block below)."""
    assert symbolic_eq13()["dI_dXr_equals_minus_K_weighted_error"]


@pytest.mark.parametrize(
    "measured, force_rate",
    [(3.0, 4.0), (3.0, 40.0), (8.0, -4.0), (8.0, -40.0)],
    ids=["E>0,w>0", "E>0,w<0", "E<0,w<0", "E<0,w>0"],
)
def test_eq13_holds_on_the_implemented_admittance_law(measured, force_rate):
    """Eq. 13 on the block itself: dV/dt = (dI/dXr) dXr/dt with dI/dXr = -K w (eq. 12, the
    test above), w = E + alpha dE/dt, and dXr/dt the OptimalAdmittance system's own, taken by
    AutoDiffXd along time (dF/dt given, dz/dt the block's own derivative). Eq. 13 says
    dV/dt = -K Gamma K w^2 < 0 for either sign of E and of w; the printed sign of eq. 10
    would make it +K Gamma K w^2."""
    gamma, alpha, K, desired = 1e-5, 0.1, 2500.0, 5.0
    # The converted block is a plain Diagram: its ports by name, z its only state; E0 (a
    # constant, left at its default) does not enter dXr/dt.
    block = OptimalAdmittance(
        gamma=gamma, alpha=alpha, stiffness=K, force_axes=(0,), num_axes=3
    ).ToAutoDiffXd()
    context = block.CreateDefaultContext()
    block.GetInputPort("measured_force").FixValue(context, [AutoDiffXd(measured, [force_rate])])
    block.GetInputPort("desired_force").FixValue(context, [AutoDiffXd(desired, [0.0])])
    context.SetContinuousState([AutoDiffXd(0.4, [0.0])])
    integral_rate = block.EvalTimeDerivatives(context).CopyToVector()[0].value()
    context.SetContinuousState([AutoDiffXd(0.4, [integral_rate])])
    offset = block.GetOutputPort("reference_offset").Eval(context)[0]
    reference_rate = offset.derivatives()[0]
    weighted = (desired - measured) + alpha * (-force_rate)
    lyapunov_rate = (-K * weighted) * reference_rate
    assert lyapunov_rate == pytest.approx(-K * gamma * K * weighted**2, rel=1e-12)
    assert lyapunov_rate < 0


def test_papers_gains_are_stable_with_margin(paper_with_sensor):
    A = LinearizeAtEquilibrium(FindContactEquilibrium(paper_with_sensor)).A()
    modes = modal_summary(A)
    assert modes["stable"]
    assert modes["max_real_part"] < -0.05
    certificate = lyapunov_certificate(A)
    assert certificate["positive_definite"]
    assert certificate["residual"] < 1e-6 * certificate["max_eigenvalue"]
    # Margin: Gamma can grow more than 3x before the loop loses stability on Ke = 5e4 N/m.
    assert max_real_part(with_values(paper_with_sensor, {"admittance.gamma": 3e-5})) < 0


def test_linear_model_matches_the_nonlinear_diagram(paper_with_sensor):
    step = linear_versus_nonlinear(paper_with_sensor, step=0.1, duration=0.5, samples=51)
    # The force follows the 0.1 N step of Fr. Quasi-static model (docs/evidence/paper-notes.md §4):
    # the error jumps to 0.1 / (1 + K_eff Gamma K alpha) = 0.0144 N (K_eff = Kp Ke / (Kp + Ke)
    # = 2381 N/m) and decays with alpha + 1 / (K_eff Gamma K) = 0.117 s: 2e-4 N is left at
    # 0.5 s (measured 7.6e-5 N). 1e-3 N holds that with a factor of 5.
    assert step.nonlinear[-1] == pytest.approx(0.1, abs=1e-3)
    # Linear and nonlinear agree to 5.8e-7 N (measured; both simulated at accuracy 1e-7,
    # and a 0.1 N step barely leaves the linear range). 1e-5 N is 17 times that. The
    # linearized law with its integral gain 30 % too high (the admittance state's column of
    # A times 1.3) departs by 1.0e-3 N: 100 times the tolerance.
    assert np.max(np.abs(step.linear - step.nonlinear)) < 1e-5


def test_critical_gamma_agrees_with_nonlinear_simulation(paper_with_sensor):
    """The boundary from the linearization, confirmed on the nonlinear diagram (20 %)."""
    scenario = with_values(paper_with_sensor, {"wall.stiffness": 1e5})
    gamma = critical_gamma(scenario)
    assert gamma is not None and 1e-5 < gamma < 1e-4
    below = simulate_near_critical(scenario, 0.8 * gamma, duration=1.5)
    above = simulate_near_critical(scenario, 1.25 * gamma, duration=1.5)
    assert below["converges"] and not above["converges"]


def test_ideal_sensor_has_no_critical_gamma_below_1e_2():
    scenario = load_scenario("paper_stiffness_step", ["sensor.kind=ideal"])
    assert critical_gamma(scenario, high=1e-2) is None


def test_sampled_admittance_needs_a_fast_rate(paper_with_sensor):
    """A 1 kHz digital admittance block is unstable with the paper's gains; 10 kHz is not."""
    assert sampled_spectral_radius(paper_with_sensor, 1e-4) < 1.0
    assert sampled_spectral_radius(paper_with_sensor, 1e-3) > 1.0


def test_stability_map_boundary_moves_with_stiffness(paper_with_sensor):
    gammas = np.array([1e-6, 1e-5, 1e-4])
    stiffnesses = np.array([1e3, 1e5, 1e7])
    grid = stability_map(
        paper_with_sensor, "admittance.gamma", gammas, "wall.stiffness", stiffnesses
    )
    stable = grid < 0
    assert stable[0, :2].all()  # a soft wall tolerates large Gamma
    assert not stable[2, 1] and not stable[2, 2]  # a very stiff wall does not
    assert stable[1, 1]  # the paper's Gamma at 1e5 N/m


def test_lyapunov_function_along_the_paper_run():
    result = run_scenario(load_scenario("paper_stiffness_step", ["sensor.kind=ideal"]))
    trajectory = lyapunov_along_trajectory(result)
    V = trajectory["V"]
    # V decays from the first contact (E = Fr) to the end, but not monotonically: the
    # paper's claim is quasi-static; the stiffness step at 15 s kicks it up again.
    assert V[-1] < 1e-3 * V[0]
    assert not trajectory["monotone_after_contact"]
    assert any(start <= 15.0 <= end + 0.01 for start, end in trajectory["growing_intervals"])


def test_lyapunov_function_along_the_moving_wall_rises_by_the_force_lag():
    """Settled before the wall moves, V holds the noise's share only; the wall receding at
    v = 5 mm/s from t = 2.5 s leaves the force error E = v / (Gamma K) = 0.42 N (the lag of
    docs/evidence/paper-notes.md §4), so the mean of V rises by 1/2 (v / (Gamma K))^2 = 0.087."""
    result = run_scenario(load_scenario("paper_moving_wall", ["duration=4.0"]))
    trajectory = lyapunov_along_trajectory(result)
    V = trajectory["V"]
    before_motion = (result.time > 2.0) & (result.time < 2.5)
    during_motion = result.time > 3.0
    lag = 0.005 / (1e-5 * 1200.0)
    predicted = np.mean(V[before_motion]) + 0.5 * lag**2
    # Measured 0.102 against the predicted 0.108: the lag is still building up after 3 s.
    # 20 % holds that; without the lag (or with V unchanged) the mean stays near 0.021.
    assert np.mean(V[during_motion]) == pytest.approx(predicted, rel=0.2)
    # The sensor noise makes V flicker: it grows on about half of the samples after the
    # first contact (measured 48 %), as a coin flip does; a V that decays or grows
    # steadily gives a fraction near 0 or 1. Reported, not hidden.
    assert 0.3 < trajectory["growing_fraction"] < 0.7


def test_stability_command_writes_the_report(tmp_path, capsys):
    out = tmp_path / "stability"
    status = main(
        [
            "stability",
            "paper_stiffness_step",
            "--set",
            "sensor.kind=flexiforce",
            "--quick",
            "--no-trajectory",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    report = json.loads((out / "report.json").read_text())
    assert report["modes"]["stable"] and report["lyapunov"]["positive_definite"]
    # The nonlinear diagram converges at Gamma = 4.2e-5 and does not at 5.2e-5
    # (test_critical_gamma_bracket_by_simulation): the linearization's boundary lies there.
    assert GAMMA_CONVERGES < report["critical_gamma"] < GAMMA_DIVERGES
    assert report["confirmation"]["below"]["converges"]
    assert not report["confirmation"]["above"]["converges"]
    for name in ("stiffness", "alpha", "filter_cutoff", "period"):
        assert (out / f"map_gamma_vs_{name}.png").is_file()
    assert "P > 0" in (out / "report.txt").read_text()
    # It says what it wrote, and only that: no V(t) figure without the trajectory.
    captured = capsys.readouterr()
    written = captured.out.strip().splitlines()[-1]
    assert written.startswith(f"wrote {out}/: ")
    names = sorted(p.name for p in out.iterdir() if p.name != MARKER)
    assert sorted(written.split(": ", 1)[1].split(", ")) == names
    assert sorted(marker_entries(out)) == names  # the result marker lists every file
    assert "lyapunov_along_trajectory.png" not in written
    # A progress line per stage on stderr, the four maps among them.
    assert captured.err.count("admittance stability: stability map ") == 4


# A bracket of the critical Gamma of paper_stiffness_step with the FlexiForce (Ke = 5e4 N/m)
# by nonlinear simulation, independent of the linearization: from the equilibrium, a 0.5 N
# step of Fr dies out (peak error 1.7e-4 N in the last fifth of 1.5 s, from 0.5 N) at the
# lower value and grows (0.94 N to 1.05 N) at the upper one.
GAMMA_CONVERGES, GAMMA_DIVERGES = 4.2e-5, 5.2e-5


@pytest.mark.slow
def test_critical_gamma_bracket_by_simulation(paper_with_sensor):
    assert simulate_near_critical(paper_with_sensor, GAMMA_CONVERGES, duration=1.5)["converges"]
    assert not simulate_near_critical(paper_with_sensor, GAMMA_DIVERGES, duration=1.5)["converges"]
