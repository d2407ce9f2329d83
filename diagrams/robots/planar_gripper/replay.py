"""A self-contained Meshcat replay of a grasp: the hand, the brick and the contact forces.

Like the arm's replay (diagrams/views/replay.py), it is made after the run from the logged
data, on a diagram of its own (the hand and brick, a SceneGraph and a MeshcatVisualizer),
so that the simulated loop never carries a visualizer.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.planar_gripper.plant import AddHand
from admittance.diagrams.robots.planar_gripper.run import GraspResult
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS
from admittance.diagrams.views.replay import (
    FORCE_COLOR,
    ForceArrow,
    Replay,
    arrow_scale,
    interpolate,
    replay_frames,
    view_bounds,
)

__all__ = [
    "write_grasp_meshcat_replay",
]

# Length of a force arrow per newton, m/N, unless the peak would draw longer than
# ARROW_MAX_LENGTH (then the scale shrinks so the peak fits).
ARROW_METERS_PER_NEWTON = 0.02
ARROW_MAX_LENGTH = 0.08
# The overlays are drawn this far in front of the hand's plane (the camera looks along -x).
OVERLAY_X = 0.06
FORCE_PATH = "/replay/contact_force"
ARROW_SHAFT_WIDTH = 0.004
ARROW_HEAD_LENGTH = 0.01
ARROW_HEAD_RADIUS = 0.006


def _along(normal: np.ndarray) -> RotationMatrix:
    """A rotation that turns +x into `normal` (a unit vector in the y-z plane), +y into -x
    and +z into x cross `normal`; its first column is `normal` exactly."""
    _, ny, nz = normal
    return RotationMatrix(np.array([[0.0, -1.0, 0.0], [ny, 0.0, -nz], [nz, 0.0, ny]]))


def write_grasp_meshcat_replay(result: GraspResult, path: str | os.PathLike) -> Path:
    """Writes a self-contained HTML replay of a finished grasp, viewable offline.

    The gripper and the brick (their illustration geometry from Drake's models) are posed
    at the logged joint positions, REPLAY_FRAMES_PER_SECOND frames per simulated second; a
    red arrow at each fingertip's contact point, along its face's inward normal, has a
    length proportional to the contact engine's normal force. The view is orthographic
    onto the hand's y-z plane (world y to the right, world z, against gravity, up).

    Args:
        result: a finished grasp (``run_grasp``).
        path: the HTML file to write; its folder is created if needed.

    Returns:
        The path written.
    """
    path = Path(path)
    times, joint_positions = replay_frames(result)
    forces = np.maximum(
        np.column_stack([interpolate(result.time, result.force[:, i], times) for i in range(3)]),
        0.0,
    )
    tips = [interpolate(result.time, result.tip[:, i, :], times) for i in range(3)]
    meters_per_newton = arrow_scale(forces, ARROW_METERS_PER_NEWTON, ARROW_MAX_LENGTH)

    builder = DiagramBuilder()
    plant, scene_graph, geometry = AddHand(builder, result.scenario)
    replay = Replay(builder, plant, scene_graph)

    normals, rotations, arrows = [], [], []
    for index, finger in enumerate(FINGERS):
        normals.append(geometry.face_frames[index].rotation().col(0))
        rotations.append(_along(normals[-1]))
        arrows.append(
            ForceArrow(
                f"{FORCE_PATH}/{finger}",
                ARROW_SHAFT_WIDTH,
                ARROW_HEAD_LENGTH,
                ARROW_HEAD_RADIUS,
                FORCE_COLOR,
            )
        )
        arrows[-1].add_to(replay.meshcat)

    def draw_overlays(animation, frame: int, frame_index: int) -> None:
        for index, arrow in enumerate(arrows):
            tip = tips[index][frame_index]
            # The contact point: the tip centre moved by the radius along the normal.
            centre = geometry.face_frames[index].multiply(np.array([tip[0], tip[1], 0.0]))
            start = centre + geometry.tip_radius * normals[index]
            start[0] = OVERLAY_X
            length = forces[frame_index, index] * meters_per_newton
            arrow.animate(animation, frame, start, length, rotations[index])

    replay.record(times, joint_positions, draw_overlays)
    # Fit the view around the fingers' bodies and the brick over the run.
    bodies = [
        plant.GetBodyByName(f"{finger}_{link}")
        for finger in FINGERS
        for link in ("base", "link1", "link2", "tip_link")
    ] + [plant.GetBodyByName("brick_link")]
    sampled = joint_positions[:: max(1, len(joint_positions) // 50)]
    bounds = view_bounds(replay.body_positions(sampled, bodies)[:, 1:])
    # Camera in front of the plane (x = +1) looking along -x (its +y), world z up (its +z):
    # its x axis is then world +y, drawn to the right.
    X_WCamera = RigidTransform(RotationMatrix.MakeZRotation(math.pi / 2), [1.0, 0.0, 0.0])
    return replay.write(path, X_WCamera, bounds)
