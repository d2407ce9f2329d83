"""The baseline force controllers: their laws against hand-computed values, their common
ports, the matched tuning rule, and the scenario keys that choose them."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from admittance.diagrams.robots.planar_arm.plant import baseline_gains
from admittance.diagrams.robots.planar_arm.scenario import CONTROLLER_KINDS
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.adaptive_impedance import AdaptiveImpedance
from admittance.systems.classical_admittance import ClassicalAdmittance
from admittance.systems.fixed_reference import FixedReference
from admittance.systems.force_axes import force_error
from admittance.systems.optimal_admittance import OptimalAdmittance


def _fix(block, measured, desired, state=None):
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [measured])
    block.desired_force_input.FixValue(context, [desired])
    if state is not None:
        context.SetContinuousState(state)
    return context


def test_classical_admittance_is_a_mass_damper_spring_on_the_force_error():
    block = ClassicalAdmittance(
        mass=0.5, damping=40.0, stiffness=100.0, force_axes=(0,), num_axes=3
    )
    # Xr = 2 mm, dXr/dt = 0.1 m/s, E = 5 - 3 = 2 N:
    # M a = E - D v - Ks x = 2 - 4 - 0.2 = -2.2 N -> a = -4.4 m/s^2.
    context = _fix(block, measured=3.0, desired=5.0, state=[0.002, 0.1])
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [0.1, -4.4])
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.002, 0, 0])


def test_adaptive_impedance_follows_jung_hsia_bonitz():
    block = AdaptiveImpedance(
        mass=0.5, damping=40.0, adaptation_rate=10.0, force_axes=(0,), num_axes=3
    )
    # Xr = 1 mm, dXr/dt = 0.01 m/s, Phi = 0.02 m/s, E = 2 N:
    # m a = E + b Phi - b v = 2 + 0.8 - 0.4 = 2.4 N -> a = 4.8; Phi' = 10 * 2 / 40 = 0.5.
    context = _fix(block, measured=3.0, desired=5.0, state=[0.001, 0.01, 0.02])
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [0.01, 4.8, 0.5])
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.001, 0, 0])


def test_fixed_reference_is_eq_6():
    block = FixedReference(wall_position=0.201, wall_stiffness=5e4, force_axes=(0,), num_axes=3)
    context = _fix(block, measured=0.0, desired=5.0)
    block.desired_position_input.FixValue(context, [0.2, -0.25, math.pi / 2])
    # Xr = Xe + Fr / Ke - Xd = 0.201 + 1e-4 - 0.2 = 1.1 mm, on x only.
    np.testing.assert_allclose(
        block.reference_offset_output.Eval(context), [0.0011, 0, 0], atol=1e-15
    )


@pytest.mark.parametrize(
    "block, state",
    [
        (ClassicalAdmittance(mass=0.5, damping=40.0, force_axes=(0,), num_axes=3), [0.001, 0.01]),
        (
            AdaptiveImpedance(
                mass=0.5, damping=40.0, adaptation_rate=10.0, force_axes=(0,), num_axes=3
            ),
            [0.001, 0.01, 0.0],
        ),
        (
            OptimalAdmittance(gamma=1e-5, alpha=0.1, stiffness=2500.0, force_axes=(0,), num_axes=3),
            [0.3],
        ),
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


def test_the_force_error_of_a_broken_reading_is_zero_for_autodiff_too():
    """The baselines' E = Fr - Fm per axis (systems/force_axes.py): 0 where Fm is NaN, for
    floats and for AutoDiffXd (a converted baseline in Linearize) alike."""
    assert force_error(float, np.array([5.0, 5.0]), np.array([4.0, math.nan])) == [1.0, 0.0]
    errors = force_error(
        AutoDiffXd, [AutoDiffXd(5.0), AutoDiffXd(5.0)], [AutoDiffXd(4.0), AutoDiffXd(math.nan)]
    )
    assert [e.value() for e in errors] == [1.0, 0.0]


@pytest.mark.parametrize(
    "block",
    [
        ClassicalAdmittance(mass=0.5, damping=40.0, force_axes=(0,), num_axes=3),
        AdaptiveImpedance(
            mass=0.5, damping=40.0, adaptation_rate=10.0, force_axes=(0,), num_axes=3
        ),
        FixedReference(wall_position=0.2, wall_stiffness=5e4, force_axes=(0,), num_axes=3),
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
    arguments = dict(force_axes=(0,), num_axes=3)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        ClassicalAdmittance(**arguments)


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
    from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop

    for kind in CONTROLLER_KINDS:
        loop = BuildClosedLoop(load_scenario("paper_moving_wall", [f"controller.kind={kind}"]))
        assert (loop.admittance is None) == (kind == "pid_only")
        if loop.admittance is not None:
            assert loop.admittance.get_name() == kind


def _fix_axes(block, measured, desired, state):
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, measured)
    block.desired_force_input.FixValue(context, desired)
    context.SetContinuousState(state)
    return context


def test_classical_admittance_on_two_axes_keeps_each_axis_its_own_gains():
    """Force on x and theta (axes 0 and 2), different M, D, Ks each; by hand, per axis:
    a = (E - D v - Ks x) / M, with state (x0, x2, v0, v2)."""
    block = ClassicalAdmittance(
        mass=[0.5, 2.0], damping=[40.0, 10.0], stiffness=[100.0, 0.0], force_axes=[0, 2], num_axes=3
    )
    assert block.gains["mass"].tolist() == [0.5, 2.0]
    context = _fix_axes(block, [3.0, 1.0], [5.0, 0.0], [0.002, 0.01, 0.1, -0.2])
    # Axis 0: E = 2, (2 - 4 - 0.2) / 0.5 = -4.4. Axis 2: E = -1, (-1 + 2 - 0) / 2 = 0.5.
    np.testing.assert_allclose(
        block.EvalTimeDerivatives(context).CopyToVector(), [0.1, -0.2, -4.4, 0.5]
    )
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.002, 0.0, 0.01])


def test_adaptive_impedance_on_three_axes_keeps_each_axis_its_own_gains():
    """State (x0, x1, x2, v0, v1, v2, Phi0, Phi1, Phi2): m a = E + b Phi - b v,
    Phi' = rate E / b, each axis with its own m, b and rate."""
    block = AdaptiveImpedance(
        mass=[0.5, 2.0, 1.0],
        damping=[40.0, 10.0, 20.0],
        adaptation_rate=[10.0, 5.0, 2.0],
        force_axes=[0, 1, 2],
        num_axes=3,
    )
    assert block.gains["adaptation_rate"].tolist() == [10.0, 5.0, 2.0]
    state = [0.001, 0.002, 0.003, 0.01, -0.1, 0.0, 0.02, 0.3, 0.0]
    context = _fix_axes(block, [3.0, 1.0, 4.0], [5.0, 0.0, 0.0], state)
    # Axis 0: (2 + 0.8 - 0.4) / 0.5 = 4.8, Phi' = 10 * 2 / 40 = 0.5.
    # Axis 1: (-1 + 3 + 1) / 2 = 1.5, Phi' = 5 * -1 / 10 = -0.5.
    # Axis 2: (-4 + 0 - 0) / 1 = -4, Phi' = 2 * -4 / 20 = -0.4.
    np.testing.assert_allclose(
        block.EvalTimeDerivatives(context).CopyToVector(),
        [0.01, -0.1, 0.0, 4.8, 1.5, -4.0, 0.5, -0.5, -0.4],
    )
    np.testing.assert_allclose(block.reference_offset_output.Eval(context), [0.001, 0.002, 0.003])


