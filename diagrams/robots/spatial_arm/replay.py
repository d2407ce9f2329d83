"""A self-contained Meshcat replay of a spatial-arm run: the arm with its own meshes, the
tool, the table and the force along the planned normal.

Like the planar arm's replay (diagrams/views/replay.py), it is made after the run from the
logged data, on a diagram of its own (the scenario's arm, tool and table, a SceneGraph and a
MeshcatVisualizer), so that the simulated loop never carries a visualizer.

**What it shows.** The arm's illustration geometry as its description gives it: the Franka
Panda's and the UR5's visual meshes in example-robot-data are Collada (.dae) files, which
Drake's Meshcat sends whole (a ``_meshfile_geometry`` of format ``dae``, read by the
viewer's Collada loader), in Drake's default grey (the URDFs give them no material); the
collision meshes are never loaded (robots.spatial_arm.model leaves them out). The tool
(shaft and sphere or disc) and the table (at its true height and tilt, not the plan's) are
the plant's own primitives. The Panda's meshes make a file of about 16 MB.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from pydrake.geometry import Cylinder, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.spatial_arm.plant import TOOL_TIP_FRAME, AddSpatialArm
from admittance.diagrams.robots.spatial_arm.run import SpatialResult
from admittance.diagrams.views.replay import (
    COMMANDED_COLOR,
    COMMANDED_PATH,
    FORCE_COLOR,
    FORCE_PATH,
    FORCE_REFERENCE_PATH,
    REFERENCE_COLOR,
    ForceArrow,
    Replay,
    arrow_scale,
    interpolate,
    replay_frames,
)

__all__ = ["write_spatial_meshcat_replay"]

# Length of the force arrow per newton, m/N, unless the peak would draw longer than
# ARROW_MAX_LENGTH (then the scale shrinks so that the peak fits).
ARROW_METERS_PER_NEWTON = 0.01
ARROW_MAX_LENGTH = 0.15
ARROW_SHAFT_WIDTH = 0.004
ARROW_HEAD_LENGTH = 0.012
ARROW_HEAD_RADIUS = 0.007
# The Fr mark: a thin disc across the normal, at Fr's length on the arrow's scale.
REFERENCE_RADIUS = 0.012
REFERENCE_THICKNESS = 0.002
# The camera, from the point halfway between the arm's base and the planned contact point
# (its height CAMERA_TARGET_HEIGHT): off to the side and above, m.
CAMERA_OFFSET = (0.7, -1.3, 0.5)
CAMERA_TARGET_HEIGHT = 0.3


def write_spatial_meshcat_replay(result: SpatialResult, path: str | os.PathLike) -> Path:
    """Writes a self-contained HTML replay of a finished spatial-arm run, viewable offline.

    The arm, its tool and the table (see the module's docstring) are posed at the logged
    joint positions, REPLAY_FRAMES_PER_SECOND frames per simulated second. A red arrow from
    the tool tip along the planned inward normal (the control frame's z) has a length
    proportional to the true force along it (ARROW_METERS_PER_NEWTON, less if the peak would
    not fit); a blue disc marks Fr on the same scale; a green dot marks the commanded
    position Xd + Xr. The view is Meshcat's perspective camera, world z up, which the
    mouse turns; "Open Controls" (Animations) plays the run again, pauses or scrubs it.

    Args:
        result: what ``run_spatial`` returned.
        path: where the HTML goes (missing folders are made).

    Returns:
        `path`, as a Path.
    """
    path, scenario = Path(path), result.scenario
    times, joint_positions = replay_frames(result)
    force = np.maximum(interpolate(result.time, result.force, times), 0.0)
    commanded = interpolate(result.time, result.plan[:, :3], times)
    commanded[:, 2] += interpolate(result.time, result.reference_offset, times)
    meters_per_newton = arrow_scale(force, ARROW_METERS_PER_NEWTON, ARROW_MAX_LENGTH)

    builder = DiagramBuilder()
    plant, scene_graph, geometry = AddSpatialArm(builder, scenario)
    replay = Replay(builder, plant, scene_graph)

    # The tool tip in world at each frame, and the commanded position (in the control
    # frame E) in world.
    tip_frame = plant.GetFrameByName(TOOL_TIP_FRAME)
    tips = []
    for q in joint_positions:
        plant.SetPositions(replay.plant_context, q)
        tips.append(tip_frame.CalcPoseInWorld(replay.plant_context).translation())
    X_WE = geometry.X_WE
    commanded_W = [X_WE.multiply(point) for point in commanded]
    R_WE = X_WE.rotation()
    normal = R_WE.col(2)
    # The arrow is drawn along its +x: turned so that +x is the inward normal.
    along_normal = R_WE @ RotationMatrix.MakeYRotation(-math.pi / 2)
    reference_length = scenario.force_reference * meters_per_newton

    meshcat = replay.meshcat
    arrow = ForceArrow(
        FORCE_PATH, ARROW_SHAFT_WIDTH, ARROW_HEAD_LENGTH, ARROW_HEAD_RADIUS, FORCE_COLOR
    )
    arrow.add_to(meshcat)
    meshcat.SetObject(
        FORCE_REFERENCE_PATH, Cylinder(REFERENCE_RADIUS, REFERENCE_THICKNESS), REFERENCE_COLOR
    )
    meshcat.SetObject(COMMANDED_PATH, Sphere(0.004), COMMANDED_COLOR)

    def draw_overlays(animation, frame: int, index: int) -> None:
        tip = tips[index]
        arrow.animate(animation, frame, tip, force[index] * meters_per_newton, along_normal)
        animation.SetTransform(
            frame,
            FORCE_REFERENCE_PATH,
            RigidTransform(R_WE, tip + reference_length * normal),
        )
        animation.SetTransform(frame, COMMANDED_PATH, RigidTransform(commanded_W[index]))

    replay.record(times, joint_positions, draw_overlays)
    contact = X_WE.translation()
    target = np.array([0.5 * contact[0], 0.5 * contact[1], CAMERA_TARGET_HEIGHT])
    return replay.write_perspective(path, target + np.array(CAMERA_OFFSET), target)
