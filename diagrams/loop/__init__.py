"""The loop of the paper's Fig. 1 as Drake Diagrams, the steps every robot shares: the
force-controlled point (plan, kinematics, contact, sensor, force controller, PID) and the
safety layer's systems. Each robot's builder is in its package (``robots.<name>.loop``)."""

from admittance.diagrams.loop.build import *  # noqa: F403
from admittance.diagrams.loop.layer_systems import *  # noqa: F403
from admittance.diagrams.loop.point import *  # noqa: F403
