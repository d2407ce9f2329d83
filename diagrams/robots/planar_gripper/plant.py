"""The hand: Drake's planar gripper holding its brick, and its three force-controlled points.

The paper closes with "future applications to manipulation and grasping tasks". This module
loads Drake's three-fingered planar gripper and its brick from the installed drake package
(``package://drake/examples/planar_gripper/``), welds the fingers around the brick as Drake's
planar gripper example does, in the vertical y-z plane with gravity along -z, and describes
each fingertip as a force-controlled point (:func:`finger_points`); ``robots.planar_gripper.loop``
wires one copy of the paper's Fig. 1 per finger from that description:

    Xd_i --(+)--> Xc_i --> CartesianPid_i --tau_i--(+)--> plant --contact results--+
           ^ Xr_i             (tip's (x, y) in its face's frame)                    |
           +--- OptimalAdmittance_i <-- Fm_i -- FlexiForce_i <-- F_i -- ContactForceSensor
                        ^ Fr_i(t)

* Contact is Drake's own compliant point contact (a sphere tip on a box face gives one
  contact point with a linear stiffness, the paper's Ke of eq. 4, swept directly by
  ``contact.stiffness`` and ``brick.stiffness_error``), with Hunt-Crossley dissipation and
  Coulomb friction, on a discrete plant (SAP's convex solver, "lagged" approximation).
  docs/evidence/grasp.md gives the measurements behind the choice (time per simulated second, force
  ripple, Linearize).
* Every controller and the sensors' ADC are sampled at the plant's time step.
* Each finger's task space is (x, y) of its tip sphere's centre in a frame C fixed at the
  planned face it touches: x along the face's inward normal (the force axis), y along the
  face in the hand's plane. The plan presses each planned face by Fr / contact.stiffness:
  the paper's eq. 6 (the fixed reference) on the planned brick, where position-only fingers
  press it with Fr once their PID's integral has brought the tips there.

The plan knows the brick only as planned: its size is the real one (Drake's model) minus
``brick.size_error``, its contact stiffness ``contact.stiffness`` (the real one is that
times ``brick.stiffness_error``). At t = 0 the brick rests on finger3 (below it), in
equilibrium under its weight; finger1 and finger2 are open by ``plan.open_distance``. They
close on the planned faces over ``plan.close_time``; then every desired force ramps from
what the finger reads at t = 0 to its Fr over ``plan.force_ramp_time``, and the plan
presses each face over the same interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    Box,
    ProximityProperties,
    Role,
    RoleAssign,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import FixedOffsetFrame
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.description import ForcePoint, force_law, sensor_chain
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS, GraspScenario

__all__ = [
    "BRICK_BODY",
    "BRICK_JOINTS",
    "BRICK_URL",
    "FINGER_COORDINATES",
    "GRIPPER_URL",
    "AddHand",
    "HandGeometry",
    "contact_frame",
    "finger_points",
    "tip_centre_frame",
    "tip_link",
]

GRIPPER_URL = "package://drake/examples/planar_gripper/planar_gripper.sdf"
BRICK_URL = "package://drake/examples/planar_gripper/planar_brick.sdf"
# Drake's finger layout (examples/planar_gripper, WeldGripperFrames): each finger's base is
# welded this far from the gripper's origin, rotated about world x from +z by these angles
# (finger1 and finger2 above the brick on either side, finger3 below it).
BASE_DISTANCE = 0.201  # m
BASE_ANGLES = (math.pi / 3.0, -math.pi / 3.0, math.pi)  # rad
# Elbow branch of each finger's inverse kinematics: the elbow bends away from the brick,
# so link 2 reaches its face along the normal and clears the brick's corners.
JOINT_SEEDS = ((-0.5, 1.0), (0.5, -1.0), (0.5, -1.0))
# The task coordinates of a finger: its tip's (normal, tangent) position in frame C.
FINGER_COORDINATES = ("x", "y")
# The force-controlled axis: the face normal, x of C.
NORMAL_AXIS = 0
GRAVITY = 9.81  # m/s^2, Drake's default, along world -z
# With time_step = 0: the sensor noise's sampling period and the logging period, s.
CONTINUOUS_NOISE_PERIOD = 1e-3


def tip_link(finger: str) -> str:
    return f"{finger}_tip_link"


def tip_centre_frame(finger: str) -> str:
    return f"{finger}_tip_centre"


def contact_frame(finger: str) -> str:
    return f"{finger}_contact_frame"


BRICK_BODY = "brick_link"
BRICK_JOINTS = ("brick_translate_y_joint", "brick_translate_z_joint", "brick_revolute_x_joint")


@dataclass
class HandGeometry:
    """What the builder reads from Drake's models and what the plan assumes."""

    # Radius of the fingertip spheres and their centre in the tip link, m.
    tip_radius: float
    tip_offset: np.ndarray
    # The real brick's edges in the hand's plane (world y, world z), m.
    brick_size: np.ndarray
    # The planned brick's edges (real minus brick.size_error), m.
    planned_size: np.ndarray
    # X_WC of each finger's face frame C (origin on the planned face, x its inward normal).
    face_frames: list[RigidTransform]
    # The brick's mass, kg.
    brick_mass: float


def _contact_properties(scenario: GraspScenario) -> ProximityProperties:
    """The point-contact material of every fingertip and of the brick.

    Drake combines two geometries' point stiffnesses in series and their dissipations and
    friction coefficients as weighted means; giving both sides 2 k, d and mu makes the pair's
    stiffness k, dissipation d and friction mu.
    """
    properties = ProximityProperties()
    friction = scenario.contact.friction
    AddContactMaterial(
        dissipation=scenario.contact.dissipation,
        point_stiffness=2.0 * scenario.true_contact_stiffness,
        friction=CoulombFriction(friction, friction),
        properties=properties,
    )
    return properties


