"""The robots: each one's plant (model files, gravity, time step), its actuated joints,
its force-controlled points and their frames, and its inverse kinematics."""

from admittance.diagrams.robots.description import *  # noqa: F403
from admittance.diagrams.robots.planar_arm import *  # noqa: F403
from admittance.diagrams.robots.planar_gripper import *  # noqa: F403
from admittance.diagrams.robots.spatial_arm import *  # noqa: F403
