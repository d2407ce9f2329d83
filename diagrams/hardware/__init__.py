"""The hardware split: a station that is (or simulates) the robot and a controller process
that knows it only through Drake's LCM driver messages (docs/evidence/hardware.md)."""

from admittance.diagrams.hardware.config import *  # noqa: F403
from admittance.diagrams.hardware.controller import *  # noqa: F403
from admittance.diagrams.hardware.interface import *  # noqa: F403
from admittance.diagrams.hardware.messages import *  # noqa: F403
from admittance.diagrams.hardware.pacer import *  # noqa: F403
from admittance.diagrams.hardware.sliders import *  # noqa: F403
from admittance.diagrams.hardware.station import *  # noqa: F403
from admittance.diagrams.hardware.timing import *  # noqa: F403