def _read_geometry(plant, scene_graph) -> tuple[float, np.ndarray, np.ndarray]:
    """(tip radius, tip sphere centre in the tip link, brick edges in y-z) from the models."""
    inspector = scene_graph.model_inspector()
    radius, offset, size = None, None, None
    tip_frame_id = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(tip_link(FINGERS[0])).index())
    brick_frame_id = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(BRICK_BODY).index())
    for geometry in inspector.GetGeometries(tip_frame_id, Role.kProximity):
        shape = inspector.GetShape(geometry)
        if isinstance(shape, Sphere):
            radius = shape.radius()
            offset = inspector.GetPoseInFrame(geometry).translation()
    for geometry in inspector.GetGeometries(brick_frame_id, Role.kProximity):
        shape = inspector.GetShape(geometry)
        if isinstance(shape, Box):
            size = np.array([shape.depth(), shape.height()])  # along y and z
    if radius is None or size is None:  # pragma: no cover (Drake's models have both)
        raise RuntimeError("the planar gripper model has no tip sphere or no brick box")
    return radius, offset, size


def _face_frames(scenario: GraspScenario, planned_size: np.ndarray) -> list[RigidTransform]:
    """X_WC per finger: origin on the planned face, x its inward normal, y along the face.

    The planned brick's centre is the world origin (where Drake's brick_base is welded).
    """
    half_width, half_height = 0.5 * planned_size
    height = scenario.plan.side_contact_height
    unit_x, unit_y, unit_z = np.eye(3)
    faces = (
        ([0.0, -half_width, height], unit_y, unit_z),  # finger1: left face, normal +y
        ([0.0, half_width, height], -unit_y, unit_z),  # finger2: right face, normal -y
        ([0.0, 0.0, -half_height], unit_z, unit_y),  # finger3: bottom face, normal +z
    )
    frames = []
    for origin, normal, tangent in faces:
        rotation = RotationMatrix(np.column_stack([normal, tangent, np.cross(normal, tangent)]))
        frames.append(RigidTransform(rotation, origin))
    return frames


def AddHand(builder: DiagramBuilder, scenario: GraspScenario):
    """Adds the gripper and the brick as a discrete plant with point contact.

    Returns:
        (plant, scene_graph, geometry), the plant finalized.
    """
    config = MultibodyPlantConfig(
        time_step=scenario.time_step,
        contact_model="point",
        discrete_contact_approximation="lagged" if scenario.time_step > 0 else "",
        stiction_tolerance=scenario.contact.stiction_tolerance,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    parser = Parser(plant)
    parser.AddModelsFromUrl(GRIPPER_URL)
    parser.AddModelsFromUrl(BRICK_URL)
    for finger, angle in zip(FINGERS, BASE_ANGLES, strict=True):
        X_WB = RigidTransform(RotationMatrix.MakeXRotation(angle)) @ RigidTransform(
            [0.0, 0.0, BASE_DISTANCE]
        )
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(f"{finger}_base"), X_WB)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("brick_base"))

    radius, offset, size = _read_geometry(plant, scene_graph)
    planned = size - scenario.brick.size_error
    frames = _face_frames(scenario, planned)
    for finger, X_WC in zip(FINGERS, frames, strict=True):
        plant.AddFrame(
            FixedOffsetFrame(
                tip_centre_frame(finger),
                plant.GetFrameByName(tip_link(finger)),
                RigidTransform(offset),
            )
        )
        plant.AddFrame(FixedOffsetFrame(contact_frame(finger), plant.world_frame(), X_WC))

    # One contact material for every collision geometry of the hand and the brick.
    properties = _contact_properties(scenario)
    inspector = scene_graph.model_inspector()
    for geometry in inspector.GetAllGeometryIds(Role.kProximity):
        scene_graph.AssignRole(plant.get_source_id(), geometry, properties, RoleAssign.kReplace)
    plant.Finalize()
    brick_mass = plant.GetBodyByName(BRICK_BODY).default_mass()
    geometry = HandGeometry(
        tip_radius=radius,
        tip_offset=offset,
        brick_size=size,
        planned_size=planned,
        face_frames=frames,
        brick_mass=brick_mass,
    )
    return plant, scene_graph, geometry


def finger_points(scenario: GraspScenario) -> list[ForcePoint]:
    """The hand's force-controlled points: each fingertip's centre, X = (x, y) in a frame at
    its planned face (x along the face's normal, into the brick), force along x, with the
    scenario's sensor (read at time_step), the paper's law (or none) and the PID."""
    period = scenario.time_step
    sensor, admittance, pid = scenario.sensor, scenario.admittance, scenario.pid
    return [
        ForcePoint(
            name=finger,
            frame=tip_centre_frame(finger),
            coordinates=FINGER_COORDINATES,
            expressed_in=contact_frame(finger),
            force_axes=(NORMAL_AXIS,),
            sensor=sensor_chain(
                sensor, noise_period=period or CONTINUOUS_NOISE_PERIOD, period=period
            ),
            law=force_law(scenario.controller.kind, admittance, period=period),
            kp=list(pid.kp),
            kd=list(pid.kd),
            ki=list(pid.ki),
            pid_period=period,
        )
        for finger in FINGERS
    ]
