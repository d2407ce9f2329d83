"""Sensor faults that keep the sensor's noise, while the wall recedes (docs/evidence/safety.md
section 3): safe_contact (the moving-wall arm, FlexiForce noise 0.02 N, Fr = 5 N,
Fmax = 10 N, the wall receding at 5 mm/s from 2.5 s).

A dropout to 0 N plus the noise is neither stuck (the reading changes) nor hidden by the
plausibility allowance: a tip that follows the wall at a constant force moves without
changing the observer's estimate, so the allowance stays F_tol plus the noise's rate. It
is flagged implausible at the third sample of evidence after the onset sample, within the
detector's delay 4 T = 20 ms, and the force stays under Fmax. Without a fault nothing is
flagged (a false detection would freeze the law).
"""

from __future__ import annotations

import pytest

from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.scenario.files import load_scenario

FMAX = 10.0
ONSET = 3.0


def _safe_contact(duration: float, faults: str = "[]"):
    return run_scenario(load_scenario("safe_contact", [f"duration={duration}", f"faults={faults}"]))


@pytest.fixture(scope="module")
def noisy_dropout():
    """0 N plus the noise from 3 s (the wall receding since 2.5 s), 0.3 s of it."""
    return _safe_contact(
        ONSET + 0.3,
        f"[{{kind: sensor_zero, start: {ONSET}, end: {ONSET + 1.0}, noisy: true}}]",
    )


def test_a_noisy_dropout_on_a_receding_wall_is_caught_within_the_delay(noisy_dropout):
    """The onset sample's own change (5 N in 5 ms, 10 N of allowance) hides it; the next
    three are evidence: at most 4 T = 20 ms after the onset (measured 16.3 ms), against
    587 ms with the allowance of the tip's speed (k_hat |x'| / K_o = 8.9 N)."""
    (fault,) = noisy_dropout.metrics["faults"]
    assert fault["detected_kind"] == "implausible"
    assert 0.0 < fault["detection_delay"] <= 0.02
    assert noisy_dropout.metrics["safety"]["detections"][0]["time"] == pytest.approx(
        ONSET + fault["detection_delay"]
    )
    assert noisy_dropout.metrics["peak_force"] <= FMAX  # measured 6.92 N


def test_without_a_fault_the_receding_wall_raises_nothing():
    """The whole contact up to 4 s: 1.5 s against the receding wall, no flag."""
    result = _safe_contact(4.0)
    assert result.metrics["safety"]["detections"] == []
    assert result.metrics["peak_force"] <= FMAX
