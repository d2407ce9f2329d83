"""Planar task-space kinematics of a frame, taken from a MultibodyPlant (paper eq. 1-2).

The task vector of a planar arm moving in the world x-y plane is X = (x, y, theta): the
position of a frame's origin and its rotation about world z. X = h(q) and the Jacobian
J(q) = dh/dq come from the plant's own kinematics, so another URDF works unchanged:

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

__all__ = [
    "PlanarFrameKinematics",
    "PlanarKinematics",
    "PlanarKinematics_",
    "TASK_SIZE",
    "generate_planar_kinematics",
    "kinematics_size",
    "split_kinematics",
    "wrap_angle",
]

# The size of the task vector X = (x, y, theta).
TASK_SIZE = 3


def wrap_angle(angle):
    """Wraps an angle to [-pi, pi], for float, AutoDiffXd and Expression alike.

    For a float, the IEEE remainder by 2 pi: exact, and the angle itself when it is
    already within [-pi, pi].
    """
    if isinstance(angle, float):
        return math.remainder(angle, 2.0 * math.pi)
    return atan2(np.sin(angle), np.cos(angle))


def kinematics_size(num_velocities: int) -> int:
    """The length of the ``kinematics`` vector: X (3), dX/dt (3) and J (3 x nv)."""
    return 2 * TASK_SIZE + TASK_SIZE * num_velocities


def split_kinematics(values, num_velocities: int):
    """(X, dX/dt, J) from a ``kinematics`` vector [X; dX/dt; J row by row] (numpy views)."""
    values = np.asarray(values)
    return (
        values[:TASK_SIZE],
        values[TASK_SIZE : 2 * TASK_SIZE],
        values[2 * TASK_SIZE :].reshape(TASK_SIZE, num_velocities),
    )


def _check_frame(plant, frame_name: str) -> None:
    if not plant.is_finalized():
        raise ValueError("the plant must be finalized before its kinematics are used")
    if not plant.HasFrameNamed(frame_name):
        raise ValueError(f"the plant has no frame named '{frame_name}'")


class PlanarFrameKinematics:
    """X = (x, y, theta) of a frame and its 3 x nv Jacobian, from a plant's state.

    Holds a private context of ``plant`` (of any scalar type), so it can be used inside a
    LeafSystem's calc without touching the diagram's plant context.
    """

    def __init__(self, plant, frame_name: str) -> None:
        _check_frame(plant, frame_name)
        self.plant = plant
        self.frame_name = frame_name
        self.frame = plant.GetFrameByName(frame_name)
        self.num_positions = plant.num_positions()
        self.num_velocities = plant.num_velocities()
        self._context = plant.CreateDefaultContext()
        self._world = plant.world_frame()
        self._origin = np.zeros(3)

    def set_state(self, state) -> None:
        """Sets the private context's positions and velocities from [q; v]."""
        self.plant.SetPositionsAndVelocities(self._context, state)

    def pose(self):
        """X = (x, y, theta) at the last state set."""
        X_WF = self.plant.CalcRelativeTransform(self._context, self._world, self.frame)
        matrix = X_WF.GetAsMatrix34()  # [R | p], one copy out of the plant
        cos_theta, sin_theta = matrix[0, 0], matrix[1, 0]
        theta = (
            math.atan2(sin_theta, cos_theta)
            if isinstance(cos_theta, float)
            else atan2(sin_theta, cos_theta)
        )
        return np.array([matrix[0, 3], matrix[1, 3], theta])

    def jacobian(self):
        """J (3 x nv): rows d(x, y, theta)/dt per unit generalized velocity."""
        J_spatial = self.plant.CalcJacobianSpatialVelocity(
            self._context,
            JacobianWrtVariable.kV,
            self.frame,
            self._origin,
            self._world,
            self._world,
        )
        # Spatial velocity rows are (wx, wy, wz, vx, vy, vz).
        return J_spatial[[3, 4, 2], :]

    def position(self):
        """The frame's origin in world, p_WF (3,), at the last state set."""
        return self.plant.CalcPointsPositions(self._context, self.frame, self._origin, self._world)[
            :, 0
        ]

    def kinematics(self, state):
        """[X; dX/dt; J row by row] at the state [q; v] (the ``kinematics`` vector)."""
        self.set_state(state)
        jacobian = self.jacobian()
        velocity = jacobian @ np.asarray(state)[self.num_positions :]
        return np.concatenate([self.pose(), velocity, jacobian.reshape(-1)])


