"""The compliant wall (eq. 4): unilateral spring, stiffness schedule and wall motion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import MultibodyForces
from pydrake.systems.framework import DiagramBuilder

from admittance.systems.compliant_wall import CompliantWall, CompliantWallLaw
from admittance.systems.planar_kinematics import (
    PLANAR_COORDINATES,
    PlanarFrameKinematics,
    PlanarKinematics,
)

Q = np.array([-0.45, 1.66, 0.36])  # an elbow configuration near the paper's task point


def _tip_x(plant, q):
    kinematics = PlanarFrameKinematics(plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    return kinematics.pose()[0]


def _wall_context(plant, wall, q, time=0.0):
    """The wall's context at time `time`, its kinematics input at [q; 0] from the plant."""
    context = wall.CreateDefaultContext()
    context.SetTime(time)
    kinematics = PlanarFrameKinematics(plant, "fingertip", coordinates=PLANAR_COORDINATES)
    wall.kinematics_input.FixValue(context, kinematics.kinematics(np.concatenate([q, np.zeros(3)])))
    return context


@pytest.mark.parametrize("penetration", [-1e-3, 0.0, 1e-4, 2e-3])
def test_force_is_unilateral_spring(arm_plant, penetration):
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - penetration,
        stiffness=5e4,
    )
    force = wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q))[0]
    assert force == pytest.approx(5e4 * max(penetration, 0.0), abs=1e-9)
    assert force >= 0.0  # the wall never pulls


def test_generalized_force_is_the_push_along_minus_x_at_the_fingertip(arm_plant):
    """tau = -F J_x^T is what the plant itself makes of the world force (-F, 0, 0) applied
    at the fingertip point (0, -0.10, 0) of link3: its own tree computation
    (CalcGeneralizedForces), independent of the kinematics vector the wall reads."""
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 1e-4,
        stiffness=5e4,
    )
    context = _wall_context(arm_plant, wall, Q)
    assert wall.contact_force_output.Eval(context)[0] == pytest.approx(5.0, rel=1e-6)
    plant_context = arm_plant.CreateDefaultContext()
    arm_plant.SetPositions(plant_context, Q)
    forces = MultibodyForces(arm_plant)
    link3 = arm_plant.GetBodyByName("link3")
    R_WB = arm_plant.EvalBodyPoseInWorld(plant_context, link3).rotation()
    link3.AddInForce(
        plant_context,
        p_BP_E=R_WB @ [0.0, -0.10, 0.0],  # the fingertip, from link3's origin, in world
        F_Bp_E=SpatialForce(tau=np.zeros(3), f=[-5.0, 0.0, 0.0]),
        frame_E=arm_plant.world_frame(),
        forces=forces,
    )
    expected = arm_plant.CalcGeneralizedForces(plant_context, forces)
    # The penetration 1e-4 m is exact to round-off: F = 5 N to 1e-11 (5e4 * 2e-16 m).
    np.testing.assert_allclose(wall.generalized_force_output.Eval(context), expected, atol=1e-9)
    assert np.all(expected != 0.0)  # every joint feels the push at this pose


def test_stiffness_steps_at_the_given_times(arm_plant):
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 1e-4,
        stiffness=5e4,
        stiffness_steps=[(15.0, 1e5), (20.0, 2e4)],
    )
    for time, stiffness in [(0.0, 5e4), (14.999, 5e4), (15.0, 1e5), (19.0, 1e5), (25.0, 2e4)]:
        assert wall.stiffness_at(time) == stiffness
        force = wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q, time))[0]
        assert force == pytest.approx(stiffness * 1e-4, rel=1e-6)


def test_wall_moves_between_start_and_end(arm_plant):
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=0.15,
        stiffness=2e4,
        velocity=0.005,
        motion_start=2.5,
        motion_end=6.5,
    )
    for time, position in [(0.0, 0.15), (2.5, 0.15), (4.5, 0.16), (6.5, 0.17), (9.0, 0.17)]:
        assert wall.position_at(time) == pytest.approx(position, abs=1e-15)
    assert wall.discontinuity_times() == [2.5, 6.5]
    # A wall that recedes past the tip releases it.
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 1e-3,
        stiffness=2e4,
        velocity=0.01,
    )
    assert wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q, 0.0))[0] > 0
    assert wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q, 0.2))[0] == 0.0


