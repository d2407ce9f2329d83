"""The controller process's law: the paper's optimal admittance (eq. 10, corrected sign) in
its sampled, incremental form along the press axis, around a 6-D Cartesian PD on the tool's
tip, computed on plain floats once per status message.

The law (docs/paper-notes.md section 3) with the explicit force bound of
``admittance.systems.optimal_admittance``:

    E_b[k] = (Fr - F[k]) - mu max(0, F[k] - Fg),      Fg = (Fr + Fmax) / 2
    Xr[k]  = clip(Xr[k-1] + Gamma K (dt E_b[k] + alpha (E_b[k] - E_b[k-1])), -max_push, max_push)

with dt the status clock's step. This is the difference form of Xr = Gamma K [z + alpha
(E - E0)], dz/dt = E; kept as an increment, the offset Xr is the law's state, so a change of
Gamma, alpha or Fmax while running changes its rate and never its value (bumpless), and a
step of Fr moves Xr by Gamma K alpha dFr at once, as the continuous law does.

The Cartesian PD (the PID of eq. 14-16 with Ki = 0: the law's integral removes the force
error) pulls the tip T toward p_ref = p_plan - Xr e_z (the press axis is the world's -z) and
the tool's orientation toward the plan's, with a null-space posture term for the seventh
joint. The torques exclude gravity: the Panda's torque interface adds it.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable

from admittance.diagrams.hardware.config import HardwareConfig
from admittance.diagrams.hardware.panda import AddPanda

__all__ = ["AdmittanceLaw", "CartesianPd", "force_along"]


class AdmittanceLaw:
    """The sampled optimal admittance law along one axis (module docstring)."""

    def __init__(
        self,
        *,
        force_reference: float,
        gamma: float,
        alpha: float,
        stiffness: float,
        max_force: float,
        force_bound_gain: float,
        max_push: float,
    ) -> None:
        self.force_reference = float(force_reference)
        self.gamma = float(gamma)
        self.alpha = float(alpha)
        self.max_force = float(max_force)
        self.stiffness = float(stiffness)
        self.force_bound_gain = float(force_bound_gain)
        self.max_push = float(max_push)
        self.offset = 0.0
        self._previous_error: float | None = None

    def bounded_error(self, force: float) -> float:
        """E_b = (Fr - F) - mu max(0, F - Fg)."""
        guard = 0.5 * (self.force_reference + self.max_force)
        excess = force - guard if force > guard else 0.0
        return (self.force_reference - force) - self.force_bound_gain * excess

    def update(self, force: float, dt: float) -> float:
        """Advances the law by one sample of length `dt` s; returns the offset Xr, m."""
        error = self.bounded_error(force)
        previous = error if self._previous_error is None else self._previous_error
        step = self.gamma * self.stiffness * (dt * error + self.alpha * (error - previous))
        self.offset = min(self.max_push, max(-self.max_push, self.offset + step))
        self._previous_error = error
        return self.offset

    def hold(self, force: float | None = None) -> float:
        """The offset held (no update): what a failed measurement leaves; the next valid
        sample restarts the difference from its own error (no jump)."""
        self._previous_error = None
        return self.offset

    def set_parameters(self, **values: float) -> None:
        """Changes Fr, Gamma, alpha or Fmax; the offset Xr continues (bumpless)."""
        for key, value in values.items():
            if key not in ("force_reference", "gamma", "alpha", "max_force"):
                raise ValueError(f"unknown law parameter {key!r}")
            setattr(self, key, float(value))


class CartesianPd:
    """The 6-D Cartesian PD on the Panda's tool tip, from the controller's own model.

    tau = J^T [k_r e_R - d_r w; k_t (p_ref - p) - d_t v] + N^T (k_q (q0 - q) - d_q qdot)

    with J the tip's spatial-velocity Jacobian in the world, e_R the rotation vector of
    R_ref R^T and N^T = I - J^T (J^+)^T the null-space projector; clipped to the effort
    limits. No gravity term (the robot adds it).
    """

    def __init__(self, config: HardwareConfig) -> None:
        self._plant = MultibodyPlant(0.0)
        model = AddPanda(self._plant)
        self._plant.Finalize()
        self._context = self._plant.CreateDefaultContext()
        self._frame = model.tool.body_frame()
        self._world = self._plant.world_frame()
        self._p_ST = model.p_ST.reshape(3, 1)
        self._limits = model.effort_limits
        self._kt, self._dt = config.translational_stiffness, config.translational_damping
        self._kr, self._dr = config.rotational_stiffness, config.rotational_damping
        self._kq, self._dq = config.posture_stiffness, config.posture_damping

    def tip_pose(self, q: np.ndarray) -> tuple[np.ndarray, RotationMatrix]:
        """p_WT and R_WS at the joint positions q."""
        self._plant.SetPositions(self._context, q)
        X_WS = self._plant.CalcRelativeTransform(self._context, self._world, self._frame)
        return X_WS.multiply(self._p_ST).reshape(3), X_WS.rotation()

    def torque(
        self,
        q: np.ndarray,
        v: np.ndarray,
        p_ref: np.ndarray,
        R_ref: RotationMatrix,
        q_posture: np.ndarray,
    ) -> np.ndarray:
        """The joint torques toward (p_ref, R_ref), at the pose set by q."""
        p, R = self.tip_pose(q)
        J = self._plant.CalcJacobianSpatialVelocity(
            self._context, JacobianWrtVariable.kV, self._frame, self._p_ST, self._world, self._world
        )
        twist = J @ v
        angle_axis = R_ref.multiply(R.inverse()).ToAngleAxis()
        e_R = angle_axis.axis() * angle_axis.angle()
        wrench = np.concatenate(
            [self._kr * e_R - self._dr * twist[:3], self._kt * (p_ref - p) - self._dt * twist[3:]]
        )
        J_pinv = np.linalg.pinv(J)
        null = np.eye(len(q)) - J.T @ J_pinv.T
        tau = J.T @ wrench + null @ (self._kq * (q_posture - q) - self._dq * v)
        return np.clip(tau, -self._limits, self._limits)


def force_along(R_WS: RotationMatrix, f_S: np.ndarray, axis: int = 2) -> float:
    """The world component `axis` of a force measured in the sensor frame S."""
    value = R_WS.multiply(np.asarray(f_S, dtype=float))[axis]
    return float(value) if math.isfinite(value) else float("nan")
