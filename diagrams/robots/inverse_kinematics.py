"""Inverse kinematics of a frame's planar task coordinates on any plant, by damped
Newton steps on the plant's own kinematics (the paper's arm, the gripper's fingers).
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = ["SolvePlanarInverseKinematics"]


def SolvePlanarInverseKinematics(
    plant: MultibodyPlant,
    frame_name: str,
    target,
    joint_guess,
    *,
    coordinates: tuple[str, ...],
    tolerance: float = 1e-10,
    max_iterations: int = 100,
    expressed_in: str = "world",
) -> np.ndarray:
    """Joint positions that put `frame_name` at X = target, by Newton steps from a seed.

    Uses the plant's own kinematics (so any planar URDF works); the seed picks the branch.
    X holds `coordinates` (the planar arm's (x, y, theta), a fingertip's (x, y)) in
    `expressed_in` (world, or the frame of a finger's face); the seed may hold every
    position of the plant, and joints that do not move the frame keep their seed.

    Raises:
        ValueError: the target is not reached (out of the workspace, or singular).
    """
    kinematics = PlanarFrameKinematics(
        plant, frame_name, coordinates=coordinates, expressed_in=expressed_in
    )
    angle = kinematics.angle_index
    target = np.asarray(target, dtype=float)
    q = np.zeros(plant.num_positions())
    guess = np.asarray(joint_guess, dtype=float)
    q[: min(q.size, guess.size)] = guess[: q.size]
    v = np.zeros(plant.num_velocities())
    for _ in range(max_iterations):
        kinematics.set_state(np.concatenate([q, v]))
        error = target - kinematics.pose()
        if angle is not None:
            error[angle] = np.arctan2(np.sin(error[angle]), np.cos(error[angle]))
        if np.linalg.norm(error) < tolerance:
            return q
        step = np.linalg.lstsq(kinematics.jacobian(), error, rcond=None)[0]
        # Limit each Newton step so that a far seed does not jump branches.
        q = q + step * min(1.0, 0.5 / max(np.max(np.abs(step)), 1e-12))
    raise ValueError(f"the pose {target.tolist()} is not reachable from the seed {guess.tolist()}")
