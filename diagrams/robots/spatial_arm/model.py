"""A serial arm's published description loaded into a plant: where the model comes from,
its text made parseable, its frames, and its joints made actuated or rigid.

* **the source**: a URDF or SDF file, or a ``package://`` URL; example-robot-data's
  packages (``panda_description``, ``ur_description``) are registered in Drake's package
  map when the optional extra ``robots`` is installed;
* **the text**: the model is parsed from its text without its collision elements (only the
  tool and the table collide; Drake refuses the published arms' STL collision meshes) and
  without ROS's ``safety_controller`` tags, its relative mesh names made absolute;
* **the joints**: its base welded to the world at ``arm.base_position``; one actuator per
  joint that moves the flange, where the description has none (the Panda's URDF has no
  ``transmission``), with the effort limit of its ``<limit effort>``; the joints that do
  not move the flange and have no actuator (the Panda's fingers) become welds at their zero
  position.

The plant that holds it (tool, table, control frame) is :mod:`.plant`'s.
"""

from __future__ import annotations

import importlib.metadata
import math
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FrameIndex, WeldJoint

from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.scenario.schema import ScenarioError

__all__ = [
    "ROBOTS_EXTRA",
    "example_robot_data_packages",
    "frame_names",
    "load_arm",
]

# The optional extra that brings example-robot-data, and the packages it registers.
ROBOTS_EXTRA = 'pip install "optimal-admittance[robots]"'
EXAMPLE_ROBOT_DATA = "example-robot-data"
EXAMPLE_ROBOT_PACKAGES = ("panda_description", "ur_description")


def example_robot_data_packages() -> dict[str, Path] | None:
    """{package name: folder} of example-robot-data's descriptions, None if not installed.

    The distribution (a cmeel package) installs its robots under
    ``cmeel.prefix/share/example-robot-data/robots`` in site-packages; their meshes are
    named from the package ``example-robot-data`` itself (its share folder).
    """
    try:
        distribution = importlib.metadata.distribution(EXAMPLE_ROBOT_DATA)
    except importlib.metadata.PackageNotFoundError:
        return None
    root = Path(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not root.is_dir():
        return None
    packages = {name: root / name for name in EXAMPLE_ROBOT_PACKAGES if (root / name).is_dir()}
    packages[EXAMPLE_ROBOT_DATA] = root.parent
    return packages


def _model_source(scenario: SpatialScenario) -> tuple[str, dict[str, Path]]:
    """The model's URL or file path, and the packages to register; one-line errors."""
    url = scenario.arm.urdf
    packages = example_robot_data_packages() or {}
    if url.startswith("package://"):
        package = url[len("package://") :].split("/", 1)[0]
        if package in EXAMPLE_ROBOT_PACKAGES and package not in packages:
            raise ScenarioError(
                f"arm.urdf: {url} comes from example-robot-data, which is not installed: "
                f"{ROBOTS_EXTRA}"
            )
        return url, packages
    path = Path(url).expanduser()
    if not path.is_file():
        raise ScenarioError(f"arm.urdf: must be an existing URDF or SDF file, got {url!r}")
    return str(path.resolve()), packages


def _efforts_from_file(path: Path) -> dict[str, float]:
    """{joint name: effort limit} from a URDF's ``<limit effort>`` or an SDF's ``<effort>``."""
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError):
        return {}
    efforts = {}
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        if limit is None:
            limit = joint.find("axis/limit")
        if limit is None:
            continue
        text = limit.get("effort") or (limit.findtext("effort") or "")
        try:
            value = float(text)
        except ValueError:
            continue
        if value > 0 and math.isfinite(value):
            efforts[joint.get("name")] = value
    return efforts


_COLLISION = re.compile(r"<collision\b[^>]*?/>|<collision\b.*?</collision>", re.DOTALL)
# ROS's soft joint limits (the Panda's), which Drake does not read and warns about.
_SAFETY_CONTROLLER = re.compile(
    r"<safety_controller\b[^>]*?/>|<safety_controller\b.*?</safety_controller>", re.DOTALL
)
_MESH_FILE = re.compile(r'(filename\s*=\s*"|<uri>\s*)([^"<]+)')


def _without_collisions(file: Path) -> str:
    """The model file's text without its collision elements (and without ROS's
    ``safety_controller`` tags, which Drake ignores with a warning each), relative mesh names
    made absolute (the text is parsed from a string).

    Only the tool and the table collide here, and Drake refuses the published arms' STL
    collision meshes (it makes convex hulls of .obj, .vtk and .gltf only), so they are left
    out before parsing rather than removed after.
    """
    text = file.read_text(encoding="utf-8")
    folder = file.resolve().parent

    def absolute(match: re.Match) -> str:
        name = match.group(2).strip()
        if "://" in name or Path(name).is_absolute():
            return match.group(0)
        return match.group(1) + str(folder / name)

    text = _SAFETY_CONTROLLER.sub("", _COLLISION.sub("", text))
    return _MESH_FILE.sub(absolute, text)


# How many names an unknown-frame message lists of the links, and of the other frames.
SHOWN_LINKS = 40
SHOWN_OTHER_FRAMES = 10


