"""The fingertip kinematics: generated float code against the plant and against eq. 18.

The generated code (systems/planar_kinematics.py, systems/expression_code.py) must give the
plant's own X = (x, y, theta), J v and J at any configuration, for the project's arm and for
another URDF, while AutoDiffXd keeps asking the plant.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.symbolic import Evaluate, Expression, Variable, if_then_else
from pydrake.symbolic import atan2 as symbolic_atan2
from pydrake.symbolic import cos as symbolic_cos
from pydrake.symbolic import max as symbolic_max
from pydrake.symbolic import sqrt as symbolic_sqrt

from admittance.systems.expression_code import compile_expressions
from admittance.systems.planar_kinematics import (
    PLANAR_COORDINATES,
    PlanarFrameKinematics,
    PlanarKinematics,
    generate_planar_kinematics,
)
from admittance.systems.task_kinematics import split_kinematics, wrap_angle

LENGTHS = (0.20, 0.20, 0.10)

# Plant and generated code agree to round-off: the worst difference measured over 1,000
# random states was 4.4e-16; 1e-12 leaves a margin of three orders for other machines.
TOLERANCE = 1e-12


def eq18(q, v):
    """[X; J v; J] of the paper's arm (eq. 18), written by hand."""
    l1, l2, l3 = LENGTHS
    a1, a2, a3 = q[0], q[0] + q[1], q[0] + q[1] + q[2]
    X = [
        l1 * math.sin(a1) + l2 * math.sin(a2) + l3 * math.sin(a3),
        -l1 * math.cos(a1) - l2 * math.cos(a2) - l3 * math.cos(a3),
        a3,
    ]
    J = np.array(
        [
            [
                l1 * math.cos(a1) + l2 * math.cos(a2) + l3 * math.cos(a3),
                l2 * math.cos(a2) + l3 * math.cos(a3),
                l3 * math.cos(a3),
            ],
            [
                l1 * math.sin(a1) + l2 * math.sin(a2) + l3 * math.sin(a3),
                l2 * math.sin(a2) + l3 * math.sin(a3),
                l3 * math.sin(a3),
            ],
            [1.0, 1.0, 1.0],
        ]
    )
    return np.concatenate([X, J @ v, J.reshape(-1)])


def _assert_same_kinematics(actual, expected, atol=TOLERANCE):
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    np.testing.assert_allclose(actual[[0, 1]], expected[[0, 1]], rtol=0, atol=atol)
    assert abs(math.remainder(actual[2] - expected[2], 2 * math.pi)) < atol  # angles mod 2 pi
    np.testing.assert_allclose(actual[3:], expected[3:], rtol=0, atol=atol)


def test_generated_kinematics_are_the_plants_and_eq18(arm_plant):
    generated = generate_planar_kinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    plant_path = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    rng = np.random.default_rng(19)
    for _ in range(200):
        q = rng.uniform(-math.pi, math.pi, 3)
        v = rng.uniform(-2.0, 2.0, 3)
        state = np.concatenate([q, v])
        values = generated(state.tolist())
        _assert_same_kinematics(values, plant_path.kinematics(state))
        _assert_same_kinematics(values, eq18(q, v))


# A different arm: four joints (a prismatic one among them), tilted and offset joint
# frames, and a frame that is not a body origin. Nothing in the generator knows this model.
_LINK = """  <link name="{}"><inertial><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
"""
_JOINT = """  <joint name="{}" type="{}"><parent link="{}"/><child link="{}"/>
    <origin xyz="{}" rpy="0 0 {}"/><axis xyz="{}"/>
    <limit lower="-{}" upper="{}" effort="10" velocity="1"/></joint>
"""
_JOINTS = [  # name, type, parent, child, origin xyz, origin yaw, axis, limit
    ("j1", "revolute", "base", "a", "0.1 0.05 0", 0.3, "0 0 1", 3),
    ("j2", "prismatic", "a", "b", "0.3 0 0", -0.2, "1 0 0", 1),
    ("j3", "revolute", "b", "c", "0 0.25 0", 0.0, "0 0 1", 3),
    ("j4", "revolute", "c", "d", "0.15 0 0", 0.5, "0 0 1", 3),
]
OTHER_URDF = (
    '<?xml version="1.0"?>\n<robot name="other_arm">\n  <link name="base"/>\n'
    + "".join(_LINK.format(name) for name in "abcd")
    + '  <link name="tip"/>\n'
    + "".join(_JOINT.format(*joint, joint[-1]) for joint in _JOINTS)
    + """  <joint name="tool" type="fixed"><parent link="d"/><child link="tip"/>
    <origin xyz="0.07 -0.02 0" rpy="0 0 0.1"/></joint>
</robot>
"""
)


