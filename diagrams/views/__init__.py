"""Pictures of a run and of the loop: the figures and replay of any result, the machinery
of every Meshcat replay, the Graphviz diagram. Each robot's drawings are in its package."""

from admittance.diagrams.views.figures import *  # noqa: F403
from admittance.diagrams.views.picture import *  # noqa: F403
from admittance.diagrams.views.replay import *  # noqa: F403
