"""Meshcat replays of a run: one self-contained HTML file, made after the run.

A replay is built from the logged data on a small diagram of its own (the robot's plant +
SceneGraph + MeshcatVisualizer), so the simulated loop never carries a visualizer
(analysis diagrams stay visualizer-free, so that they convert to AutoDiffXd). This module
holds what every robot's replay uses (:class:`Replay`, :class:`ForceArrow`, the frame
times, the view bounds, the arrow scale, the atomic write) and the arm's replay,
:func:`write_meshcat_replay`: the arm, the wall at Xe(t) and the contact force as an arrow,
animated in a 2-D view of the x-y plane. The gripper's is ``robots.planar_gripper.replay``;
``views.figures.write_replay`` picks the robot's.
"""

from __future__ import annotations

import logging
import math
import os
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Box,
    Meshcat,
    MeshcatCone,
    MeshcatParams,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import (
    DiagramBuilder,
)

__all__ = [
    "ForceArrow",
    "Replay",
    "arrow_scale",
    "frame_times",
    "interpolate",
    "replay_frames",
    "staging_path",
    "view_bounds",
    "write_atomically",
]

# ---------------------------------------------------------------------------- replay

# Frames per second of simulated time in the replay (it plays back in real time). A power of
# two, so that frame k's time k / fps is exact and Meshcat's frame(time) = floor(time * fps)
# gives back k (with 50 fps, 29 / 50 * 50 = 28.999... would land on frame 28).
REPLAY_FRAMES_PER_SECOND = 32.0
# Length of the force arrow per newton of contact force, m/N ...
FORCE_ARROW_METERS_PER_NEWTON = 0.01
# ... unless the peak force would draw longer than this, m: then the scale shrinks so that
# the peak fits (the arrow stays proportional to the force within one replay).
FORCE_ARROW_MAX_LENGTH = 0.25
# Margin around everything drawn, m.
VIEW_MARGIN = 0.05
# The view shows its whole x range in any window at least this many times wider than tall.
VIEW_ASPECT = 1.4
FORCE_Z = 0.08
FORCE_PATH = "/replay/force"
FORCE_REFERENCE_PATH = "/replay/force_reference"
COMMANDED_PATH = "/replay/commanded_position"

# Colours of the overlays every replay draws.
FORCE_COLOR = Rgba(0.85, 0.10, 0.10, 1.0)
REFERENCE_COLOR = Rgba(0.10, 0.45, 0.85, 0.9)
COMMANDED_COLOR = Rgba(0.10, 0.60, 0.20, 0.9)

ARROW_SHAFT_WIDTH = 0.008
ARROW_HEAD_LENGTH = 0.02
ARROW_HEAD_RADIUS = 0.012
# A zero-length shaft is drawn with this scale (three.js dislikes a singular scale).
_TINY_SCALE = 1e-4


def staging_path(path: Path) -> Path:
    """A new hidden sibling of `path`, to write into before moving it onto `path`.

    (Unlike tempfile's files, it gets the usual permissions of a new file.)
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}{path.suffix}")


def write_atomically(path: Path, data: bytes) -> None:
    """Writes `data` to a sibling file, then moves it onto `path`: no half-written file."""
    staging = staging_path(path)
    try:
        staging.write_bytes(data)
        os.replace(staging, path)
    finally:
        staging.unlink(missing_ok=True)


def _quiet_meshcat() -> Meshcat:
    """A Meshcat on localhost, without its "listening for connections" message.

    The server lives only while the replay is recorded: pointing a user at it would mislead.
    """
    drake_logger = logging.getLogger("drake")
    level = drake_logger.level
    drake_logger.setLevel(logging.WARNING)
    try:
        return Meshcat(MeshcatParams(host="localhost"))
    finally:
        drake_logger.setLevel(level)


def frame_times(time: np.ndarray) -> np.ndarray:
    """Replay times k / fps over the logged span, for consecutive integers k."""
    first = math.ceil(float(time[0]) * REPLAY_FRAMES_PER_SECOND - 1e-9)
    last = math.floor(float(time[-1]) * REPLAY_FRAMES_PER_SECOND + 1e-9)
    return np.arange(first, max(last, first + 1) + 1) / REPLAY_FRAMES_PER_SECOND


def replay_frames(result) -> tuple[np.ndarray, np.ndarray]:
    """A run's replay frame times (:func:`frame_times`) and its joint positions there."""
    times = frame_times(result.time)
    return times, interpolate(result.time, result.joint_positions, times)


