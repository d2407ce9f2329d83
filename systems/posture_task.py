"""The joint-space terms a robot's torque interface adds to a Cartesian PID.

A real arm's torque interface (Franka's, a UR's) compensates gravity from its model, and a
redundant arm (n > m joints, the Panda's seven for a 6-D task) needs its spare motion
held, or the joints drift in the null space of J. Both are added to the PID's
tau = J^T F_PID (paper eq. 16) before the effort limits:

    tau += -tau_g(q)                                           gravity compensation
    tau += (I - J^T Jbar^T) (Kq (q0 - q) - Dq v)               posture in the null space

tau_g is Drake's ``CalcGravityGeneralizedForces``: the generalized force OF gravity on
the arm (M dv/dt + C v = tau + tau_g), so the motors cancel it with -tau_g = g(q).

Jbar is the dynamically consistent generalized inverse of J (Khatib, "A unified approach
for motion and force control of robot manipulators: the operational space formulation",
IEEE J. Robotics and Automation, 1987):

    Jbar = M^-1 J^T Lambda,   Lambda = (J M^-1 J^T + eps I)^-1

With eps = 0 the projected torque N^T tau0 = tau0 - J^T Lambda J M^-1 tau0 gives
J M^-1 N^T tau0 = 0: it produces no acceleration of the task coordinates at all, so the
posture pulls the elbow without pushing the tool, whatever the arm's inertia (a plain
pseudo-inverse J^+ = J^T (J J^T)^-1 projects in the Euclidean metric and leaves a
coupling J M^-1 N^T tau0 != 0 through the off-diagonal inertia). eps, a millionth of
the mean diagonal of J M^-1 J^T, only keeps Lambda finite at a singular J, where the
task loses a direction and the projection must stay bounded.

The terms read the plant's state [q; v]; they are computed from the plant itself, for
float and AutoDiffXd alike (so Linearize differentiates them).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.math import inv

__all__ = ["JointSpaceTorque", "PostureTask"]


@dataclass
class PostureTask:
    """Joint-space stiffness and damping toward a rest posture, in the null space of J."""

    # The rest posture q0, rad (one value per position of the plant).
    q0: Sequence[float]
    # Joint stiffness Kq, N m/rad (a value, or one per joint).
    kp: float | Sequence[float] = 10.0
    # Joint damping Dq, N m s/rad (a value, or one per joint).
    kd: float | Sequence[float] = 2.0


# eps of Lambda = (J M^-1 J^T + eps I)^-1, relative to the mean diagonal of J M^-1 J^T.
_RELATIVE_DAMPING = 1e-6


def _per_joint(name: str, value, size: int) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    if not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError(f"posture.{name} must be finite and >= 0, got {array.tolist()}")
    return array


class JointSpaceTorque:
    """-tau_g(q) and the null-space posture torque, as generalized forces (nv).

    Holds a private context of `plant` (of any scalar type).
    """

    def __init__(
        self, plant, *, gravity_compensation: bool, posture: PostureTask | None = None
    ) -> None:
        self.plant = plant
        self.gravity_compensation = bool(gravity_compensation)
        self.posture = posture
        self._num_positions = plant.num_positions()
        self._num_velocities = plant.num_velocities()
        if posture is not None:
            if self._num_positions != self._num_velocities:
                raise ValueError(
                    "posture: the null-space posture needs q and v of one size (revolute and "
                    f"prismatic joints); the plant has {self._num_positions} positions and "
                    f"{self._num_velocities} velocities"
                )
            q0 = np.asarray(posture.q0, dtype=float).reshape(-1)
            if q0.shape != (self._num_positions,) or not np.all(np.isfinite(q0)):
                raise ValueError(
                    f"posture.q0 must be {self._num_positions} finite joint positions, "
                    f"got {q0.tolist()}"
                )
            self._q0 = q0
            self._kp = _per_joint("kp", posture.kp, self._num_velocities)
            self._kd = _per_joint("kd", posture.kd, self._num_velocities)
        self._context = plant.CreateDefaultContext()

    @property
    def active(self) -> bool:
        """Whether any term is on (the PID then reads the plant's state)."""
        return self.gravity_compensation or self.posture is not None

    def torque(self, state, jacobian) -> np.ndarray:
        """The generalized force (nv) at the state [q; v], for a task Jacobian (m x nv)."""
        plant, context = self.plant, self._context
        state = np.asarray(state)
        plant.SetPositionsAndVelocities(context, state)
        if self.gravity_compensation:
            torque = -plant.CalcGravityGeneralizedForces(context)
        else:
            torque = np.zeros(self._num_velocities)
        if self.posture is None:
            return torque
        q, v = state[: self._num_positions], state[self._num_positions :]
        rest = self._kp * (self._q0 - q) - self._kd * v  # tau0
        mass = plant.CalcMassMatrix(context)
        jacobian = np.asarray(jacobian)
        size = jacobian.shape[0]
        if state.dtype != object:  # one solve for M^-1 [J^T, tau0], one for Lambda
            columns = np.empty((self._num_velocities, size + 1))
            columns[:, :size] = jacobian.T
            columns[:, size] = rest
            solved = np.linalg.solve(mass, columns)
            inertia = jacobian @ solved[:, :size]  # J M^-1 J^T, the inverse of Lambda
            inertia.flat[:: size + 1] += _RELATIVE_DAMPING / size * inertia.trace()
            force = np.linalg.solve(inertia, jacobian @ solved[:, size])
        else:
            inverse_mass = inv(mass)
            inertia = jacobian @ inverse_mass @ jacobian.T
            trace = sum(inertia[i, i].value() for i in range(size))
            damped = inertia + _RELATIVE_DAMPING * trace / size * np.eye(size)
            force = inv(damped) @ (jacobian @ (inverse_mass @ rest))  # Lambda J M^-1 tau0
        return torque + rest - jacobian.T @ force  # + (I - J^T Jbar^T) tau0
