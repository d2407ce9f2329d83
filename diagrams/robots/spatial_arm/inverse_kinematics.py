"""Inverse kinematics of a frame's 6-D pose on a spatial arm's plant, by damped Newton
steps on the plant's own kinematics (the tool tip at the plan's start)."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable

from admittance.systems.spatial_kinematics import rotation_vector

__all__ = ["SolveSpatialInverseKinematics"]


def SolveSpatialInverseKinematics(
    plant: MultibodyPlant,
    frame_name: str,
    X_WT: RigidTransform,
    joint_guess,
    *,
    tolerance: float = 1e-10,
    max_iterations: int = 200,
) -> np.ndarray:
    """Joint positions that put `frame_name` at the pose X_WT, by damped Newton steps.

    The step is the least-squares solution of J dq = (rotation vector, position error);
    a redundant arm's remaining freedom pulls towards `joint_guess` (a null-space step),
    so the guess picks the branch and the posture.

    Raises:
        ValueError: the pose is not reached (out of the workspace, singular, or beyond the
            joint limits).
    """
    context = plant.CreateDefaultContext()
    frame = plant.GetFrameByName(frame_name)
    guess = np.zeros(plant.num_positions())
    given = np.asarray(joint_guess, dtype=float)
    guess[: min(guess.size, given.size)] = given[: guess.size]
    q = guess.copy()
    for _ in range(max_iterations):
        plant.SetPositions(context, q)
        X = plant.CalcRelativeTransform(context, plant.world_frame(), frame)
        error = np.concatenate(
            [
                rotation_vector((X_WT.rotation() @ X.rotation().inverse()).matrix().tolist()),
                X_WT.translation() - X.translation(),
            ]
        )
        if np.linalg.norm(error) < tolerance:
            break
        J = plant.CalcJacobianSpatialVelocity(
            context,
            JacobianWrtVariable.kQDot,
            frame,
            np.zeros(3),
            plant.world_frame(),
            plant.world_frame(),
        )
        pseudo_inverse = np.linalg.pinv(J, rcond=1e-6)
        step = pseudo_inverse @ error
        step += (np.eye(q.size) - pseudo_inverse @ J) @ (0.2 * (guess - q))
        q = q + step * min(1.0, 0.3 / max(np.max(np.abs(step)), 1e-12))
    else:
        raise ValueError(f"the pose is not reached from {given.tolist()} (error {error.tolist()})")
    low, high = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    if np.any(q < low - 1e-9) or np.any(q > high + 1e-9):
        raise ValueError(f"the pose needs joints {q.tolist()} beyond the joint limits")
    return q
