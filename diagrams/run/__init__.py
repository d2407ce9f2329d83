"""Running a built loop headless: the simulation, its time series as plain arrays, and
its metrics."""

from admittance.diagrams.run.engine import *  # noqa: F403
from admittance.diagrams.run.metrics import *  # noqa: F403
from admittance.diagrams.run.planar_arm import *  # noqa: F403
from admittance.diagrams.run.planar_gripper import *  # noqa: F403
from admittance.diagrams.run.simulation import *  # noqa: F403
from admittance.diagrams.run.spatial_arm import *  # noqa: F403