def test_classical_admittance_is_a_mass_damper_by_default():
    """Without stiffness: Ks = 0, so the offset itself does not pull back (a = (E - D v) / M)."""
    block = ClassicalAdmittance(mass=0.5, damping=40.0, force_axes=(0,), num_axes=3)
    context = _fix(block, measured=3.0, desired=5.0, state=[0.002, 0.1])
    np.testing.assert_allclose(block.EvalTimeDerivatives(context).CopyToVector(), [0.1, -4.0])


def test_fixed_reference_on_two_axes_subtracts_each_axis_own_desired_position():
    """force_axes [2, 0]: entry i of the estimates belongs to axis force_axes[i]."""
    block = FixedReference(
        wall_position=[0.5, 0.201], wall_stiffness=[1e3, 5e4], force_axes=[2, 0], num_axes=3
    )
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [0.0, 0.0])
    block.desired_force_input.FixValue(context, [2.0, 5.0])
    block.desired_position_input.FixValue(context, [0.2, -0.25, 0.4])
    # theta: 0.5 + 2 / 1e3 - 0.4 = 0.102; x: 0.201 + 1e-4 - 0.2 = 0.0011.
    np.testing.assert_allclose(
        block.reference_offset_output.Eval(context), [0.0011, 0.0, 0.102], atol=1e-15
    )