def _listed(names: list[str], most: int) -> str:
    """`names` joined, whole names only: the first `most` and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def frame_names(plant: MultibodyPlant) -> tuple[list[str], list[str]]:
    """The names a frame key may take: the links (body frames), then the other frames
    (joint frames, frames the model adds), each sorted; the world and Drake's own
    ``_``-prefixed frames left out."""
    links, others = set(), set()
    for i in range(plant.num_frames()):
        frame = plant.get_frame(FrameIndex(i))
        name = frame.name()
        if not name or name.startswith("_") or name == "world":
            continue
        is_link = frame.index() == frame.body().body_frame().index()
        (links if is_link else others).add(name)
    return sorted(links), sorted(others - links)


def _frame(plant: MultibodyPlant, name: str, key: str):
    if not plant.HasFrameNamed(name):
        links, others = frame_names(plant)
        listed = f"its links: {_listed(links, SHOWN_LINKS)}"
        if others:
            listed += f"; its other frames: {_listed(others, SHOWN_OTHER_FRAMES)}"
        raise ScenarioError(f"{key}: the model has no frame named {name!r}; {listed}")
    return plant.GetFrameByName(name)


def _parse_model(plant: MultibodyPlant, scenario: SpatialScenario) -> Path:
    """Adds the model, without its collisions, to `plant`; returns its file."""
    source, packages = _model_source(scenario)
    parser = Parser(plant)
    for name, folder in packages.items():
        if not parser.package_map().Contains(name):
            parser.package_map().Add(name, str(folder))
    try:
        file = Path(parser.package_map().ResolveUrl(source)) if "://" in source else Path(source)
        parser.AddModelsFromString(_without_collisions(file), file.suffix.lstrip(".").lower())
    except (RuntimeError, OSError, UnicodeDecodeError) as error:
        first = str(error).strip().splitlines()[0] if str(error).strip() else "unreadable"
        raise ScenarioError(f"arm.urdf: Drake cannot read {source!r}: {first}") from None
    return file


def _weld_base(plant: MultibodyPlant, scenario: SpatialScenario, joints: list) -> set[str]:
    """Welds the base frame to the world; returns the names of the joints between the
    flange and the base (`joints` loses the description's own weld to the world)."""
    arm = scenario.arm
    base = _frame(plant, arm.base_frame, "arm.base_frame")
    flange = _frame(plant, arm.flange_frame, "arm.flange_frame")
    parent_joint = {joint.child_body().index(): joint for joint in joints}
    # The joints between the flange and the base (walked before any joint is removed: a
    # removed joint's Python handle points at freed memory).
    chain, body = set(), flange.body().index()
    while body in parent_joint and body not in (base.body().index(), plant.world_body().index()):
        chain.add(parent_joint[body].name())
        body = parent_joint[body].parent_body().index()
    existing = parent_joint.get(base.body().index())
    if existing is not None and existing.parent_body().index() == plant.world_body().index():
        # The description welds its base to its own "world" link (the UR5's): the
        # scenario's weld replaces it.
        joints.remove(existing)
        plant.RemoveJoint(existing)
    plant.WeldFrames(plant.world_frame(), base, RigidTransform(arm.base_position))
    return chain


def _actuate_chain(
    plant: MultibodyPlant, joints: list, chain: set[str], efforts: dict[str, float]
) -> list:
    """Gives each moving joint of the flange's chain without an actuator one (its effort
    limit from the description); returns the other moving joints without one."""
    actuated = {plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()}
    rigid = []
    for joint in joints:
        if joint.num_velocities() == 0 or joint.name() in actuated:
            continue
        if joint.name() in chain:
            if joint.num_velocities() != 1:
                raise ScenarioError(
                    f"arm.urdf: joint {joint.name()!r} moves the flange with "
                    f"{joint.num_velocities()} degrees of freedom; a serial arm's joints "
                    "have one"
                )
            effort = efforts.get(joint.name(), math.inf)
            plant.AddJointActuator(f"{joint.name()}_actuator", joint, effort)
            continue
        rigid.append(joint)
    return rigid


def _weld_rigid(plant: MultibodyPlant, rigid: list) -> None:
    """Replaces each of the `rigid` joints by a weld at its zero position."""
    if rigid:
        # The description's mimic couplers (the Panda's second finger follows the first)
        # go with the joints they couple: Drake removes a joint only from a plant without
        # constraints.
        for constraint in plant.GetConstraintIds():
            plant.RemoveConstraint(constraint)
    for joint in rigid:
        parent, child, name = joint.frame_on_parent(), joint.frame_on_child(), joint.name()
        plant.RemoveJoint(joint)
        plant.AddJoint(WeldJoint(f"{name}_weld", parent, child, RigidTransform()))


def load_arm(plant: MultibodyPlant, scenario: SpatialScenario) -> list[str]:
    """Parses the model, welds its base, makes its flange chain actuated and its other
    joints rigid; returns the actuated joints' names.

    Raises:
        ScenarioError: the model cannot be read, a frame is missing, an extra is missing,
            or no joint moves the flange.
    """
    file = _parse_model(plant, scenario)
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    chain = _weld_base(plant, scenario, joints)
    rigid = _actuate_chain(plant, joints, chain, _efforts_from_file(file))
    _weld_rigid(plant, rigid)
    names = [plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()]
    if not names:
        raise ScenarioError(
            f"arm.flange_frame: no joint moves {scenario.arm.flange_frame!r} (is it on the arm?)"
        )
    return names
