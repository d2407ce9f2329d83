"""The law's parameters as Meshcat sliders on the station: Fr, Gamma, alpha and Fmax, each
published as the parameter message (``messages.encode_parameters``) when it moves, so the
controller takes it as it takes any other sender's (bumpless; refused with an event line
when out of bounds).

The station's Meshcat listens on localhost only (``MeshcatParams(host="localhost")``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydrake.geometry import Meshcat, MeshcatParams

from admittance.diagrams.hardware.messages import CHANNELS, encode_parameters

__all__ = ["ParameterSliders", "Slider", "station_meshcat"]


@dataclass(frozen=True)
class Slider:
    # The parameter message's key and the slider's label.
    key: str
    label: str
    low: float
    high: float
    step: float


def station_meshcat() -> Meshcat:
    """A Meshcat server on localhost (never on the machine's other interfaces)."""
    return Meshcat(MeshcatParams(host="localhost"))


class ParameterSliders:
    """The four sliders on `meshcat`, at the scenario's values (`force_reference`, `gamma`,
    `alpha`; `max_force` at the slider's top when it is infinite: moving it sets a bound);
    :meth:`poll` publishes the values that moved since the last poll on `lcm`."""

    def __init__(self, meshcat: Meshcat, lcm, *, force_reference, gamma, alpha, max_force):
        self.meshcat = meshcat
        self._lcm = lcm
        top_force = max(100.0, 5.0 * force_reference)
        self.sliders = (
            Slider("force_reference", "Fr (N)", 0.5, top_force, 0.1),
            Slider("gamma", "Gamma (m/(N s) per N/m)", 1e-7, 5e-5, 1e-7),
            Slider("alpha", "alpha (s)", 0.0, 0.1, 1e-3),
            Slider("max_force", "Fmax (N)", 1.0, top_force, 0.5),
        )
        initial = {
            "force_reference": force_reference,
            "gamma": gamma,
            "alpha": alpha,
            "max_force": max_force if math.isfinite(max_force) else top_force,
        }
        self.values = {}
        for slider in self.sliders:
            self.values[slider.key] = meshcat.AddSlider(
                slider.label, slider.low, slider.high, slider.step, initial[slider.key]
            )
        self.published: list[dict] = []

    def label(self, key: str) -> str:
        return next(s.label for s in self.sliders if s.key == key)

    def poll(self) -> dict:
        """Publishes the sliders' values that changed (one message); returns them."""
        changed = {}
        for slider in self.sliders:
            value = self.meshcat.GetSliderValue(slider.label)
            if value != self.values[slider.key]:
                changed[slider.key] = value
                self.values[slider.key] = value
        if changed:
            self._lcm.Publish(CHANNELS.parameters, encode_parameters(**changed))
            self.published.append(changed)
        return changed
