"""Planar task-space kinematics of a frame: its position and its angle about z (paper eq. 1-2).

The task vector of a frame F moving in a plane is X = (x, y, theta) (PLANAR_COORDINATES):
the position of F's origin in a frame E and F's rotation theta about E's z axis. Any of
x, y, z and theta may be picked, in any frame E that does not move (a fingertip
controlled in 2-D: X = (x, y) of its tip in a frame fixed at the face it touches, x along
the face's inward normal). The vocabulary of the coordinates, the frame helper's base and
the system's are systems/task_kinematics.py's; X = h(q) and J(q) = dh/dq come from the
plant's own kinematics, so another model works unchanged:

* ``PlanarFrameKinematics`` asks the plant (any scalar type) through a private context;
* ``generate_planar_kinematics`` takes the same quantities once from the plant's symbolic
  model (``plant.ToSymbolic()``) and compiles them into plain float code
  (systems/expression_code.py), about ten times cheaper per evaluation;
* ``PlanarKinematics`` is the LeafSystem that computes them once per context for the
  systems that need them (the Cartesian PID and the wall): generated code for double,
  the plant itself for AutoDiffXd, so that Linearize differentiates the plant's own
  kinematics.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import atan2
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.symbolic import MakeVectorVariable
from pydrake.symbolic import atan2 as symbolic_atan2
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.expression_code import compile_expressions
from admittance.systems.task_kinematics import (
    TaskFrameKinematics,
    TaskKinematics,
    check_frame,
    has_rotation_vector,
    jacobian_rows,
    task_coordinates,
)

__all__ = [
    "PLANAR_COORDINATES",
    "PlanarFrameKinematics",
    "PlanarKinematics",
    "PlanarKinematics_",
    "generate_planar_kinematics",
]

#: The planar task vector: the frame's origin in the x-y plane of E and its angle about z.
PLANAR_COORDINATES = ("x", "y", "theta")


def _check_planar(coordinates) -> None:
    if has_rotation_vector(coordinates):
        raise ValueError(
            f"coordinates {coordinates}: the rotation vector is computed by SpatialKinematics "
            "(systems/spatial_kinematics.py), not PlanarKinematics"
        )


def _task_vector(coordinates, matrix, theta) -> list:
    """X from a pose [R | p] (3 x 4) and its angle about z, in the order of `coordinates`."""
    return [theta if c == "theta" else matrix["xyz".index(c), 3] for c in coordinates]


class PlanarFrameKinematics(TaskFrameKinematics):
    """A planar task vector X of a frame and its m x nv Jacobian, from a plant's state.

    X picks ``coordinates`` among x, y, z and theta of the frame in ``expressed_in``
    (TaskFrameKinematics); (x, y, theta), PLANAR_COORDINATES, is read in one step.
    """

    def __init__(self, plant, frame_name: str, *, coordinates, expressed_in: str = "world") -> None:
        super().__init__(plant, frame_name, coordinates=coordinates, expressed_in=expressed_in)
        self._planar = self.coordinates == PLANAR_COORDINATES

    def pose(self):
        """X at the last state set: the origin's coordinates and the angle about z."""
        X_WF = self.plant.CalcRelativeTransform(self._context, self._world, self.frame)
        matrix = X_WF.GetAsMatrix34()  # [R | p], one copy out of the plant
        cos_theta, sin_theta = matrix[0, 0], matrix[1, 0]
        theta = (
            math.atan2(sin_theta, cos_theta)
            if isinstance(cos_theta, float)
            else atan2(sin_theta, cos_theta)
        )
        if self._planar:
            return np.array([matrix[0, 3], matrix[1, 3], theta])
        return np.array(_task_vector(self.coordinates, matrix, theta))


