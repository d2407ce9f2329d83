"""The baseline force controllers: their laws against hand-computed values, their common
ports, the matched tuning rule, and the scenario keys that choose them."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from admittance.diagrams.force_controllers import baseline_gains
from admittance.diagrams.scenario import CONTROLLER_KINDS, ScenarioError, load_scenario
from admittance.systems.adaptive_impedance import AdaptiveImpedance
from admittance.systems.classical_admittance import ClassicalAdmittance
from admittance.systems.fixed_reference import FixedReference
from admittance.systems.optimal_admittance import OptimalAdmittance


def _fix(block, measured, desired, state=None):
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [measured])
    block.desired_force_input.FixValue(context, [desired])
    if state is not None:
        context.SetContinuousState(state)
    return context


def test_classical_admittance_is_a_mass_damper_spring_on_the_force_error():
    block = ClassicalAdmittance(mass=0.5, damping=40.0, stiffness=100.0)
    # Xr = 2 mm, dXr/dt = 0.1 m/s, E = 5 - 3 = 2 N:
    # M a = E - D v - Ks x = 2 - 4 - 0.2 = -2.2 N -> a = -4.4 m/s^2.
    context = _fix(block, measured=3.0, desired=5.0, state=[0.002, 0.1])
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [0.1, -4.4])
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.002, 0, 0])


def test_adaptive_impedance_follows_jung_hsia_bonitz():
    block = AdaptiveImpedance(mass=0.5, damping=40.0, adaptation_rate=10.0)
    # Xr = 1 mm, dXr/dt = 0.01 m/s, Phi = 0.02 m/s, E = 2 N:
    # m a = E + b Phi - b v = 2 + 0.8 - 0.4 = 2.4 N -> a = 4.8; Phi' = 10 * 2 / 40 = 0.5.
    context = _fix(block, measured=3.0, desired=5.0, state=[0.001, 0.01, 0.02])
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [0.01, 4.8, 0.5])
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.001, 0, 0])


def test_fixed_reference_is_eq_6():
    block = FixedReference(wall_position=0.201, wall_stiffness=5e4)
    context = _fix(block, measured=0.0, desired=5.0)
    block.desired_position_input.FixValue(context, [0.2, -0.25, math.pi / 2])
    # Xr = Xe + Fr / Ke - Xd = 0.201 + 1e-4 - 0.2 = 1.1 mm, on x only.
    np.testing.assert_allclose(
        block.reference_offset_output.Eval(context), [0.0011, 0, 0], atol=1e-15
    )


@pytest.mark.parametrize(
    "block, state",
    [
        (ClassicalAdmittance(mass=0.5, damping=40.0), [0.001, 0.01]),
        (AdaptiveImpedance(mass=0.5, damping=40.0, adaptation_rate=10.0), [0.001, 0.01, 0.0]),
        (OptimalAdmittance(gamma=1e-5, alpha=0.1, stiffness=2500.0), [0.3]),
    ],
    ids=["classical", "adaptive", "optimal"],
)
def test_a_broken_sensor_reading_holds_the_controller(block, state):
    """NaN in: no NaN out, and the force error counts as zero (no integration)."""
    context = _fix(block, measured=math.nan, desired=5.0, state=state)
    assert np.all(np.isfinite(block.reference_offset_output.Eval(context)))
    derivatives = block.EvalTimeDerivatives(context).CopyToVector()
    assert np.all(np.isfinite(derivatives))
    healthy = _fix(block, measured=5.0, desired=5.0, state=state)  # E = 0 exactly
    np.testing.assert_allclose(derivatives, block.EvalTimeDerivatives(healthy).CopyToVector())


@pytest.mark.parametrize(
    "block",
    [
        ClassicalAdmittance(mass=0.5, damping=40.0),
        AdaptiveImpedance(mass=0.5, damping=40.0, adaptation_rate=10.0),
        FixedReference(wall_position=0.2, wall_stiffness=5e4),
    ],
    ids=["classical", "adaptive", "fixed"],
)
def test_baselines_have_the_admittance_ports_and_convert_to_autodiff(block):
    for name in ("measured_force", "desired_force"):
        assert block.GetInputPort(name).size() == 1
    assert block.GetOutputPort("reference_offset").size() == 3
    block.ToAutoDiffXd()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(mass=0.0, damping=1.0), "mass must be > 0"),
        (dict(mass=1.0, damping=-1.0), "damping must be > 0"),
        (dict(mass=1.0, damping=1.0, stiffness=-5.0), "stiffness must be >= 0"),
        (dict(mass=1.0, damping=1.0, force_axes=[3]), "force_axes must be distinct"),
    ],
)
def test_classical_admittance_arguments_are_checked(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ClassicalAdmittance(**kwargs)


def test_matched_tuning_gives_the_paper_s_crossover():
    scenario = load_scenario("paper_stiffness_step")
    gains = baseline_gains(scenario)
    kp, gamma = 2500.0, 1e-5
    # Same integral gain as Gamma K; the force loop M s^2 + D s + Kp critically damped.
    assert gains["damping"] == pytest.approx(1.0 / (gamma * kp))
    assert gains["damping"] ** 2 == pytest.approx(4.0 * gains["mass"] * kp)
    assert gains["adaptation_rate"] == pytest.approx(kp * gamma * kp / 5.0)
    manual = load_scenario(
        "paper_stiffness_step", ["controller.tuning=manual", "controller.damping=80"]
    )
    assert baseline_gains(manual)["damping"] == 80.0


@pytest.mark.parametrize(
    "override, message",
    [
        ("controller.kind=impedance", "controller.kind: must be one of optimal_admittance"),
        ("controller.tuning=auto", "controller.tuning: must be 'matched' or 'manual'"),
        ("controller.mass=0", "controller.mass: must be in (0, 1000]"),
        ("controller.wall_position_error=0.5", "controller.wall_position_error"),
        ("admittance.max_force=4", "admittance.max_force: must be > force_reference"),
        ("admittance.max_force=200", "admittance.max_force: must be < 111"),
        ("admittance.force_bound_gain=0", "admittance.force_bound_gain: must be in (0, 100]"),
    ],
)
def test_controller_keys_are_validated(override, message):
    with pytest.raises(ScenarioError, match=re.escape(message)):
        load_scenario("paper_moving_wall", [override])


def test_every_controller_kind_builds_a_loop():
    from admittance.diagrams.closed_loop import BuildClosedLoop

    for kind in CONTROLLER_KINDS:
        loop = BuildClosedLoop(load_scenario("paper_moving_wall", [f"controller.kind={kind}"]))
        assert (loop.admittance is None) == (kind == "pid_only")
        if loop.admittance is not None:
            assert loop.admittance.get_name() == kind
