"""The planar arm's Meshcat replay: the arm, the wall at Xe(t) and the contact force as an
arrow, in a 2-D view of the x-y plane (the machinery is views.replay's).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Box,
    Rgba,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import (
    DiagramBuilder,
)

from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.run import SimulationResult
from admittance.diagrams.views.replay import (
    ARROW_HEAD_LENGTH,
    ARROW_HEAD_RADIUS,
    ARROW_SHAFT_WIDTH,
    COMMANDED_COLOR,
    COMMANDED_PATH,
    FORCE_ARROW_MAX_LENGTH,
    FORCE_ARROW_METERS_PER_NEWTON,
    FORCE_COLOR,
    FORCE_PATH,
    FORCE_REFERENCE_PATH,
    FORCE_Z,
    REFERENCE_COLOR,
    VIEW_MARGIN,
    ForceArrow,
    Replay,
    arrow_scale,
    interpolate,
    replay_frames,
    view_bounds,
)

__all__ = ["WALL_PATH", "WALL_THICKNESS", "WALL_Z", "write_meshcat_replay"]


# Wall slab thickness along x, m (it spans the view's height).
WALL_THICKNESS = 0.03


# Heights (world z) at which the overlays are drawn: the camera looks down -z, so a larger
# z is drawn on top. The arm's drive cylinders reach z = 0.055.
WALL_Z = 0.0


# Paths in the Meshcat scene tree.
WALL_PATH = "/replay/wall"


_WALL_COLOR = Rgba(0.55, 0.42, 0.30, 0.75)


def write_meshcat_replay(result: SimulationResult, path: str | os.PathLike) -> Path:
    """Writes a self-contained HTML replay of a finished run, viewable offline.

    The arm (illustration geometry of the scenario's URDF) is posed at the logged joint
    positions, REPLAY_FRAMES_PER_SECOND frames per simulated second; the wall is a slab whose
    face is at Xe(t); a red arrow from the fingertip into the wall has a length proportional
    to the true contact force (FORCE_ARROW_METERS_PER_NEWTON, less if the peak would not
    fit), a blue tick marks the length of Fr on the same scale, and a green dot marks the
    commanded position Xc = Xd + Xr. The view is orthographic onto the x-y plane: +x to the
    right, +y (against gravity) up, scaled to fit the window's height. The animation plays
    once, in real time, when the file is opened and holds its last frame; Meshcat's "Open
    Controls" menu (Animations) plays it again, pauses it, changes its speed or scrubs it.

    The replay is made on a diagram of its own (the scenario's arm, a SceneGraph and a
    MeshcatVisualizer on a Meshcat served on localhost for the time of the call).

    Args:
        result: a finished run (``run_scenario``).
        path: the HTML file to write; its folder is created if needed.

    Returns:
        The path written.
    """
    path = Path(path)
    times, joint_positions = replay_frames(result)
    tracks = _Tracks.of(result, times)
    builder = DiagramBuilder()
    replay = Replay(builder, *AddScenarioArm(builder, result.scenario.arm))
    bounds = _view_bounds(replay, tracks, joint_positions)
    draw_overlays = _add_overlays(replay.meshcat, tracks, bounds)
    replay.record(times, joint_positions, draw_overlays)
    # Camera above the plane looking down -z (its +y axis) with world +y up (its +z axis):
    # its x axis is then world +x, drawn to the right.
    X_WC = RigidTransform(RotationMatrix.MakeXRotation(-math.pi / 2), [0.0, 0.0, 1.0])
    return replay.write(path, X_WC, bounds)


@dataclass
class _Tracks:
    """What the overlays follow, at the replay's frames: the fingertip's and the commanded
    position's x-y, the wall's face, the arrow's length and Fr's on the same scale."""

    tip_xy: np.ndarray
    commanded_xy: np.ndarray
    wall_position: np.ndarray
    arrow_length: np.ndarray
    reference_length: float

    @classmethod
    def of(cls, result: SimulationResult, times: np.ndarray) -> _Tracks:
        force = np.maximum(interpolate(result.time, result.force, times), 0.0)
        meters_per_newton = arrow_scale(
            force, FORCE_ARROW_METERS_PER_NEWTON, FORCE_ARROW_MAX_LENGTH
        )
        return cls(
            tip_xy=interpolate(result.time, result.pose[:, :2], times),
            commanded_xy=interpolate(
                result.time, (result.desired_position + result.reference_offset)[:, :2], times
            ),
            wall_position=interpolate(result.time, result.wall_position, times),
            arrow_length=force * meters_per_newton,
            reference_length=result.scenario.force_reference * meters_per_newton,
        )


def _view_bounds(replay: Replay, tracks: _Tracks, joint_positions: np.ndarray) -> tuple:
    """(xmin, xmax, ymin, ymax) around everything drawn: every body of the arm over the
    run, the wall's face, the longest arrow and the commanded position."""
    plant = replay.plant
    tip_xy = tracks.tip_xy
    bodies = [plant.get_body(BodyIndex(index)) for index in range(1, plant.num_bodies())]
    points = [tip_xy, tracks.commanded_xy, np.column_stack([tracks.wall_position, tip_xy[:, 1]])]
    points.append(np.column_stack([tip_xy[:, 0] + tracks.arrow_length, tip_xy[:, 1]]))
    points.append(replay.body_positions(joint_positions, bodies)[:, :2])
    return view_bounds(np.vstack(points))


def _add_overlays(meshcat, tracks: _Tracks, bounds: tuple):
    """Adds the wall (spanning the view's height), the force arrow, Fr's tick and the
    commanded position's dot; returns what poses them at each frame."""
    xmin, xmax, ymin, ymax = bounds
    wall_height = (ymax - ymin) + 2.0 * VIEW_MARGIN
    meshcat.SetObject(WALL_PATH, Box(WALL_THICKNESS, wall_height, 0.02), _WALL_COLOR)
    # The arrow points along +x, the direction of the force the fingertip applies to the wall.
    arrow = ForceArrow(
        FORCE_PATH, ARROW_SHAFT_WIDTH, ARROW_HEAD_LENGTH, ARROW_HEAD_RADIUS, FORCE_COLOR
    )
    arrow.add_to(meshcat)
    meshcat.SetObject(FORCE_REFERENCE_PATH, Box(0.003, 0.04, 0.003), REFERENCE_COLOR)
    meshcat.SetObject(COMMANDED_PATH, Sphere(0.005), COMMANDED_COLOR)
    wall_y = 0.5 * (ymin + ymax)

    def draw_overlays(animation, frame: int, index: int) -> None:
        tip, xc = tracks.tip_xy[index], tracks.commanded_xy[index]
        animation.SetTransform(
            frame,
            WALL_PATH,
            RigidTransform([tracks.wall_position[index] + 0.5 * WALL_THICKNESS, wall_y, WALL_Z]),
        )
        arrow.animate(
            animation, frame, np.array([tip[0], tip[1], FORCE_Z]), tracks.arrow_length[index]
        )
        animation.SetTransform(
            frame,
            FORCE_REFERENCE_PATH,
            RigidTransform([tip[0] + tracks.reference_length, tip[1], FORCE_Z + 0.001]),
        )
        animation.SetTransform(
            frame, COMMANDED_PATH, RigidTransform([xc[0], xc[1], FORCE_Z - 0.002])
        )

    return draw_overlays
