"""A self-contained Meshcat replay of a grasp: the hand, the brick and the contact forces.

Like the arm's replay (diagrams/visualization.py), it is made after the run from the logged
data, on a diagram of its own (the hand and brick, a SceneGraph and a MeshcatVisualizer),
so that the simulated loop never carries a visualizer.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Box,
    MeshcatCone,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.grasp import AddHand
from admittance.diagrams.grasp_scenario import FINGERS
from admittance.diagrams.grasp_simulation import GraspResult
from admittance.diagrams.visualization import (
    REPLAY_FRAMES_PER_SECOND,
    _frame_times,
    _interpolate,
    _quiet_meshcat,
    _view_bounds,
    _write_atomically,
)

__all__ = ["write_grasp_meshcat_replay"]

# Length of a force arrow per newton, m/N, unless the peak would draw longer than
# ARROW_MAX_LENGTH (then the scale shrinks so the peak fits).
ARROW_METERS_PER_NEWTON = 0.02
ARROW_MAX_LENGTH = 0.08
# The overlays are drawn this far in front of the hand's plane (the camera looks along -x).
OVERLAY_X = 0.06
FORCE_PATH = "/replay/contact_force"
_FORCE_COLOR = Rgba(0.85, 0.10, 0.10, 1.0)
_SHAFT_WIDTH = 0.004
_HEAD_LENGTH = 0.01
_HEAD_RADIUS = 0.006
_TINY_SCALE = 1e-4


def _along(normal: np.ndarray) -> RotationMatrix:
    """A rotation that turns +x into `normal` (a unit vector in the y-z plane)."""
    angle = math.atan2(normal[2], normal[1])
    return RotationMatrix.MakeXRotation(angle) @ RotationMatrix.MakeZRotation(math.pi / 2)


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
    times = _frame_times(result.time)
    joint_positions = _interpolate(result.time, result.joint_positions, times)
    forces = np.maximum(
        np.column_stack([_interpolate(result.time, result.force[:, i], times) for i in range(3)]),
        0.0,
    )
    tips = [_interpolate(result.time, result.tip[:, i, :], times) for i in range(3)]
    peak = float(forces.max()) if forces.size else 0.0
    meters_per_newton = ARROW_METERS_PER_NEWTON
    if peak * meters_per_newton > ARROW_MAX_LENGTH:
        meters_per_newton = ARROW_MAX_LENGTH / peak

    builder = DiagramBuilder()
    plant, scene_graph, geometry = AddHand(builder, result.scenario)
    meshcat = _quiet_meshcat()
    visualizer = MeshcatVisualizer.AddToBuilder(
        builder,
        scene_graph,
        meshcat,
        MeshcatVisualizerParams(
            role=Role.kIllustration, publish_period=1.0 / REPLAY_FRAMES_PER_SECOND
        ),
    )
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)

    head_rotation = RotationMatrix.MakeYRotation(-math.pi / 2)  # the cone's apex along +x
    normals, rotations = [], []
    for index, finger in enumerate(FINGERS):
        X_WC = geometry.face_frames[index]
        normals.append(X_WC.rotation().col(0))
        rotations.append(_along(normals[-1]))
        meshcat.SetObject(
            f"{FORCE_PATH}/{finger}/shaft", Box(1.0, _SHAFT_WIDTH, _SHAFT_WIDTH), _FORCE_COLOR
        )
        meshcat.SetObject(
            f"{FORCE_PATH}/{finger}/head",
            MeshcatCone(_HEAD_LENGTH, _HEAD_RADIUS, _HEAD_RADIUS),
            _FORCE_COLOR,
        )

    animation = visualizer.StartRecording(set_transforms_while_recording=False)
    for frame_index, t in enumerate(times):
        context.SetTime(float(t))
        plant.SetPositions(plant_context, joint_positions[frame_index])
        diagram.ForcedPublish(context)
        frame = animation.frame(float(t))
        for index, finger in enumerate(FINGERS):
            X_WC = geometry.face_frames[index]
            tip = tips[index][frame_index]
            # The contact point: the tip centre moved by the radius along the normal.
            centre = X_WC.multiply(np.array([tip[0], tip[1], 0.0]))
            start = centre + geometry.tip_radius * normals[index]
            start[0] = OVERLAY_X
            length = forces[frame_index, index] * meters_per_newton
            shaft = max(length - _HEAD_LENGTH, _TINY_SCALE)
            head_scale = max(min(1.0, length / _HEAD_LENGTH), _TINY_SCALE)
            base = f"{FORCE_PATH}/{finger}"
            animation.SetProperty(frame, base, "visible", bool(length > _TINY_SCALE))
            animation.SetTransform(
                frame,
                f"{base}/shaft",
                RigidTransform(rotations[index], start + 0.5 * shaft * normals[index]),
            )
            animation.SetProperty(frame, f"{base}/shaft", "scale", [shaft, 1.0, 1.0])
            animation.SetTransform(
                frame,
                f"{base}/head",
                RigidTransform(rotations[index] @ head_rotation, start + length * normals[index]),
            )
            animation.SetProperty(frame, f"{base}/head", "scale", [head_scale] * 3)
    visualizer.StopRecording()
    visualizer.PublishRecording()

    # Fit the view around the fingers' bodies and the brick over the run.
    points = []
    bodies = [
        plant.GetBodyByName(f"{finger}_{link}")
        for finger in FINGERS
        for link in ("base", "link1", "link2", "tip_link")
    ] + [plant.GetBodyByName("brick_link")]
    for q in joint_positions[:: max(1, len(joint_positions) // 50)]:
        plant.SetPositions(plant_context, q)
        points.append(
            [plant.EvalBodyPoseInWorld(plant_context, body).translation()[1:] for body in bodies]
        )
    ymin, ymax, zmin, zmax = _view_bounds(np.vstack(points))
    # Camera in front of the plane (x = +1) looking along -x (its +y), world z up (its +z):
    # its x axis is then world +y, drawn to the right.
    X_WCamera = RigidTransform(RotationMatrix.MakeZRotation(math.pi / 2), [1.0, 0.0, 0.0])
    meshcat.Set2dRenderMode(X_WC=X_WCamera, xmin=ymin, xmax=ymax, ymin=zmin, ymax=zmax)
    _write_atomically(path, meshcat.StaticHtml().encode("utf-8"))
    return path
