"""Planar task-space kinematics of a frame, taken from a MultibodyPlant (paper eq. 1-2).

The task vector of a planar arm moving in the world x-y plane is X = (x, y, theta): the
position of a frame's origin and its rotation about world z. Both X = h(q) and the Jacobian
J(q) = dh/dq come from the plant's own kinematics, so another URDF works unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import atan2
from pydrake.multibody.tree import JacobianWrtVariable

__all__ = ["PlanarFrameKinematics", "wrap_angle"]


def wrap_angle(angle):
    """Wraps an angle to (-pi, pi], for float, AutoDiffXd and Expression alike."""
    if isinstance(angle, float):
        return math.atan2(math.sin(angle), math.cos(angle))
    return atan2(np.sin(angle), np.cos(angle))


class PlanarFrameKinematics:
    """X = (x, y, theta) of a frame and its 3 x nv Jacobian, from a plant's state.

    Holds a private context of ``plant`` (of any scalar type), so it can be used inside a
    LeafSystem's calc without touching the diagram's plant context.
    """

    def __init__(self, plant, frame_name: str) -> None:
        if not plant.is_finalized():
            raise ValueError("the plant must be finalized before its kinematics are used")
        if not plant.HasFrameNamed(frame_name):
            raise ValueError(f"the plant has no frame named '{frame_name}'")
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
