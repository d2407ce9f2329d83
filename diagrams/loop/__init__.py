"""The loop of the paper's Fig. 1 as Drake Diagrams: plan, kinematics, contact, sensor,
force controller (or the safety layer) and PID, wired for each force-controlled point."""

from admittance.diagrams.loop.build import *  # noqa: F403
from admittance.diagrams.loop.layer_systems import *  # noqa: F403
from admittance.diagrams.loop.planar_arm import *  # noqa: F403
from admittance.diagrams.loop.planar_gripper import *  # noqa: F403
from admittance.diagrams.loop.point import *  # noqa: F403
from admittance.diagrams.loop.safety_layer import *  # noqa: F403
from admittance.diagrams.loop.spatial_arm import *  # noqa: F403
from admittance.diagrams.loop.spatial_safety import *  # noqa: F403