@pytest.mark.parametrize(
    "make, state",
    [
        (
            lambda: ClassicalAdmittance(
                mass=0.5, damping=40.0, stiffness=100.0, force_axes=(0,), num_axes=3
            ),
            [0.002, 0.1],
        ),
        (
            lambda: AdaptiveImpedance(
                mass=0.5, damping=40.0, adaptation_rate=10.0, force_axes=(0,), num_axes=3
            ),
            [0.001, 0.01, 0.02],
        ),
    ],
    ids=["classical", "adaptive"],
)
def test_baselines_converted_to_autodiff_keep_their_law(make, state):
    """The AutoDiffXd copy (what Linearize uses) computes the same derivatives, and its
    derivative with respect to the measured force is the law's: -1 / M on the acceleration."""
    block = make()
    context = _fix(block, measured=3.0, desired=5.0, state=state)
    expected = block.EvalTimeDerivatives(context).CopyToVector()
    block_ad = block.ToAutoDiffXd()
    context_ad = block_ad.CreateDefaultContext()
    block_ad.measured_force_input.FixValue(context_ad, [AutoDiffXd(3.0, [1.0])])
    block_ad.desired_force_input.FixValue(context_ad, [AutoDiffXd(5.0, [0.0])])
    context_ad.SetContinuousState([AutoDiffXd(x, [0.0]) for x in state])
    derivatives = block_ad.EvalTimeDerivatives(context_ad).CopyToVector()
    np.testing.assert_allclose([d.value() for d in derivatives], expected, rtol=1e-12)
    assert derivatives[1].derivatives()[0] == pytest.approx(-1.0 / 0.5)


def test_fixed_reference_converted_to_autodiff_keeps_its_law():
    block = FixedReference(
        wall_position=0.201, wall_stiffness=5e4, force_axes=(0,), num_axes=3
    ).ToAutoDiffXd()
    context = block.CreateDefaultContext()
    block.measured_force_input.FixValue(context, [AutoDiffXd(0.0)])
    block.desired_force_input.FixValue(context, [AutoDiffXd(5.0, [1.0])])
    block.desired_position_input.FixValue(context, [AutoDiffXd(v, [0.0]) for v in (0.2, 0, 0)])
    (offset, _, _) = block.reference_offset_output.Eval(context)
    assert offset.value() == pytest.approx(0.0011, abs=1e-15)
    assert offset.derivatives()[0] == pytest.approx(1.0 / 5e4)  # dXr/dFr = 1 / Ke_est


@pytest.mark.parametrize(
    "make",
    [
        lambda: ClassicalAdmittance(0.5, 40.0),
        lambda: AdaptiveImpedance(0.5, 40.0, 10.0),
        lambda: FixedReference(0.2, 5e4),
    ],
    ids=["classical", "adaptive", "fixed"],
)
def test_baseline_arguments_are_keyword_only(make):
    with pytest.raises(TypeError):
        make()


@pytest.mark.parametrize(
    "make, message",
    [
        (
            lambda: AdaptiveImpedance(
                mass=0.0, damping=1.0, adaptation_rate=1.0, force_axes=(0,), num_axes=3
            ),
            "mass must be > 0",
        ),
        (
            lambda: AdaptiveImpedance(
                mass=1.0, damping=0.0, adaptation_rate=1.0, force_axes=(0,), num_axes=3
            ),
            "damping",
        ),
        (
            lambda: AdaptiveImpedance(
                mass=1.0, damping=1.0, adaptation_rate=0.0, force_axes=(0,), num_axes=3
            ),
            "adaptation_rate must be > 0",
        ),
        (
            lambda: FixedReference(
                wall_position=math.nan, wall_stiffness=5e4, force_axes=(0,), num_axes=3
            ),
            "wall_position",
        ),
        (
            lambda: FixedReference(
                wall_position=0.2, wall_stiffness=0.0, force_axes=(0,), num_axes=3
            ),
            "wall_stiffness",
        ),
        (
            lambda: FixedReference(
                wall_position=0.2, wall_stiffness=5e4, force_axes=[3], num_axes=3
            ),
            "axes",
        ),
    ],
)
def test_baseline_arguments_are_checked(make, message):
    with pytest.raises(ValueError, match=message):
        make()
