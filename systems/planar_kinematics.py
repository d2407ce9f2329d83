"""Task-space kinematics of a frame, taken from a MultibodyPlant (paper eq. 1-2).

The task vector of a planar arm moving in the world x-y plane is X = (x, y, theta): the
position of a frame's origin and its rotation about world z. A fingertip of a planar hand
is controlled in 2-D: X = (x, y) of its tip in a frame fixed at the face it touches (x
along the face's inward normal). Both are a choice of COORDINATES among the position of a
frame F's origin in a frame E (x, y, z) and F's rotation theta about E's z axis, given at
construction (TASK_COORDINATES; by default (x, y, theta) in world). X = h(q) and the
Jacobian J(q) = dh/dq come from the plant's own kinematics, so another model works
unchanged:

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
    "TASK_COORDINATES",
    "PlanarFrameKinematics",
    "PlanarKinematics",
    "PlanarKinematics_",
    "ROTATION_COORDINATES",
    "TASK_SIZE",
    "generate_planar_kinematics",
    "has_rotation_vector",
    "kinematics_size",
    "split_kinematics",
    "wrap_angle",
]

# The size of the planar arm's task vector X = (x, y, theta).
TASK_SIZE = 3
# The arm's task vector, the default.
PLANAR_COORDINATES = ("x", "y", "theta")
#: The coordinates a task vector may pick: the position of the frame's origin in E, its
#: rotation about E's z axis, or the rotation vector of its orientation in E (all three
#: of rx, ry, rz, never with theta: systems/spatial_kinematics.py computes them).
TASK_COORDINATES = ("x", "y", "z", "theta", "rx", "ry", "rz")
#: The spatial orientation coordinates: the rotation vector of R_EF.
ROTATION_COORDINATES = ("rx", "ry", "rz")
# Their rows in a spatial velocity (wx, wy, wz, vx, vy, vz).
_SPATIAL_ROW = {"x": 3, "y": 4, "z": 5, "theta": 2, "rx": 0, "ry": 1, "rz": 2}


def wrap_angle(angle):
    """Wraps an angle to [-pi, pi], for float, AutoDiffXd and Expression alike.

    For a float, the IEEE remainder by 2 pi: exact, and the angle itself when it is
    already within [-pi, pi].
    """
    if isinstance(angle, float):
        return math.remainder(angle, 2.0 * math.pi)
    return atan2(np.sin(angle), np.cos(angle))


def kinematics_size(num_velocities: int, size: int = TASK_SIZE) -> int:
    """The length of the ``kinematics`` vector: X (m), dX/dt (m) and J (m x nv)."""
    return 2 * size + size * num_velocities


def split_kinematics(values, num_velocities: int, size: int = TASK_SIZE):
    """(X, dX/dt, J) from a ``kinematics`` vector [X; dX/dt; J row by row] (numpy views)."""
    values = np.asarray(values)
    return (
        values[:size],
        values[size : 2 * size],
        values[2 * size :].reshape(size, num_velocities),
    )


def task_coordinates(coordinates) -> tuple[str, ...]:
    """`coordinates` as a tuple; raises ValueError unless distinct TASK_COORDINATES."""
    coordinates = tuple(coordinates)
    if (
        not coordinates
        or len(set(coordinates)) != len(coordinates)
        or any(c not in TASK_COORDINATES for c in coordinates)
    ):
        raise ValueError(
            f"coordinates must be distinct names among {TASK_COORDINATES}, got {coordinates}"
        )
    rotations = [c for c in coordinates if c in ROTATION_COORDINATES]
    if rotations and (len(rotations) != 3 or "theta" in coordinates):
        raise ValueError(
            f"coordinates: the rotation vector needs all of {ROTATION_COORDINATES} and no "
            f"theta, got {coordinates}"
        )
    return coordinates


def has_rotation_vector(coordinates) -> bool:
    """Whether the task vector holds the rotation vector (rx, ry, rz) of the frame."""
    return any(c in ROTATION_COORDINATES for c in coordinates)


def _check_planar(coordinates) -> None:
    if has_rotation_vector(coordinates):
        raise ValueError(
            f"coordinates {coordinates}: the rotation vector is computed by SpatialKinematics "
            "(systems/spatial_kinematics.py), not PlanarKinematics"
        )


def _check_frame(plant, frame_name: str, expressed_in: str = "world") -> None:
    if not plant.is_finalized():
        raise ValueError("the plant must be finalized before its kinematics are used")
    for name in (frame_name, expressed_in):
        if not plant.HasFrameNamed(name):
            raise ValueError(f"the plant has no frame named '{name}'")


def _task_vector(coordinates, matrix, theta) -> list:
    """X from a pose [R | p] (3 x 4) and its angle about z, in the order of `coordinates`."""
    return [theta if c == "theta" else matrix["xyz".index(c), 3] for c in coordinates]


class PlanarFrameKinematics:
    """A task vector X of a frame and its m x nv Jacobian, from a plant's state.

    By default X = (x, y, theta) of the frame in world (the planar arm); ``coordinates``
    picks others among TASK_COORDINATES and ``expressed_in`` the frame E they are measured
    and expressed in (one that does not move, e.g. welded to the world).

    Holds a private context of ``plant`` (of any scalar type), so it can be used inside a
    LeafSystem's calc without touching the diagram's plant context.
    """

    def __init__(
        self,
        plant,
        frame_name: str,
        *,
        coordinates=PLANAR_COORDINATES,
        expressed_in: str = "world",
    ) -> None:
        _check_frame(plant, frame_name, expressed_in)
        self.plant = plant
        self.frame_name = frame_name
        self.frame = plant.GetFrameByName(frame_name)
        self.coordinates = task_coordinates(coordinates)
        self.expressed_in = expressed_in
        self.num_coordinates = len(self.coordinates)
        #: Index of theta in X (None if X has no angle).
        self.angle_index = self.coordinates.index("theta") if "theta" in self.coordinates else None
        self.num_positions = plant.num_positions()
        self.num_velocities = plant.num_velocities()
        self._context = plant.CreateDefaultContext()
        self._world = plant.GetFrameByName(expressed_in)  # E: world for the arm
        self._origin = np.zeros(3)
        self._planar = self.coordinates == PLANAR_COORDINATES
        self._rows = [_SPATIAL_ROW[c] for c in self.coordinates]

    def set_state(self, state) -> None:
        """Sets the private context's positions and velocities from [q; v]."""
        self.plant.SetPositionsAndVelocities(self._context, state)

    @property
    def context(self):
        """The private plant context at the last state set (for M(q), g(q) at that state)."""
        return self._context

    def pose(self):
        """X at the last state set: (x, y, theta) by default."""
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

    def jacobian(self):
        """J (m x nv): rows dX/dt per unit generalized velocity."""
        J_spatial = self.plant.CalcJacobianSpatialVelocity(
            self._context,
            JacobianWrtVariable.kV,
            self.frame,
            self._origin,
            self._world,
            self._world,
        )
        # Spatial velocity rows are (wx, wy, wz, vx, vy, vz).
        return J_spatial[self._rows, :]

    def position(self):
        """The frame's origin in E (world by default), p_EF (3,), at the last state set."""
        return self.plant.CalcPointsPositions(self._context, self.frame, self._origin, self._world)[
            :, 0
        ]

    def kinematics(self, state):
        """[X; dX/dt; J row by row] at the state [q; v] (the ``kinematics`` vector)."""
        self.set_state(state)
        jacobian = self.jacobian()
        velocity = jacobian @ np.asarray(state)[self.num_positions :]
        return np.concatenate([self.pose(), velocity, jacobian.reshape(-1)])


