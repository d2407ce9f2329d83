"""Analysis of a loop, whatever its robot: modes, Lyapunov certificates, critical gains,
and the paper's eq. 13 symbolically. Each robot's analysis is in its package."""

from admittance.diagrams.analysis.eq13 import *  # noqa: F403
from admittance.diagrams.analysis.linear import *  # noqa: F403