def test_another_urdf_works_unchanged():
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(OTHER_URDF, "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base"))
    plant.Finalize()
    generated = generate_planar_kinematics(plant, "tip", coordinates=PLANAR_COORDINATES)
    plant_path = PlanarFrameKinematics(plant, "tip", coordinates=PLANAR_COORDINATES)
    rng = np.random.default_rng(4)
    for _ in range(100):
        state = np.concatenate([rng.uniform(-2.5, 2.5, 4), rng.uniform(-1.0, 1.0, 4)])
        _assert_same_kinematics(generated(state.tolist()), plant_path.kinematics(state))


def test_the_system_outputs_the_generated_kinematics(arm_plant):
    system = PlanarKinematics(arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES)
    context = system.CreateDefaultContext()
    q, v = np.array([-0.45, 1.66, 0.36]), np.array([0.1, -0.2, 0.3])
    system.estimated_state_input.FixValue(context, np.concatenate([q, v]))
    values = system.kinematics_output.Eval(context)
    _assert_same_kinematics(values, eq18(q, v))
    pose, velocity, jacobian = split_kinematics(values, 3, 3)
    np.testing.assert_allclose(velocity, jacobian @ v, atol=TOLERANCE)
    np.testing.assert_allclose(pose, values[:3])


def test_autodiff_asks_the_plant(arm_plant):
    """Linearize differentiates the plant's own kinematics: dX/dq = J."""
    system = PlanarKinematics(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES
    ).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    q = np.array([-0.45, 1.66, 0.36])
    state = [AutoDiffXd(value, np.eye(6)[i]) for i, value in enumerate(np.r_[q, 0, 0, 0])]
    system.GetInputPort("estimated_state").FixValue(context, state)
    values = system.GetOutputPort("kinematics").Eval(context)
    expected = eq18(q, np.zeros(3))
    _assert_same_kinematics([x.value() for x in values], expected)
    pose_gradient = np.array([x.derivatives()[:3] for x in values[:3]])
    np.testing.assert_allclose(pose_gradient, expected[6:].reshape(3, 3), atol=TOLERANCE)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_state_that_is_not_finite_is_named(arm_plant, bad):
    system = PlanarKinematics(arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES)
    context = system.CreateDefaultContext()
    system.estimated_state_input.FixValue(context, [0.1, bad, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(RuntimeError, match="state is not finite"):
        system.kinematics_output.Eval(context)


def test_expression_code_evaluates_as_drake_does():
    x, y = Variable("x"), Variable("y")
    X, Y = Expression(x), Expression(y)
    expressions = [
        3.0 * X * Y - 2.0 * X + 0.5,
        X / (Y + 2.0),
        symbolic_sqrt(X * X + Y * Y) + symbolic_atan2(Y, X),
        symbolic_cos(X) ** 2 - abs(Y),
        symbolic_max(X, Y),
        Expression(7.0),
        -X,
    ]
    function = compile_expressions(expressions, [x, y])
    rng = np.random.default_rng(0)
    for values in rng.uniform(-3.0, 3.0, (50, 2)):
        expected = [Evaluate([e], {x: values[0], y: values[1]})[0, 0] for e in expressions]
        np.testing.assert_allclose(function(values.tolist()), expected, rtol=1e-15, atol=1e-15)
    # Repeated subexpressions are computed once.
    shared = compile_expressions([symbolic_cos(X) * 2.0, symbolic_cos(X) * 3.0], [x])
    assert shared.source.count("cos(") == 1


def test_expression_code_refuses_what_it_cannot_write():
    x, y = Variable("x"), Variable("y")
    with pytest.raises(NotImplementedError, match="IfThenElse"):
        compile_expressions([if_then_else(Expression(x) > 0.0, Expression(x), 0.0)], [x])
    with pytest.raises(ValueError, match="'y'"):
        compile_expressions([Expression(x) + Expression(y)], [x])


def test_wrap_angle_keeps_an_angle_within_pi_exactly_and_wraps_the_rest():
    """The IEEE remainder by 2 pi: an angle in [-pi, pi] comes back bit for bit (atan2 of
    its sine and cosine would not: -0.9331 comes back one unit in the last place off)."""
    assert wrap_angle(-0.9331) == -0.9331
    assert wrap_angle(1.5 * math.pi) == pytest.approx(-0.5 * math.pi, abs=1e-15)
    assert wrap_angle(-3.5) == pytest.approx(2.0 * math.pi - 3.5, abs=1e-15)
    assert wrap_angle(AutoDiffXd(1.5 * math.pi)).value() == pytest.approx(-0.5 * math.pi)


def test_task_vectors_of_other_coordinates_and_their_jacobian_rows(arm_plant):
    """(x, y), (theta, x), (y, x) and (x, z) of the fingertip are the entries of the arm's
    (x, y, theta) in that order; z is 0 and its Jacobian row is zero (the arm moves in the
    x-y plane). A name built at run time (not an interned literal) counts as well."""
    q = np.array([-0.45, 1.66, 0.36])
    planar = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    planar.set_state(np.concatenate([q, np.zeros(3)]))
    pose, jacobian = planar.pose(), planar.jacobian()
    theta = "".join(["the", "ta"])
    for coordinates, rows in (
        (("x", "y"), [0, 1]),
        ((theta, "x"), [2, 0]),
        (("y", "x"), [1, 0]),
    ):
        kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=coordinates)
        kinematics.set_state(np.concatenate([q, np.zeros(3)]))
        np.testing.assert_array_equal(kinematics.pose(), pose[rows])
        np.testing.assert_array_equal(kinematics.jacobian(), jacobian[rows])
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=("x", "z"))
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    assert kinematics.pose()[1] == pytest.approx(0.0, abs=1e-15)
    assert np.all(kinematics.jacobian()[1] == 0.0)
    np.testing.assert_array_equal(kinematics.position()[:2], pose[:2])
    with pytest.raises(ValueError, match="coordinates must be distinct"):
        PlanarFrameKinematics(arm_plant, "fingertip", coordinates=("x", "x"))
    with pytest.raises(TypeError):  # keyword-only: a positional task could be a typo
        PlanarFrameKinematics(arm_plant, "fingertip", ("x", "y"))
    with pytest.raises(TypeError):
        PlanarKinematics(arm_plant, "fingertip")
    with pytest.raises(TypeError):  # the task is the caller's: no default frame or task
        PlanarKinematics(arm_plant, frame_name="fingertip")
    system = PlanarKinematics(arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES)
    assert (system.frame_name, system.num_velocities) == ("fingertip", 3)


def test_its_context_holds_the_state_last_set(arm_plant):
    """The safety systems read M(q) and g(q) from this context after set_state: it must be
    the plant context set to [q; v], not a fresh one."""
    q, v = np.array([-0.45, 1.66, 0.36]), np.array([0.1, -0.2, 0.3])
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, v]))
    np.testing.assert_array_equal(arm_plant.GetPositions(kinematics.context), q)
    np.testing.assert_array_equal(arm_plant.GetVelocities(kinematics.context), v)
