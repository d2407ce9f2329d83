"""Pictures of a run and of the loop: figures, Meshcat replays, the Graphviz diagram."""

from admittance.diagrams.views.figures import *  # noqa: F403
from admittance.diagrams.views.gripper_plots import *  # noqa: F403
from admittance.diagrams.views.gripper_replay import *  # noqa: F403
from admittance.diagrams.views.picture import *  # noqa: F403
from admittance.diagrams.views.plots import *  # noqa: F403
from admittance.diagrams.views.replay import *  # noqa: F403
from admittance.diagrams.views.spatial_arm import *  # noqa: F403
from admittance.diagrams.views.spatial_replay import *  # noqa: F403
