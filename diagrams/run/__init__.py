"""Running a built loop headless, for every robot: the one run path, the shared metrics
and the safety layer's, the profiler, and ``simulate``."""

from admittance.diagrams.run.engine import *  # noqa: F403
from admittance.diagrams.run.metrics import *  # noqa: F403
from admittance.diagrams.run.profiling import *  # noqa: F403
from admittance.diagrams.run.safety_metrics import *  # noqa: F403
from admittance.diagrams.run.simulation import *  # noqa: F403
