"""The Franka Panda of example-robot-data, a welded tool with a spherical tip and a table:
the robot the station simulates and the model the controller's kinematics read.

The Panda's URDF (with its identified inertias) comes from the ``example-robot-data``
distribution, found through its package; nothing is copied into the repository. Drake makes
no actuators from it (the file has no ``transmission`` elements), so one is added per arm
joint with the URDF's effort limit. The hand's finger joints are welded (the tool replaces
the gripper), the meshes are left out (only the tool's tip and the table collide), which
leaves the seven arm joints. The wrist's force/torque sensor frame is the tool's body frame,
at the hand's tool-centre point ``panda_hand_tcp``.

This module is the station's stand-in for the spatial arm's plant builder; when the spatial
scenario lands, ``AddPandaStation`` gives way to it.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import AddContactMaterial, Box, ProximityProperties, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import SpatialInertia, UnitInertia

__all__ = [
    "PANDA_HOME",
    "PandaModel",
    "AddPanda",
    "panda_urdf_path",
    "panda_urdf_text",
]

NUM_JOINTS = 7
# A posture above the table with the hand pointing down (rad).
PANDA_HOME = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.785])
# The tool: a stem from the hand's tool-centre point along its z axis, ending in a sphere.
TOOL_LENGTH = 0.04  # m, sensor frame to the tip sphere's centre
TOOL_RADIUS = 0.01  # m, the tip sphere
TOOL_MASS = 0.1  # kg


def panda_urdf_path() -> Path:
    """The Panda's URDF in the installed example-robot-data distribution.

    Raises:
        FileNotFoundError: one line naming the missing distribution.
    """
    spec = importlib.util.find_spec("cmeel")
    roots = []
    if spec is not None and spec.origin is not None:
        roots.append(Path(spec.origin).resolve().parents[1] / "cmeel.prefix")
    import site

    roots += [Path(p) / "cmeel.prefix" for p in site.getsitepackages()]
    for root in roots:
        path = root / "share/example-robot-data/robots/panda_description/urdf/panda.urdf"
        if path.is_file():
            return path
    raise FileNotFoundError(
        'the Panda\'s URDF was not found: pip install "optimal-admittance[robots]" (the '
        "example-robot-data distribution ships robots/panda_description/urdf/panda.urdf)"
    )


def panda_urdf_text(path: Path | None = None) -> str:
    """The Panda's URDF with the fingers welded and the meshes left out (7 joints)."""
    root = ElementTree.parse(path or panda_urdf_path()).getroot()
    for link in root.findall("link"):
        for child in list(link):
            if child.tag in ("visual", "collision"):
                link.remove(child)
    for joint in root.findall("joint"):
        for child in joint.findall("safety_controller"):
            joint.remove(child)
        if joint.get("name", "").startswith("panda_finger_joint"):
            joint.set("type", "fixed")
            for child in list(joint):
                if child.tag in ("limit", "axis", "mimic", "dynamics", "safety_controller"):
                    joint.remove(child)
    return ElementTree.tostring(root, encoding="unicode")


@dataclass
class PandaModel:
    """What the station and the controller need to find in a plant holding the Panda."""

    plant: MultibodyPlant
    # The tool's body: its frame is the wrist sensor's frame S.
    tool: object
    # The tool tip's centre T, fixed in S (p_ST).
    p_ST: np.ndarray  # noqa: N815 (monogram notation)
    effort_limits: np.ndarray


def _proximity(stiffness: float, dissipation: float) -> ProximityProperties:
    properties = ProximityProperties()
    AddContactMaterial(
        dissipation=dissipation,
        point_stiffness=stiffness,
        friction=CoulombFriction(0.3, 0.3),
        properties=properties,
    )
    return properties


def AddPanda(
    plant: MultibodyPlant,
    *,
    table_height: float | None = None,
    contact_stiffness: float = 2.0e4,
    contact_dissipation: float = 20.0,
) -> PandaModel:
    """Adds the Panda (base welded to the world), its tool and, if `table_height` is given,
    a table whose top is at that height. The plant is left unfinalized; a plant without a
    SceneGraph gets no collision geometry (a model for kinematics and dynamics)."""
    parser = Parser(plant)
    (instance,) = parser.AddModelsFromString(panda_urdf_text(), "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0", instance))
    limits = []
    for i in range(1, NUM_JOINTS + 1):
        joint = plant.GetJointByName(f"panda_joint{i}", instance)
        limits.append(_effort_limit(i))
        plant.AddJointActuator(f"panda_joint{i}", joint, limits[-1])
    tool = plant.AddRigidBody(
        "tool",
        instance,
        SpatialInertia.MakeFromCentralInertia(
            TOOL_MASS, [0, 0, TOOL_LENGTH / 2], UnitInertia.SolidSphere(TOOL_RADIUS) * TOOL_MASS
        ),
    )
    plant.WeldFrames(plant.GetFrameByName("panda_hand_tcp", instance), tool.body_frame())
    p_ST = np.array([0.0, 0.0, TOOL_LENGTH])
    model = PandaModel(plant=plant, tool=tool, p_ST=p_ST, effort_limits=np.array(limits))
    if not plant.geometry_source_is_registered():  # a model for kinematics and dynamics
        return model
    properties = _proximity(contact_stiffness, contact_dissipation)
    plant.RegisterCollisionGeometry(
        tool, RigidTransform(p_ST), Sphere(TOOL_RADIUS), "tool_tip", properties
    )
    if table_height is not None:
        size = (1.0, 1.0, 0.1)
        X_WTable = RigidTransform([0.5, 0.0, table_height - size[2] / 2])
        plant.RegisterCollisionGeometry(
            plant.world_body(), X_WTable, Box(*size), "table", properties
        )
    return model


def _effort_limit(joint: int) -> float:
    """The Panda's joint torque limits (N m): 87 on joints 1-4, 12 on joints 5-7."""
    return 87.0 if joint <= 4 else 12.0
