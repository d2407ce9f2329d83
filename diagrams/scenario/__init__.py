"""Scenarios: typed YAML descriptions of one run, for every robot.

* :mod:`.schema`: the typed-tree machinery every scenario kind uses (keys, types, overrides,
  the one-line ``ScenarioError``);
* :mod:`.sections`: the sections every robot shares, declared once;
* :mod:`.planar_arm`, :mod:`.planar_gripper` and :mod:`.spatial_arm`: each robot's schema
  and its checks;
* :mod:`.validation`: ranges and the checks that relate keys;
* :mod:`.files`: the built-in scenarios and ``load_scenario``.
"""

from admittance.diagrams.scenario.files import *  # noqa: F403
from admittance.diagrams.scenario.planar_arm import *  # noqa: F403
from admittance.diagrams.scenario.planar_gripper import *  # noqa: F403
from admittance.diagrams.scenario.schema import *  # noqa: F403
from admittance.diagrams.scenario.sections import *  # noqa: F403
from admittance.diagrams.scenario.spatial_arm import *  # noqa: F403
from admittance.diagrams.scenario.validation import *  # noqa: F403