def interpolate(time: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Linear interpolation of the columns of `values` (N,) or (N, k) at times `at`."""
    if values.ndim == 1:
        return np.interp(at, time, values)
    return np.column_stack([np.interp(at, time, column) for column in values.T])


def view_bounds(points_xy: np.ndarray) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) around `points_xy`, with a margin and a landscape aspect.

    Meshcat fits the y range to the window's height and centres the x range; the y range is
    widened so that the x range fits any window at least VIEW_ASPECT times wider than tall.
    """
    low = points_xy.min(axis=0) - VIEW_MARGIN
    high = points_xy.max(axis=0) + VIEW_MARGIN
    center = 0.5 * (low + high)
    half_height = max(0.5 * (high[1] - low[1]), 0.5 * (high[0] - low[0]) / VIEW_ASPECT)
    bottom, top = center[1] - half_height, center[1] + half_height
    return float(low[0]), float(high[0]), float(bottom), float(top)


def arrow_scale(forces: np.ndarray, meters_per_newton: float, max_length: float) -> float:
    """Arrow length per newton, m/N: `meters_per_newton`, or less if the largest of `forces`
    would draw longer than `max_length` (the arrows stay proportional within a replay)."""
    peak = float(forces.max()) if forces.size else 0.0
    if peak * meters_per_newton > max_length:
        return max_length / peak
    return meters_per_newton


# The cone's apex is at its origin and it opens along +z: turned to open along -x, its apex
# points along +x.
_HEAD_ALONG_X = RotationMatrix.MakeYRotation(-math.pi / 2)


@dataclass(frozen=True)
class ForceArrow:
    """A force arrow in a replay: a box shaft and a cone head, set to a length per frame."""

    path: str
    shaft_width: float
    head_length: float
    head_radius: float
    color: Rgba

    def add_to(self, meshcat: Meshcat) -> None:
        width = self.shaft_width
        meshcat.SetObject(f"{self.path}/shaft", Box(1.0, width, width), self.color)
        meshcat.SetObject(
            f"{self.path}/head",
            MeshcatCone(self.head_length, self.head_radius, self.head_radius),
            self.color,
        )

    def animate(self, animation, frame: int, start, length: float, rotation=None) -> None:
        """The arrow from `start`, `length` long, along +x turned by `rotation` (None: +x).

        The shaft reaches the head's base and the head shrinks with an arrow shorter than
        itself; an arrow of no length is hidden.
        """
        direction = np.array([1.0, 0.0, 0.0]) if rotation is None else rotation.col(0)
        head_rotation = _HEAD_ALONG_X if rotation is None else rotation @ _HEAD_ALONG_X
        shaft_rotation = RotationMatrix() if rotation is None else rotation
        head_scale = min(1.0, length / self.head_length)
        shaft = max(length - self.head_length, _TINY_SCALE)
        animation.SetProperty(frame, self.path, "visible", bool(length > _TINY_SCALE))
        animation.SetTransform(
            frame,
            f"{self.path}/shaft",
            RigidTransform(shaft_rotation, start + 0.5 * shaft * direction),
        )
        animation.SetProperty(frame, f"{self.path}/shaft", "scale", [shaft, 1.0, 1.0])
        animation.SetTransform(
            frame, f"{self.path}/head", RigidTransform(head_rotation, start + length * direction)
        )
        animation.SetProperty(
            frame, f"{self.path}/head", "scale", [max(head_scale, _TINY_SCALE)] * 3
        )


class Replay:
    """The small diagram a replay is recorded on: a model's illustration geometry (its
    plant and SceneGraph, added to `builder`) drawn by a MeshcatVisualizer on a Meshcat
    served on localhost for the time of the call."""

    def __init__(self, builder: DiagramBuilder, plant, scene_graph) -> None:
        self.plant = plant
        self.meshcat = _quiet_meshcat()
        self.visualizer = MeshcatVisualizer.AddToBuilder(
            builder,
            scene_graph,
            self.meshcat,
            MeshcatVisualizerParams(
                role=Role.kIllustration, publish_period=1.0 / REPLAY_FRAMES_PER_SECOND
            ),
        )
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)

    def body_positions(self, joint_positions: np.ndarray, bodies) -> np.ndarray:
        """The origins of `bodies` in world at each row of `joint_positions`, (n * b, 3)."""
        plant, plant_context = self.plant, self.plant_context
        points = []
        for q in joint_positions:
            plant.SetPositions(plant_context, q)
            points.append(
                [plant.EvalBodyPoseInWorld(plant_context, b).translation() for b in bodies]
            )
        return np.vstack(points)

    def record(
        self,
        times: np.ndarray,
        joint_positions: np.ndarray,
        draw_overlays: Callable[[object, int, int], None],
    ) -> None:
        """Records the model posed at `joint_positions[k]` at `times[k]`; the overlays of
        each frame are set by ``draw_overlays(animation, frame, k)``."""
        animation = self.visualizer.StartRecording(set_transforms_while_recording=False)
        for index, t in enumerate(times):
            self.context.SetTime(float(t))
            self.plant.SetPositions(self.plant_context, joint_positions[index])
            self.diagram.ForcedPublish(self.context)
            draw_overlays(animation, animation.frame(float(t)), index)
        self.visualizer.StopRecording()
        self.visualizer.PublishRecording()

    def write(self, path: Path, X_WCamera: RigidTransform, bounds) -> Path:
        """The orthographic view of `bounds` (xmin, xmax, ymin, ymax in the camera's plane)
        from `X_WCamera`, and the recording, as one HTML file written atomically."""
        xmin, xmax, ymin, ymax = bounds
        self.meshcat.Set2dRenderMode(X_WC=X_WCamera, xmin=xmin, xmax=xmax, ymin=ymin, ymax=ymax)
        write_atomically(path, self.meshcat.StaticHtml().encode("utf-8"))
        return path

    def write_perspective(self, path: Path, camera_in_world, target_in_world) -> Path:
        """Meshcat's perspective camera at `camera_in_world` looking at `target_in_world`
        (world z up), and the recording, as one HTML file written atomically."""
        self.meshcat.SetCameraPose(
            np.asarray(camera_in_world, float), np.asarray(target_in_world, float)
        )
        write_atomically(path, self.meshcat.StaticHtml().encode("utf-8"))
        return path