def test_autodiff_force_slope_is_the_stiffness(arm_plant):
    from pydrake.autodiffutils import AutoDiffXd

    # The wall behind the shared kinematics, both converted: dF/dq through the plant's own
    # AutoDiffXd kinematics.
    tip = _tip_x(arm_plant, Q)
    builder = DiagramBuilder()
    fingertip = builder.AddSystem(
        PlanarKinematics(arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES)
    )
    wall = builder.AddSystem(
        CompliantWall(
            arm_plant,
            frame_name="fingertip",
            coordinates=PLANAR_COORDINATES,
            position=tip - 1e-4,
            stiffness=5e4,
        )
    )
    builder.Connect(fingertip.kinematics_output, wall.kinematics_input)
    builder.ExportInput(fingertip.estimated_state_input, "state")
    builder.ExportOutput(wall.contact_force_output, "force")
    diagram = builder.Build().ToAutoDiffXd()
    context = diagram.CreateDefaultContext()
    state = [AutoDiffXd(value, np.eye(6)[i]) for i, value in enumerate(np.r_[Q, 0, 0, 0])]
    diagram.get_input_port(0).FixValue(context, state)
    force = diagram.get_output_port(0).Eval(context)[0]
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.r_[Q, 0, 0, 0])
    np.testing.assert_allclose(force.derivatives()[:3], 5e4 * kinematics.jacobian()[0], rtol=1e-9)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(stiffness=0.0), "stiffness"),
        (dict(stiffness_steps=[(1.0, -5.0)]), "stiffness_steps"),
        (dict(stiffness_steps=[(2.0, 1e4), (1.0, 1e4)]), "increasing"),
        (dict(position=math.nan), "position"),
        (dict(motion_start=3.0, motion_end=1.0), "motion_end"),
        (dict(frame_name="elbow"), "elbow"),
        (dict(coordinates=("y", "theta")), "must hold x"),
        (dict(stiffness=-5e4), "stiffness must be > 0"),
        (dict(stiffness=math.inf), "stiffness must be > 0"),
        (dict(stiffness_steps=[(1.0, 0.0)]), "stiffness_steps values must be > 0"),
        (dict(stiffness_steps=[(math.nan, 1e4)]), "increasing"),
        (dict(velocity=math.nan), "velocity must be finite"),
        (dict(position_offsets=[(2.0, 2.0, 0.01)]), "position_offsets"),
        (dict(position_offsets=[(2.0, 1.0, 0.01)]), "position_offsets"),
        (dict(position_offsets=[(1.0, 2.0, math.nan)]), "position_offsets"),
        (dict(position_offsets=[(math.nan, 2.0, 0.01)]), "position_offsets"),
    ],
)
def test_bad_arguments_name_the_argument(arm_plant, kwargs, message):
    arguments = dict(
        frame_name="fingertip", coordinates=PLANAR_COORDINATES, position=0.2, stiffness=5e4
    )
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        CompliantWall(arm_plant, **arguments)


def test_the_wall_reads_x_wherever_the_task_vector_holds_it(arm_plant):
    """A task vector (y, x): the wall reads x and its Jacobian row from their places in the
    kinematics vector, and pushes as on (x, y, theta)."""
    tip = _tip_x(arm_plant, Q)
    planar = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 1e-4,
        stiffness=5e4,
    )
    swapped = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=("y", "x"),
        position=tip - 1e-4,
        stiffness=5e4,
    )
    context = swapped.CreateDefaultContext()
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=("y", "x"))
    swapped.kinematics_input.FixValue(context, kinematics.kinematics(np.r_[Q, 0.0, 0.0, 0.0]))
    expected = _wall_context(arm_plant, planar, Q)
    assert swapped.contact_force_output.Eval(context)[0] == pytest.approx(5.0, rel=1e-9)
    np.testing.assert_array_equal(
        swapped.generalized_force_output.Eval(context),
        planar.generalized_force_output.Eval(expected),
    )


def test_soft_walls_and_steps_are_accepted(arm_plant):
    """Ke > 0, not >= 1: a 0.5 N/m wall (a very soft foam) and a step to it are valid."""
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 0.1,
        stiffness=0.5,
        stiffness_steps=[(1.0, 0.5)],
    )
    force = wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q))[0]
    assert force == pytest.approx(0.05)


def test_position_offsets_hold_during_their_interval_only(arm_plant):
    """Xe(t) + d during [start, end): included at start, not at end (the wall is back)."""
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=0.15,
        stiffness=2e4,
        position_offsets=[(1.0, 2.0, 0.02)],
    )
    for time, position in [(0.5, 0.15), (1.0, 0.17), (1.5, 0.17), (2.0, 0.15), (3.0, 0.15)]:
        assert wall.position_at(time) == pytest.approx(position, abs=1e-15), time
    # A static wall: only the offsets' start and end are discontinuities.
    assert wall.discontinuity_times() == [1.0, 2.0]