def generate_planar_kinematics(
    plant, frame_name: str, *, coordinates, expressed_in: str = "world"
) -> Callable:
    """The ``kinematics`` vector of `frame_name` as generated float code.

    The plant's symbolic copy (``plant.ToSymbolic()``) is evaluated at symbolic positions q
    and velocities v through the same calls as ``PlanarFrameKinematics`` (the frame's
    transform, and its spatial-velocity Jacobian with respect to v), and the resulting
    expressions of X, J v and J are compiled by ``compile_expressions``.

    Returns:
        ``function(state) -> tuple`` of ``kinematics_size(nv, m)`` floats, for a state
        sequence [q; v] of floats.

    Raises:
        ValueError: the plant is not finalized or has no such frame.
        NotImplementedError: the plant's kinematics use an expression with no float code.
    """
    check_frame(plant, frame_name, expressed_in)
    coordinates = task_coordinates(coordinates)
    _check_planar(coordinates)
    symbolic = plant.ToSymbolic()
    context = symbolic.CreateDefaultContext()
    q = MakeVectorVariable(plant.num_positions(), "q")
    v = MakeVectorVariable(plant.num_velocities(), "v")
    symbolic.SetPositions(context, q)
    symbolic.SetVelocities(context, v)
    frame = symbolic.GetFrameByName(frame_name)
    world = symbolic.GetFrameByName(expressed_in)  # E
    matrix = symbolic.CalcRelativeTransform(context, world, frame).GetAsMatrix34()
    J_spatial = symbolic.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
    )
    jacobian = J_spatial[jacobian_rows(coordinates), :]
    theta = symbolic_atan2(matrix[1, 0], matrix[0, 0]) if "theta" in coordinates else None
    pose = _task_vector(coordinates, matrix, theta)
    velocity = [sum(row[j] * v[j] for j in range(len(v))) for row in jacobian]  # J v
    expressions = [*pose, *velocity, *jacobian.reshape(-1)]
    return compile_expressions(expressions, [*q, *v], name=f"{frame_name}_kinematics")


class _PlanarKinematics(TaskKinematics):
    """The planar task-space kinematics of a frame of a plant (paper eq. 1-2).

        X = h(q) = (x, y, theta)      the frame's origin in E's x-y plane, its angle about z
        dX/dt = J(q) v,  J = dh/dq    (m x nv, with respect to the velocities v)

    or the other ``coordinates`` of the frame in the frame ``expressed_in``, output as
    one vector ``kinematics`` = [X; dX/dt; J row by row], of length 2 m + m nv
    (``split_kinematics`` takes it apart). It is computed once per context and
    read by every system that needs the frame's motion (the Cartesian PID, the wall).

    For double the values come from float code generated from the plant's symbolic
    model when the system is built (``generate_planar_kinematics``), for AutoDiffXd
    from the plant itself (``PlanarFrameKinematics``), so that linearizing the loop
    differentiates the plant's own kinematics. A state that is not finite is reported
    here, before any kinematics (and before the plant) sees it.

    .. pydrake_system::

        name: PlanarKinematics
        input_ports:
        - estimated_state
        output_ports:
        - kinematics
    """

    def _construct(
        self,
        plant,
        *,
        frame_name: str,
        coordinates,
        generated: bool = True,
        expressed_in: str = "world",
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] (an arm, or a hand with its object).
            frame_name: the frame whose motion is output (the contact point's).
            coordinates: the task vector X, names among TASK_COORDINATES (no rotation
                vector: SpatialKinematics).
            generated: (double only) evaluate generated code; False asks the plant
                through its bindings on every evaluation (the reference path, slower).
            expressed_in: the frame X is measured and expressed in (fixed in world).
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        check_frame(plant, frame_name, expressed_in)
        coordinates = task_coordinates(coordinates)
        _check_planar(coordinates)
        task = dict(coordinates=coordinates, expressed_in=expressed_in)
        calc = None  # the plant's, TaskKinematics._CalcFromPlant
        if self._T is float and bool(generated):
            self._function = generate_planar_kinematics(plant, frame_name, **task)
            calc = self._CalcGenerated
        else:
            self._kinematics = PlanarFrameKinematics(plant, frame_name, **task)
        self._declare_kinematics(
            plant, frame_name=frame_name, generated=generated, calc=calc, **task
        )

    def _construct_copy(self, other, converter=None) -> None:
        _PlanarKinematics._construct(
            self,
            other._plant.ToScalarType[self._T](),
            converter=converter,
            **other._copy_arguments(),
        )

    def _CalcGenerated(self, context, output) -> None:
        state = self.estimated_state_input.Eval(context).tolist()
        if not math.isfinite(sum(state)):  # NaN or infinite when any entry is
            raise self._not_finite(context)
        output.SetFromVector(self._function(state))


@TemplateSystem.define("PlanarKinematics_", T_list=[float, AutoDiffXd])
def PlanarKinematics_(T):
    class Impl(_PlanarKinematics, LeafSystem_[T]):
        __doc__ = _PlanarKinematics.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _PlanarKinematics._construct
        _construct_copy = _PlanarKinematics._construct_copy

    return Impl


PlanarKinematics = PlanarKinematics_[None]
