"""Analysis of a built loop: its equilibrium, Drake's Linearize, eigenvalues, Lyapunov
certificates, critical gains and stability maps."""

from admittance.diagrams.analysis.linearization import *  # noqa: F403
from admittance.diagrams.analysis.planar_gripper import *  # noqa: F403
from admittance.diagrams.analysis.safety_margins import *  # noqa: F403
from admittance.diagrams.analysis.sampled_gains import *  # noqa: F403
from admittance.diagrams.analysis.spatial_arm import *  # noqa: F403
from admittance.diagrams.analysis.spatial_step_map import *  # noqa: F403
from admittance.diagrams.analysis.stability import *  # noqa: F403
