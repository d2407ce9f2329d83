"""Property-based tests over scenario values, with hypothesis.

Every generated scenario either fails validation with one clear line that names the key,
or runs to its end with finite numbers; every generated file (a scenario, a damaged URDF),
integer and list entry either loads as written or fails with one line naming the file or
the key. Values are drawn from the engineer's plausible
range of each key and, with some probability, from outside it (zero, negative, NaN,
infinite, absurdly large, wrong type). The runs are short (0.3 s, first contact and the
first force transient) so that the default suite stays in budget; the search is
derandomized so that CI is reproducible.
"""

import json
import math

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.scenario.schema import ScenarioError, scenario_keys
from admittance.diagrams.scenario.sections import FAULT_KINDS, FAULT_KINDS_WITH_VALUE
from admittance.urdf import PLANAR_ARM_URDF

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


# --- files, integers and list entries ---------------------------------------------------
#
# Loading alone (no run): every generated input either loads or fails with one ScenarioError
# line that names the scenario file or the key; nothing else escapes (no TypeError from
# Drake, no OverflowError, no UnicodeDecodeError), and what loads is what was written.

LOADING = settings(max_examples=40, deadline=None, derandomize=True)
SCENARIO_KEYS = sorted(scenario_keys(Scenario))
ARM_URDF = PLANAR_ARM_URDF.read_text()


def _single_line(error: ScenarioError) -> str:
    message = str(error)
    assert message and "\n" not in message
    return message


yaml_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
yaml_values = st.recursive(
    yaml_scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=3),
        st.dictionaries(
            st.sampled_from([*SCENARIO_KEYS, "wall", "faults", "x"]), children, max_size=3
        ),
    ),
    max_leaves=8,
)


@LOADING
@given(
    document=st.one_of(
        st.binary(max_size=64),  # anything, not even text
        yaml_values.map(lambda value: json.dumps(value).encode()),  # JSON is YAML
        st.dictionaries(st.sampled_from(SCENARIO_KEYS), yaml_scalars, max_size=4).map(
            lambda keys: "\n".join(f"{k}: {json.dumps(v)}" for k, v in keys.items()).encode()
        ),
    )
)
def test_any_scenario_file_loads_or_fails_in_one_line(tmp_path_factory, document):
    path = tmp_path_factory.mktemp("scenario") / "mine.yaml"
    path.write_bytes(document)
    try:
        load_scenario(path)
        # Loaded: UTF-8 text holding a mapping, written out ({} for every default; an
        # empty file is not taken for it).
        data = yaml.safe_load(document.decode("utf-8"))
        assert isinstance(data, dict) and (data or document.strip() == b"{}"), document
    except ScenarioError as error:
        message = _single_line(error)
        # The file itself, or a key inside it (dotted, maybe with a list index).
        assert message.startswith(f"scenario: {path}") or message.split(":")[0].split("[")[0].split(
            "."
        )[0] in {key.split(".")[0] for key in SCENARIO_KEYS}, message


@LOADING
@given(
    cut=st.integers(0, len(ARM_URDF)),
    noise=st.binary(max_size=16),
)
def test_any_damaged_urdf_is_refused_in_one_line_or_builds(tmp_path_factory, cut, noise):
    """The arm's URDF cut short and followed by junk: refused naming arm.urdf (or the
    fingertip frame that went missing), or, when the damage missed the model, it loads."""
    folder = tmp_path_factory.mktemp("urdf")
    (folder / "arm.urdf").write_bytes(ARM_URDF[:cut].encode() + noise)
    try:
        scenario = load_scenario(None, {"arm.urdf": str(folder / "arm.urdf")})
    except ScenarioError as error:
        assert _single_line(error).startswith(("arm.urdf: ", "arm.fingertip_frame: "))
        return
    assert scenario.arm.urdf_path() == folder / "arm.urdf"
    AddScenarioArm(DiagramBuilder(), scenario.arm)  # what loads, builds


@LOADING
@given(
    seed=st.one_of(
        st.integers(-(2**80), 2**80),
        st.integers(0, 2**32 - 1),
        # The edges: 32 bits, Drake's 64, and integers beyond any float.
        st.sampled_from([2**32 - 1, 2**32, 2**64 - 1, 2**64, 10**400, -(10**400)]),
    )
)
def test_any_integer_seed_is_kept_exactly_or_refused(seed):
    """Drake's RandomGenerator takes 32 bits: a larger seed would repeat a smaller one."""
    try:
        scenario = load_scenario("paper_stiffness_step", [f"seed={seed}"])
    except ScenarioError as error:
        assert _single_line(error).startswith("seed: must be in [0, 4294967295]")
        assert not 0 <= seed < 2**32
        return
    assert 0 <= seed < 2**32 and scenario.seed == seed  # exactly, not through a float


FAULT_FIELDS = ("kind", "start", "end", "value")
STEP_FIELDS = ("time", "stiffness")


@st.composite
def fault_entries(draw):
    kind = draw(st.sampled_from(sorted(FAULT_KINDS)))
    entry = {"kind": kind, "start": 0.5, "end": 0.8, "value": 1.0e4}
    given = draw(st.lists(st.sampled_from(FAULT_FIELDS), unique=True, max_size=4))
    return {name: entry[name] for name in given}


@st.composite
def step_entries(draw):
    entry = {"time": 0.5, "stiffness": 8.0e4}
    given = draw(st.lists(st.sampled_from(STEP_FIELDS), unique=True, max_size=2))
    return {name: entry[name] for name in given}


@LOADING
@given(faults=st.lists(fault_entries(), max_size=2), steps=st.lists(step_entries(), max_size=2))
def test_a_list_entry_with_a_field_left_out_is_refused_naming_it(faults, steps):
    """No field of a fault or a stiffness step is filled in silently by a default."""
    overrides = {"faults": faults, "wall.stiffness_steps": steps}
    try:
        scenario = load_scenario("paper_stiffness_step", overrides)
    except ScenarioError as error:
        message = _single_line(error)
        key, problem = message.split(": ", 1)
        if problem.startswith("missing"):
            section, index, name = (
                key.replace("]", "").replace("[", " ").replace(".", " ").rsplit(" ", 2)[-3:]
            )
            entries = faults if key.startswith("faults") else steps
            assert name not in entries[int(index)], message
        else:  # every field given, and a value out of range (two faults overlapping, ...)
            assert key.startswith(("faults", "wall.stiffness_steps")), message
        return
    for loaded, entry in zip(scenario.faults, faults, strict=True):
        required = ["kind", "start", "end"]
        if entry["kind"] in FAULT_KINDS_WITH_VALUE:
            required.append("value")
        assert all(name in entry for name in required)
        assert all(getattr(loaded, name) == entry[name] for name in entry)
    for loaded, entry in zip(scenario.wall.stiffness_steps, steps, strict=True):
        assert set(entry) == set(STEP_FIELDS)
        assert (loaded.time, loaded.stiffness) == (entry["time"], entry["stiffness"])
