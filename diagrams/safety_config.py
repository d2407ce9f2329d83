"""The scenario keys of the safety layer (docs/safety.md): the `safety` section.

Its own module so that diagrams/scenario.py stays one topic; the scenario's dataclasses
import it like their other sections.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

from dataclasses import dataclass

__all__ = ["SafetyConfig"]


@dataclass
class SafetyConfig:
    # The safety layer (docs/safety.md): a bounded approach, a stiffness-aware Gamma and a
    # sensor monitor around the paper's law; false = the paper's law as printed.
    enabled: bool = False
    # Ke_max, the stated upper bound on the wall's stiffness, N/m: it sets the approach
    # speed and the damping along the normal.
    max_stiffness: float = 1e6
    # The factor between the reduced model's critical Gamma and the scheduled Gamma.
    stability_margin: float = 3.0
    # Damping ratio of the contact mode at max_stiffness (a first contact bounces below 0.19).
    damping_ratio: float = 0.25
