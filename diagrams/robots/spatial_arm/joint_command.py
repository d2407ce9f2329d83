"""Position mode's step from the commanded pose to joint positions, and the stiffness the
robot's joint controller gives the tool.

In position mode the robot's own joint controller tracks the commanded joint positions
(the Panda's position interface; the station's joint PD, ``interface.CommandWatchdog``).
The controller turns the commanded pose Xc = Xd + Xr of the tool tip (x, y, z and the
rotation vector, in the control frame) into joint positions by a damped least-squares
differential inverse kinematics on the joint positions it commanded last (not the measured
ones: the commanded pose, not the pressed one, is what the joints are asked to reach):

    dq = J^T (J J^T + lambda^2 I)^-1 (Xc - X(q_c)) + (I - J^+ J) g (q0 - q_c)
    q_c <- clip(q_c + dq, the joint limits less a margin)

with J the tool tip's 6 x 7 Jacobian at q_c, J^+ the damped pseudo-inverse, and the
posture q0 (the start) pulled in J's null space (the Panda's seventh joint).

The law's K (eq. 10: the stiffness of the inner position loop) is then the joint
controller's stiffness seen at the tool along the control frame's z: a force F along z at
the tip deflects the joints by K_q^-1 J^T F, the tip by J K_q^-1 J^T F, so
K = 1 / (J K_q^-1 J^T)_zz (the other axes free of force).
"""

from __future__ import annotations

import numpy as np

from admittance.diagrams.robots.spatial_arm.plant import NORMAL_AXIS
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES
from admittance.systems.spatial_kinematics import SpatialFrameKinematics

__all__ = ["DifferentialIk", "tool_stiffness"]

# Damping of the least squares, in the pose's units (m, rad): small beside the steps.
DAMPING = 1e-3
# The posture's pull per sample in the null space (a fraction of the posture error).
POSTURE_GAIN = 0.01
# The commanded joints stay this far inside the joint limits, rad.
LIMIT_MARGIN = 0.02


def tool_stiffness(jacobian, joint_stiffness) -> float:
    """K = 1 / (J K_q^-1 J^T)_zz: the joints' stiffness K_q (one per joint) seen at the
    tool along the control frame's z, N/m (`jacobian`: the tip's 6 x n Jacobian, rows x,
    y, z, rx, ry, rz)."""
    row = np.asarray(jacobian, dtype=float)[NORMAL_AXIS]
    return float(1.0 / np.sum(row * row / np.asarray(joint_stiffness, dtype=float)))


class DifferentialIk:
    """The module docstring's step on `plant` for the frame `frame_name` in `expressed_in`."""

    def __init__(self, plant, frame_name: str, expressed_in: str, posture) -> None:
        self._kinematics = SpatialFrameKinematics(
            plant, frame_name, coordinates=SPATIAL_COORDINATES, expressed_in=expressed_in
        )
        self.posture = np.asarray(posture, dtype=float)
        self._low = plant.GetPositionLowerLimits() + LIMIT_MARGIN
        self._high = plant.GetPositionUpperLimits() - LIMIT_MARGIN
        self._zero = np.zeros(plant.num_velocities())
        self.positions = self.posture.copy()

    def reset(self, positions) -> None:
        """Starts from `positions` (the measured joints at the first status)."""
        self.positions = np.clip(np.asarray(positions, dtype=float), self._low, self._high)

    def pose_and_jacobian(self, positions) -> tuple[np.ndarray, np.ndarray]:
        """X (x, y, z, rx, ry, rz) and J at `positions`."""
        self._kinematics.set_state(np.concatenate([positions, self._zero]))
        return self._kinematics.pose(), np.asarray(self._kinematics.jacobian(), dtype=float)

    def step(self, commanded_pose) -> np.ndarray:
        """One step towards `commanded_pose`; returns the joint positions to command."""
        q = self.positions
        pose, J = self.pose_and_jacobian(q)
        error = np.asarray(commanded_pose, dtype=float) - pose
        inverse = J.T @ np.linalg.inv(J @ J.T + DAMPING**2 * np.eye(J.shape[0]))
        null = np.eye(q.size) - inverse @ J
        dq = inverse @ error + null @ (POSTURE_GAIN * (self.posture - q))
        self.positions = np.clip(q + dq, self._low, self._high)
        return self.positions.copy()