def generate_planar_kinematics(
    plant, frame_name: str, *, coordinates=PLANAR_COORDINATES, expressed_in: str = "world"
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
    _check_frame(plant, frame_name, expressed_in)
    coordinates = task_coordinates(coordinates)
    _check_planar(coordinates)
    symbolic = plant.ToSymbolic()
    context = symbolic.CreateDefaultContext()
    q = MakeVectorVariable(plant.num_positions(), "q")
    v = MakeVectorVariable(plant.num_velocities(), "v")
    symbolic.SetPositions(context, q)
    symbolic.SetVelocities(context, v)
    frame = symbolic.GetFrameByName(frame_name)
    world = symbolic.GetFrameByName(expressed_in)  # E: world for the arm
    matrix = symbolic.CalcRelativeTransform(context, world, frame).GetAsMatrix34()
    J_spatial = symbolic.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
    )
    jacobian = J_spatial[[_SPATIAL_ROW[c] for c in coordinates], :]
    theta = symbolic_atan2(matrix[1, 0], matrix[0, 0]) if "theta" in coordinates else None
    pose = _task_vector(coordinates, matrix, theta)
    velocity = [sum(row[j] * v[j] for j in range(len(v))) for row in jacobian]  # J v
    expressions = [*pose, *velocity, *jacobian.reshape(-1)]
    return compile_expressions(expressions, [*q, *v], name=f"{frame_name}_kinematics")