def generate_planar_kinematics(plant, frame_name: str) -> Callable:
    """The ``kinematics`` vector of `frame_name` as generated float code.

    The plant's symbolic copy (``plant.ToSymbolic()``) is evaluated at symbolic positions q
    and velocities v through the same calls as ``PlanarFrameKinematics`` (the frame's
    transform, and its spatial-velocity Jacobian with respect to v), and the resulting
    expressions of X, J v and J are compiled by ``compile_expressions``.

    Returns:
        ``function(state) -> tuple`` of ``kinematics_size(nv)`` floats, for a state
        sequence [q; v] of floats.

    Raises:
        ValueError: the plant is not finalized or has no such frame.
        NotImplementedError: the plant's kinematics use an expression with no float code.
    """
    _check_frame(plant, frame_name)
    symbolic = plant.ToSymbolic()
    context = symbolic.CreateDefaultContext()
    q = MakeVectorVariable(plant.num_positions(), "q")
    v = MakeVectorVariable(plant.num_velocities(), "v")
    symbolic.SetPositions(context, q)
    symbolic.SetVelocities(context, v)
    frame = symbolic.GetFrameByName(frame_name)
    world = symbolic.world_frame()
    matrix = symbolic.CalcRelativeTransform(context, world, frame).GetAsMatrix34()
    J_spatial = symbolic.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
    )
    jacobian = J_spatial[[3, 4, 2], :]
    pose = [matrix[0, 3], matrix[1, 3], symbolic_atan2(matrix[1, 0], matrix[0, 0])]
    velocity = [sum(row[j] * v[j] for j in range(len(v))) for row in jacobian]  # J v
    expressions = [*pose, *velocity, *jacobian.reshape(-1)]
    return compile_expressions(expressions, [*q, *v], name=f"{frame_name}_kinematics")


@TemplateSystem.define("PlanarKinematics_", T_list=[float, AutoDiffXd])
def PlanarKinematics_(T):
    class Impl(LeafSystem_[T]):
        """The task-space kinematics of a frame of a plant (paper eq. 1-2).

            X = h(q) = (x, y, theta)      the frame's origin in world x-y, its angle about z
            dX/dt = J(q) v,  J = dh/dq    (3 x nv, with respect to the velocities v)

        output as one vector ``kinematics`` = [X; dX/dt; J row by row], of length
        6 + 3 nv (``split_kinematics`` takes it apart). It is computed once per context and
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
            frame_name: str = "fingertip",
            generated: bool = True,
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] of the arm.
                frame_name: the frame whose motion is output (the fingertip contact point).
                generated: (double only) evaluate generated code; False asks the plant
                    through its bindings on every evaluation (the reference path, slower).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            _check_frame(plant, frame_name)
            self._plant = plant
            self._frame_name = frame_name
            self._generated = bool(generated)
            self._num_positions = plant.num_positions()
            self._num_velocities = plant.num_velocities()
            num_states = self._num_positions + self._num_velocities
            self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", num_states)
            if T is float and self._generated:
                self._function = generate_planar_kinematics(plant, frame_name)
                calc = self._CalcGenerated
            else:
                self._kinematics = PlanarFrameKinematics(plant, frame_name)
                calc = self._CalcFromPlant
            self.kinematics_output = self.DeclareVectorOutputPort(
                "kinematics",
                kinematics_size(self._num_velocities),
                calc,
                prerequisites_of_calc={self.estimated_state_input.ticket()},
            )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                other._plant.ToScalarType[T](),
                frame_name=other._frame_name,
                generated=other._generated,
                converter=converter,
            )

        @property
        def frame_name(self) -> str:
            return self._frame_name

        @property
        def num_velocities(self) -> int:
            return self._num_velocities

        def _not_finite(self, context) -> RuntimeError:
            # Say so here, rather than let the plant or the generated code meet it.
            return RuntimeError(
                f"PlanarKinematics: the arm's state is not finite at t = {context.get_time()} s"
            )

        def _CalcGenerated(self, context, output) -> None:
            state = self.estimated_state_input.Eval(context).tolist()
            if not math.isfinite(sum(state)):  # NaN or infinite when any entry is
                raise self._not_finite(context)
            output.get_mutable_value()[:] = self._function(state)

        def _CalcFromPlant(self, context, output) -> None:
            state = self.estimated_state_input.Eval(context)
            values = state.tolist() if T is float else [x.value() for x in state]
            if not math.isfinite(sum(values)):
                raise self._not_finite(context)
            output.SetFromVector(self._kinematics.kinematics(state))

    return Impl


PlanarKinematics = PlanarKinematics_[None]
