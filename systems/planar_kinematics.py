"""Task-space kinematics of a frame, taken from a MultibodyPlant (paper eq. 1-2).

The task vector of a planar arm moving in the world x-y plane is X = (x, y, theta): the
position of a frame's origin and its rotation about world z. A fingertip of a planar hand
is controlled in 2-D: X = (x, y), the position of its tip in a frame fixed at the face it
touches (x along the face's inward normal). Both are a choice of coordinates among the
position p_EF of a frame F's origin in a frame E, and F's rotation theta about E's z axis.
X = h(q) and the Jacobian J(q) = dh/dq come from the plant's own kinematics, so another
model works unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import atan2
from pydrake.multibody.tree import JacobianWrtVariable

__all__ = ["TASK_COORDINATES", "PlanarFrameKinematics", "wrap_angle"]

#: The coordinates a task vector may pick: the position of the frame's origin in E and
#: its rotation about E's z axis.
TASK_COORDINATES = ("x", "y", "z", "theta")
# Their rows in a spatial velocity (wx, wy, wz, vx, vy, vz).
_SPATIAL_ROW = {"x": 3, "y": 4, "z": 5, "theta": 2}


def wrap_angle(angle):
    """Wraps an angle to (-pi, pi], for float, AutoDiffXd and Expression alike."""
    if isinstance(angle, float):
        return math.atan2(math.sin(angle), math.cos(angle))
    return atan2(np.sin(angle), np.cos(angle))


class PlanarFrameKinematics:
    """A task vector X of a frame and its m x nv Jacobian, from a plant's state.

    By default X = (x, y, theta) of the frame in world (the planar arm). ``coordinates``
    picks others among TASK_COORDINATES and ``expressed_in`` the frame E they are measured
    and expressed in (a frame that does not move, e.g. one welded to the world).

    Holds a private context of ``plant`` (of any scalar type), so it can be used inside a
    LeafSystem's calc without touching the diagram's plant context.
    """

    def __init__(
        self,
        plant,
        frame_name: str,
        *,
        coordinates: tuple[str, ...] = ("x", "y", "theta"),
        expressed_in: str = "world",
    ) -> None:
        if not plant.is_finalized():
            raise ValueError("the plant must be finalized before its kinematics are used")
        for name in (frame_name, expressed_in):
            if not plant.HasFrameNamed(name):
                raise ValueError(f"the plant has no frame named '{name}'")
        coordinates = tuple(coordinates)
        if (
            not coordinates
            or len(set(coordinates)) != len(coordinates)
            or any(c not in TASK_COORDINATES for c in coordinates)
        ):
            raise ValueError(
                f"coordinates must be distinct names among {TASK_COORDINATES}, got {coordinates}"
            )
        self.plant = plant
        self.frame_name = frame_name
        self.frame = plant.GetFrameByName(frame_name)
        self.coordinates = coordinates
        self.num_coordinates = len(coordinates)
        #: Index of theta in X (None if X has no angle).
        self.angle_index = coordinates.index("theta") if "theta" in coordinates else None
        self.num_positions = plant.num_positions()
        self.num_velocities = plant.num_velocities()
        self._context = plant.CreateDefaultContext()
        self._frame_E = plant.GetFrameByName(expressed_in)
        self._origin = np.zeros(3)
        self._planar = coordinates == ("x", "y", "theta")
        self._rows = [_SPATIAL_ROW[c] for c in coordinates]

    def set_state(self, state) -> None:
        """Sets the private context's positions and velocities from [q; v]."""
        self.plant.SetPositionsAndVelocities(self._context, state)

    def pose(self):
        """X at the last state set: (x, y, theta) by default."""
        X_WF = self.plant.CalcRelativeTransform(self._context, self._frame_E, self.frame)
        matrix = X_WF.GetAsMatrix34()  # [R | p], one copy out of the plant
        if not self._planar and self.angle_index is None:
            return np.array([matrix["xyz".index(c), 3] for c in self.coordinates])
        cos_theta, sin_theta = matrix[0, 0], matrix[1, 0]
        theta = (
            math.atan2(sin_theta, cos_theta)
            if isinstance(cos_theta, float)
            else atan2(sin_theta, cos_theta)
        )
        if self._planar:
            return np.array([matrix[0, 3], matrix[1, 3], theta])
        return np.array(
            [theta if c == "theta" else matrix["xyz".index(c), 3] for c in self.coordinates]
        )

    def jacobian(self):
        """J (m x nv): rows dX/dt per unit generalized velocity."""
        J_spatial = self.plant.CalcJacobianSpatialVelocity(
            self._context,
            JacobianWrtVariable.kV,
            self.frame,
            self._origin,
            self._frame_E,
            self._frame_E,
        )
        # Spatial velocity rows are (wx, wy, wz, vx, vy, vz).
        return J_spatial[self._rows, :]

    def position(self):
        """The frame's origin in E, p_EF (3,), at the last state set."""
        return self.plant.CalcPointsPositions(
            self._context, self.frame, self._origin, self._frame_E
        )[:, 0]