@TemplateSystem.define("PlanarKinematics_", T_list=[float, AutoDiffXd])
def PlanarKinematics_(T):
    class Impl(LeafSystem_[T]):
        """The task-space kinematics of a frame of a plant (paper eq. 1-2).

            X = h(q) = (x, y, theta)      the frame's origin in world x-y, its angle about z
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
            frame_name: str = "fingertip",
            generated: bool = True,
            coordinates=PLANAR_COORDINATES,
            expressed_in: str = "world",
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] (the arm, or a hand with its object).
                frame_name: the frame whose motion is output (the fingertip contact point).
                generated: (double only) evaluate generated code; False asks the plant
                    through its bindings on every evaluation (the reference path, slower).
                coordinates: the task vector X, names among TASK_COORDINATES.
                expressed_in: the frame X is measured and expressed in (fixed in world).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            _check_frame(plant, frame_name, expressed_in)
            self._plant = plant
            self._frame_name = frame_name
            self._coordinates = task_coordinates(coordinates)
            _check_planar(self._coordinates)
            self._expressed_in = expressed_in
            self._generated = bool(generated)
            self._num_positions = plant.num_positions()
            self._num_velocities = plant.num_velocities()
            num_states = self._num_positions + self._num_velocities
            self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", num_states)
            task = dict(coordinates=self._coordinates, expressed_in=expressed_in)
            if T is float and self._generated:
                self._function = generate_planar_kinematics(plant, frame_name, **task)
                calc = self._CalcGenerated
            else:
                self._kinematics = PlanarFrameKinematics(plant, frame_name, **task)
                calc = self._CalcFromPlant
            self.kinematics_output = self.DeclareVectorOutputPort(
                "kinematics",
                kinematics_size(self._num_velocities, len(self._coordinates)),
                calc,
                prerequisites_of_calc={self.estimated_state_input.ticket()},
            )

        def _construct_copy(self, other, converter=None) -> None:
            type(self)._construct(  # this class's, or a subclass's (SpatialKinematics)
                self,
                other._plant.ToScalarType[T](),
                frame_name=other._frame_name,
                generated=other._generated,
                coordinates=other._coordinates,
                expressed_in=other._expressed_in,
                converter=converter,
            )

        @property
        def frame_name(self) -> str:
            return self._frame_name

        @property
        def num_velocities(self) -> int:
            return self._num_velocities

        @property
        def coordinates(self) -> tuple[str, ...]:
            """The task coordinates, in the order of X."""
            return self._coordinates

        def _not_finite(self, context) -> RuntimeError:
            # Say so here, rather than let the plant or the generated code meet it.
            return RuntimeError(
                f"PlanarKinematics: the arm's state is not finite at t = {context.get_time()} s"
            )

        def _CalcGenerated(self, context, output) -> None:
            state = self.estimated_state_input.Eval(context).tolist()
            if not math.isfinite(sum(state)):  # NaN or infinite when any entry is
                raise self._not_finite(context)
            output.SetFromVector(self._function(state))

        def _CalcFromPlant(self, context, output) -> None:
            state = self.estimated_state_input.Eval(context)
            values = state.tolist() if T is float else [x.value() for x in state]
            if not math.isfinite(sum(values)):
                raise self._not_finite(context)
            output.SetFromVector(self._kinematics.kinematics(state))

    return Impl


PlanarKinematics = PlanarKinematics_[None]
