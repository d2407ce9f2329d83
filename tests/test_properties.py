"""Property-based tests over scenario values, with hypothesis.

Every generated scenario either fails validation with one clear line that names the key,
or runs to its end with finite numbers. Values are drawn from the engineer's plausible
range of each key and, with some probability, from outside it (zero, negative, NaN,
infinite, absurdly large, wrong type). The runs are short (0.3 s, first contact and the
first force transient) so that the default suite stays in budget; the search is
derandomized so that CI is reproducible.
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from admittance.diagrams.scenario import ScenarioError, load_scenario
from admittance.diagrams.simulation import run_scenario

BAD = st.sampled_from([0.0, -1.0, math.nan, math.inf, -math.inf, 1e300, "abc"])

# key -> (plausible values, whether a bad value must be rejected)
PLAUSIBLE = {
    "force_reference": st.floats(1.0, 20.0),
    "wall.stiffness": st.floats(1e3, 1e6),
    "wall.position": st.floats(0.195, 0.205),
    "admittance.gamma": st.floats(1e-7, 1e-4),
    "admittance.alpha": st.floats(0.0, 0.5),
    "sensor.noise_std": st.floats(0.0, 0.2),
    "sensor.filter_cutoff": st.floats(3000.0, 20000.0),
    "sensor.kind": st.sampled_from(["ideal", "flexiforce"]),
    "seed": st.integers(0, 2**31 - 1),
}


def _value_text(value) -> str:
    if isinstance(value, float):
        return (
            repr(value)
            if math.isfinite(value)
            else {math.inf: ".inf", -math.inf: "-.inf"}.get(value, "nan")
        )
    return str(value)


@st.composite
def overrides(draw):
    chosen = {}
    keys = draw(st.lists(st.sampled_from(sorted(PLAUSIBLE)), min_size=1, max_size=4, unique=True))
    for key in keys:
        use_bad = draw(st.booleans()) and key not in ("sensor.kind", "seed")
        value = draw(BAD) if use_bad else draw(PLAUSIBLE[key])
        chosen[key] = value
    return chosen


@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(overrides())
def test_every_scenario_is_rejected_clearly_or_runs_finite(chosen):
    texts = [f"{key}={_value_text(value)}" for key, value in chosen.items()]
    try:
        scenario = load_scenario("paper_stiffness_step", ["duration=0.3", *texts])
    except ScenarioError as error:
        message = str(error)
        assert "\n" not in message and "Traceback" not in message
        # The message names one of the keys that were set (or the scenario as a whole).
        assert any(message.startswith(key) for key in chosen), message
        return
    result = run_scenario(scenario)
    assert result.time[-1] == pytest.approx(0.3)
    assert not result.metrics["failed"]
    for name, series in result.columns().items():
        assert np.all(np.isfinite(series)), name
    assert result.metrics["finite_actuation"]
    assert math.isfinite(result.metrics["peak_force"])
