"""Scenarios: typed YAML descriptions of one run, the machinery every robot's uses.

* :mod:`.schema`: the typed-tree machinery every scenario kind uses (keys, types, overrides,
  the one-line ``ScenarioError``);
* :mod:`.sections`: the sections every robot shares, declared once;
* :mod:`.ranges`: the allowed values of the shared keys and the one-line checks;
* :mod:`.files`: the built-in scenarios and ``load_scenario``.

Each robot's own sections and checks are in its package (``robots.<name>.scenario``).
"""

from admittance.diagrams.scenario.files import *  # noqa: F403
from admittance.diagrams.scenario.ranges import *  # noqa: F403
from admittance.diagrams.scenario.schema import *  # noqa: F403
from admittance.diagrams.scenario.sections import *  # noqa: F403