def test_a_moving_wall_in_autodiff_is_where_the_float_wall_is(arm_plant):
    """The AutoDiffXd wall reads its schedule at the context's time as a float: the same
    force as the float wall at t = 1 s, halfway through a motion."""
    from pydrake.autodiffutils import AutoDiffXd

    tip = _tip_x(arm_plant, Q)
    arguments = dict(
        position=tip - 2e-3, stiffness=5e4, velocity=1e-3, motion_start=0.5, motion_end=1.5
    )
    wall = CompliantWall(
        arm_plant, frame_name="fingertip", coordinates=PLANAR_COORDINATES, **arguments
    )
    expected = wall.contact_force_output.Eval(_wall_context(arm_plant, wall, Q, 1.0))[0]
    assert expected == pytest.approx(5e4 * (2e-3 - 0.5e-3))
    wall_ad = wall.ToAutoDiffXd()  # a plain Diagram: its ports by name
    context = wall_ad.CreateDefaultContext()
    context.SetTime(AutoDiffXd(1.0))
    kinematics = PlanarFrameKinematics(
        arm_plant, "fingertip", coordinates=PLANAR_COORDINATES
    ).kinematics(np.r_[Q, 0, 0, 0])
    wall_ad.GetInputPort("kinematics").FixValue(context, [AutoDiffXd(k) for k in kinematics])
    force = wall_ad.GetOutputPort("contact_force").Eval(context)[0]
    assert force.value() == pytest.approx(expected, rel=1e-12)


def test_a_wall_that_starts_and_stops_at_once_stays_put(arm_plant):
    """motion_end = motion_start is allowed: the wall never moves."""
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=0.15,
        stiffness=2e4,
        velocity=0.01,
        motion_start=2.0,
        motion_end=2.0,
    )
    assert wall.position_at(5.0) == pytest.approx(0.15, abs=1e-15)


def test_an_approaching_wall_reports_when_it_starts_and_stops(arm_plant):
    """A negative velocity (a wall coming at the arm) moves it too: its start and end are
    discontinuities for the integrator, as for a receding wall."""
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=0.15,
        stiffness=2e4,
        velocity=-0.05,
        motion_start=2.5,
        motion_end=2.7,
    )
    assert wall.discontinuity_times() == [2.5, 2.7]
    assert wall.position_at(3.0) == pytest.approx(0.14, abs=1e-15)


def test_autodiff_wall_does_not_pull_when_out_of_contact(arm_plant):
    """1 mm short of the wall: zero force and zero slope in AutoDiffXd too (the wall is
    unilateral whatever the scalar type)."""
    from pydrake.autodiffutils import AutoDiffXd

    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip + 1e-3,
        stiffness=5e4,
    ).ToAutoDiffXd()
    context = wall.CreateDefaultContext()
    # Every entry of the kinematics input (X, J v, J) with a derivative of its own.
    kinematics = PlanarFrameKinematics(
        arm_plant, "fingertip", coordinates=PLANAR_COORDINATES
    ).kinematics(np.r_[Q, 0, 0, 0])
    size = len(kinematics)
    wall.GetInputPort("kinematics").FixValue(
        context, [AutoDiffXd(k, np.eye(size)[i]) for i, k in enumerate(kinematics)]
    )
    force = wall.GetOutputPort("contact_force").Eval(context)[0]
    assert force.value() == 0.0
    np.testing.assert_array_equal(force.derivatives(), 0.0)


@pytest.mark.parametrize("velocity", [1.0, -1.0])
def test_a_wall_at_a_metre_per_second_moves_too(arm_plant, velocity):
    """Only a wall with zero velocity and no offsets stands still: one at +-1 m/s for 10 ms
    is at Xe = 0.15 + v t while it moves, 0.15 +- 0.01 m after."""
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=0.15,
        stiffness=2e4,
        velocity=velocity,
        motion_end=0.01,
    )
    assert wall.position_at(0.004) == pytest.approx(0.15 + 0.004 * velocity, abs=1e-15)
    assert wall.position_at(1.0) == pytest.approx(0.15 + 0.01 * velocity, abs=1e-15)


def test_the_law_alone_gives_the_force_and_its_generalized_force_in_one_vector(arm_plant):
    """``wall.law`` (``CompliantWallLaw``) outputs [F; -F J_x^T]; it takes its arguments by
    keyword only, as the wall does (position and stiffness are both numbers)."""
    tip = _tip_x(arm_plant, Q)
    wall = CompliantWall(
        arm_plant,
        frame_name="fingertip",
        coordinates=PLANAR_COORDINATES,
        position=tip - 1e-4,
        stiffness=5e4,
    )
    law = wall.law
    context = law.CreateDefaultContext()
    kinematics = PlanarFrameKinematics(arm_plant, "fingertip", coordinates=PLANAR_COORDINATES)
    law.kinematics_input.FixValue(context, kinematics.kinematics(np.r_[Q, 0.0, 0.0, 0.0]))
    output = law.contact_force_and_generalized_force_output.Eval(context)
    # F = 5e4 N/m * 1e-4 m (exact to 1e-11 N, as above); J_x from the kinematics.
    assert output[0] == pytest.approx(5.0, rel=1e-9)
    np.testing.assert_allclose(output[1:], -5.0 * kinematics.jacobian()[0], rtol=1e-9)
    arguments = dict(
        coordinates=PLANAR_COORDINATES,
        stiffness_steps=(),
        velocity=0.0,
        motion_start=0.0,
        motion_end=math.inf,
    )
    with pytest.raises(TypeError):
        CompliantWallLaw(arm_plant, "fingertip", 0.15, 5e4, **arguments, position_offsets=())
