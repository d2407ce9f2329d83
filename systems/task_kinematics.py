"""Task-space kinematics of a frame, taken from a MultibodyPlant (paper eq. 1-2).

The paper writes its loop for a task vector X in R^m of any serial arm. Here X is a
choice of COORDINATES of a frame F among the position of F's origin in a frame E (x, y,
z), F's rotation theta about E's z axis, and the rotation vector (rx, ry, rz) of F's
orientation in E (TASK_COORDINATES), given at construction with E (``expressed_in``, a
frame that does not move, e.g. welded to the world). X = h(q) and the Jacobian
J(q) = dh/dq come from the plant's own kinematics, so any model works unchanged. What
the planar kinematics (x, y, z, theta: systems/planar_kinematics.py) and the spatial
kinematics (the rotation vector: systems/spatial_kinematics.py) share is here:

* the vocabulary of task coordinates and the layout of the ``kinematics`` vector
  [X; dX/dt; J row by row] (``kinematics_size``, ``split_kinematics``);
* ``TaskFrameKinematics``, the frame helper: a private context of the plant (any scalar
  type), J and dX/dt = J v, from which each kind computes its own X (``pose``);
* ``TaskKinematics``, what the two LeafSystems share: the ``estimated_state`` input, the
  ``kinematics`` output computed once per context, and their accessors.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import atan2
from pydrake.multibody.tree import JacobianWrtVariable

__all__ = [
    "ROTATION_COORDINATES",
    "TASK_COORDINATES",
    "TaskFrameKinematics",
    "TaskKinematics",
    "check_frame",
    "has_rotation_vector",
    "jacobian_rows",
    "kinematics_size",
    "split_kinematics",
    "task_coordinates",
    "wrap_angle",
]

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


def kinematics_size(num_velocities: int, size: int) -> int:
    """The length of the ``kinematics`` vector: X (m = `size`), dX/dt (m) and J (m x nv)."""
    return 2 * size + size * num_velocities


def split_kinematics(values, num_velocities: int, size: int):
    """(X, dX/dt, J) from a ``kinematics`` vector [X; dX/dt; J row by row] (numpy views),
    m = `size` coordinates."""
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


def jacobian_rows(coordinates) -> list[int]:
    """The rows of a spatial-velocity Jacobian (wx, wy, wz, vx, vy, vz) that are the rates
    of `coordinates`, in their order (theta's and rz's: wz)."""
    return [_SPATIAL_ROW[c] for c in coordinates]


def check_frame(plant, frame_name: str, expressed_in: str) -> None:
    """Raises ValueError unless `plant` is finalized and has both frames."""
    if not plant.is_finalized():
        raise ValueError("the plant must be finalized before its kinematics are used")
    for name in (frame_name, expressed_in):
        if not plant.HasFrameNamed(name):
            raise ValueError(f"the plant has no frame named '{name}'")


class TaskFrameKinematics:
    """A task vector X of a frame and its m x nv Jacobian, from a plant's state.

    ``coordinates`` picks X among TASK_COORDINATES and ``expressed_in`` the frame E it is
    measured and expressed in (one that does not move, e.g. welded to the world). A
    subclass computes X itself (``pose``): ``PlanarFrameKinematics`` (x, y, z, theta),
    ``SpatialFrameKinematics`` (and the rotation vector).

    Holds a private context of ``plant`` (of any scalar type), so it can be used inside a
    LeafSystem's calc without touching the diagram's plant context.
    """

    def __init__(self, plant, frame_name: str, *, coordinates, expressed_in: str = "world") -> None:
        check_frame(plant, frame_name, expressed_in)
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
        self._world = plant.GetFrameByName(expressed_in)  # E
        self._origin = np.zeros(3)
        self._rows = jacobian_rows(self.coordinates)

    def set_state(self, state) -> None:
        """Sets the private context's positions and velocities from [q; v]."""
        self.plant.SetPositionsAndVelocities(self._context, state)

    @property
    def context(self):
        """The private plant context at the last state set (for M(q), g(q) at that state)."""
        return self._context

    def pose(self):
        """X at the last state set (the subclass's)."""
        raise NotImplementedError(f"{type(self).__name__} computes no task vector")

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
        """The frame's origin in E, p_EF (3,), at the last state set."""
        return self.plant.CalcPointsPositions(self._context, self.frame, self._origin, self._world)[
            :, 0
        ]

    def kinematics(self, state):
        """[X; dX/dt; J row by row] at the state [q; v] (the ``kinematics`` vector)."""
        self.set_state(state)
        jacobian = self.jacobian()
        velocity = jacobian @ np.asarray(state)[self.num_positions :]
        return np.concatenate([self.pose(), velocity, jacobian.reshape(-1)])


class TaskKinematics:
    """What the task-kinematics LeafSystems share (``PlanarKinematics_[T]``,
    ``SpatialKinematics_[T]``, whose scalar type is ``_T``): the ``estimated_state``
    input, the ``kinematics`` output [X; dX/dt; J row by row] of length 2 m + m nv
    (``split_kinematics`` takes it apart), computed once per context for every system
    that needs the frame's motion, and their accessors. A state that is not finite is
    reported here, before any kinematics (and before the plant) sees it.

    A subclass's ``_construct`` initializes its LeafSystem, checks its task, and calls
    ``_declare_kinematics`` with the calc of its output.
    """

    def _declare_kinematics(
        self, plant, *, frame_name: str, coordinates, expressed_in: str, generated: bool, calc
    ) -> None:
        """Keeps the task and declares the ports; `calc` computes the output (None:
        ``_CalcFromPlant``, which needs ``self._kinematics``)."""
        self._plant = plant
        self._frame_name = frame_name
        self._coordinates = coordinates
        self._expressed_in = expressed_in
        self._generated = bool(generated)
        self._num_positions = plant.num_positions()
        self._num_velocities = plant.num_velocities()
        num_states = self._num_positions + self._num_velocities
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", num_states)
        self.kinematics_output = self.DeclareVectorOutputPort(
            "kinematics",
            kinematics_size(self._num_velocities, len(self._coordinates)),
            self._CalcFromPlant if calc is None else calc,
            prerequisites_of_calc={self.estimated_state_input.ticket()},
        )

    def _copy_arguments(self) -> dict:
        """The construction's keyword arguments, for a copy of another scalar type."""
        return dict(
            frame_name=self._frame_name,
            generated=self._generated,
            coordinates=self._coordinates,
            expressed_in=self._expressed_in,
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

    def _CalcFromPlant(self, context, output) -> None:
        state = self.estimated_state_input.Eval(context)
        values = state.tolist() if self._T is float else [x.value() for x in state]
        if not math.isfinite(sum(values)):
            raise self._not_finite(context)
        output.SetFromVector(self._kinematics.kinematics(state))
