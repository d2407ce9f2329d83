"""Scenarios: typed YAML descriptions of one closed-loop run (README.md, "Scenarios").

A scenario is a tree of dataclasses loaded with Drake's ``yaml_load_typed``. Every field has
a default equal to the paper's value (Section VII-A); the built-in scenarios in
``diagrams/scenarios/`` override what differs. ``--set key=value`` overrides use the dotted
key of a field (``wall.stiffness``, ``admittance.gamma``, ...).

Every problem with user input raises ``ScenarioError`` with one line that names the key and
what is allowed; nothing deeper than this module sees unvalidated values.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import copy
import dataclasses
import functools
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

import yaml  # PyYAML, which pydrake.common.yaml is built on
from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed
from pydrake.systems.analysis import SimulatorConfig

from admittance.diagrams.key_hints import unknown_key_hint
from admittance.diagrams.safety_config import SafetyConfig
from admittance.urdf import URDF_DIR

__all__ = [
    "AdmittanceConfig",
    "ArmConfig",
    "CONTROLLER_KINDS",
    "ControllerConfig",
    "FAULT_KINDS",
    "FaultConfig",
    "LoggingConfig",
    "PidConfig",
    "Scenario",
    "SafetyConfig",
    "ScenarioError",
    "SensorConfig",
    "StiffnessStep",
    "TrajectoryConfig",
    "WallConfig",
    "builtin_scenario_names",
    "load_scenario",
    "scenario_to_yaml",
]

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
# A scenario file's top-level `kind`: absent or "arm" for the arm against its wall (the
# schema below), "grasp" for the planar gripper (diagrams/grasp_scenario.py).
SCENARIO_KINDS = ("arm", "grasp")


class ScenarioError(ValueError):
    """A scenario key has a missing, unknown, mistyped or impossible value."""


def _default_simulator_config() -> SimulatorConfig:
    # The loop is stiff (wall up to 1e5 N/m, Kd = 5 on a light last link: a pole near
    # -1e4 1/s); an implicit integrator with error control takes a few hundred steps where
    # an explicit one takes ~150,000. See docs/speed.md, "Integrator".
    return SimulatorConfig(
        integration_scheme="radau3",
        accuracy=1e-4,
        max_step_size=0.05,
        use_error_control=True,
    )


@dataclass
class StiffnessStep:
    # Time at which the wall stiffness jumps, s.
    time: float = 15.0
    # Wall stiffness from that time on, N/m.
    stiffness: float = 1e5


@dataclass
class WallConfig:
    # Xe at t = 0: the undeformed wall surface along world x, m.
    position: float = 0.20
    # Ke at t = 0: equivalent stiffness of wall, fingertip and sensor, N/m.
    stiffness: float = 5e4
    # Stiffness jumps (Section VII-A: Ke doubles at t = 15 s).
    stiffness_steps: list[StiffnessStep] = field(default_factory=lambda: [StiffnessStep()])
    # Wall speed along +x once it moves, m/s (0 = static; > 0 recedes from the arm).
    velocity: float = 0.0
    # When the wall starts moving, s.
    motion_start: float = 0.0
    # When the wall stops moving, s (.inf = never).
    motion_end: float = math.inf


@dataclass
class TrajectoryConfig:
    # Xd centre (x m, y m, theta rad), eq. 19.
    center: list[float] = field(default_factory=lambda: [0.20, -0.25, math.pi / 2])
    # Oscillation amplitude per axis, eq. 19: yd = 0.025 sin(0.2 pi t) - 0.25.
    amplitude: list[float] = field(default_factory=lambda: [0.0, 0.025, 0.0])
    # Oscillation frequency, Hz (0.2 pi rad/s = 0.1 Hz).
    frequency: float = 0.1


FAULT_KINDS = (
    "sensor_nan",
    "sensor_stuck",
    "sensor_zero",
    "sensor_saturated",
    "wall_retract",
    "stiffness_jump",
)


# The fault kinds that read `value`.
FAULT_KINDS_WITH_VALUE = ("sensor_stuck", "sensor_saturated", "wall_retract", "stiffness_jump")


@dataclass
class FaultConfig:
    # One of FAULT_KINDS: the sensor reads NaN / a stuck value / 0 N / a full-scale value;
    # the wall jumps back along +x by `value` m and returns; Ke becomes `value` N/m.
    kind: str = "sensor_nan"
    # When the fault starts and ends, s.
    start: float = 1.0
    end: float = 1.5
    # sensor_stuck and sensor_saturated: the reading (N); wall_retract: the jump (m);
    # stiffness_jump: Ke during the fault (N/m). Unused by sensor_nan and sensor_zero.
    value: float = 0.0


@dataclass
class AdmittanceConfig:
    # false = the PID alone on Xd (the unsafe baseline).
    enabled: bool = True
    # Gamma of eq. 10 on the wall-normal axis.
    gamma: float = 1e-5
    # alpha of eq. 7 and 10 on the wall-normal axis, s.
    alpha: float = 0.1
    # Sampling period of a digital admittance block, s (0 = continuous, the paper's law).
    period: float = 0.0
    # Largest reference offset into the wall (+x), m: a safety bound with anti-windup.
    max_push: float = 0.01
    # Largest reference offset away from the wall (-x), m: bounds the integral's windup
    # when the sensor reads too high (e.g. saturated), so contact is regained quickly.
    max_retract: float = 0.1
    # Fmax, an explicit upper bound on the contact force, N (.inf = none): a penalty on the
    # force above it is added to the paper's cost (systems/optimal_admittance.py).
    max_force: float = math.inf
    # mu, the weight of that penalty: above Fmax the law's gains grow by (1 + mu).
    force_bound_gain: float = 4.0


CONTROLLER_KINDS = (
    "optimal_admittance",
    "pid_only",
    "fixed_reference",
    "classical_admittance",
    "adaptive_impedance",
)


@dataclass
class ControllerConfig:
    # The force controller in front of the PID (all have the same ports): the paper's
    # optimal_admittance, or a baseline: pid_only (the PID on Xd; also admittance.enabled:
    # false), fixed_reference (eq. 6 from wall estimates), classical_admittance (mass-damper
    # on the force error, as ROS 2's admittance_controller), adaptive_impedance (Jung, Hsia
    # and Bonitz 2004).
    kind: str = "optimal_admittance"
    # fixed_reference: error of its wall-position estimate, m (+ = beyond the real wall).
    wall_position_error: float = 0.001
    # fixed_reference: relative error of its stiffness estimate (0.1 = 10 % too stiff).
    stiffness_error: float = 0.0
    # Baseline gains: "matched" derives them from the paper's law (same force-loop
    # crossover Kp Gamma K, docs/comparison.md); "manual" takes the values below.
    tuning: str = "matched"
    # classical_admittance and adaptive_impedance (manual tuning): virtual mass, kg,
    mass: float = 0.16
    # damping, N s/m,
    damping: float = 40.0
    # classical_admittance: virtual spring, N/m (0 = mass-damper),
    stiffness: float = 0.0
    # adaptive_impedance: eta / lambda, the rate of its adaptive term, 1/s.
    adaptation_rate: float = 12.5


@dataclass
class PidConfig:
    # Cartesian PID gains on (x, y, theta), eq. 14 (Section VII-A's simulation values).
    kp: list[float] = field(default_factory=lambda: [2500.0, 2500.0, 1000.0])
    kd: list[float] = field(default_factory=lambda: [50.0, 50.0, 5.0])
    ki: list[float] = field(default_factory=lambda: [200.0, 200.0, 200.0])
    # Sampling period of a digital PID, s (0 = continuous).
    period: float = 0.0


@dataclass
class SensorConfig:
    # "ideal" (the true force) or "flexiforce" (A201 + op-amp + analog filter + noise).
    kind: str = "flexiforce"
    # Standard deviation of the measured-force noise at the ADC, N.
    noise_std: float = 0.02
    # Sampling period of the noise (the ADC period), s.
    noise_period: float = 0.005
    # Cut-off of the analog low-pass filter after the op-amp, Hz.
    filter_cutoff: float = 5000.0


@dataclass
class ArmConfig:
    # URDF of the arm: a file path (relative to the current folder, or in a scenario file to
    # that file's folder), or the name of a built-in model (planar_arm.urdf).
    urdf: str = "planar_arm.urdf"
    # Name of the frame at the contact point.
    fingertip_frame: str = "fingertip"
    # Include the motors' reflected inertia (rotor inertia x gear ratio^2) from the URDF.
    # false reproduces the paper's rigid-body model.
    reflected_inertia: bool = False
    # Joint-space seed that picks the elbow branch of the initial inverse kinematics, rad.
    joint_guess: list[float] = field(default_factory=lambda: [-0.45, 1.66, 0.36])
    # Initial fingertip pose (x m, y m, theta rad); empty = Xd(0). The arm starts at rest.
    initial_position: list[float] = field(default_factory=list)

    def urdf_path(self) -> Path:
        """The URDF file: `urdf` as a path if it names a file, else a built-in model."""
        path = Path(self.urdf).expanduser()
        if path.is_absolute() or path.is_file():
            return path
        return URDF_DIR / path


@dataclass
class LoggingConfig:
    # Logging period, s (0 = one sample per integrator step).
    period: float = 0.0


@dataclass
class Scenario:
    # Simulated time, s.
    duration: float = 30.0
    # Seed of every noise source.
    seed: int = 0
    # Fr: desired contact force along the wall normal (+x), N.
    force_reference: float = 5.0
    wall: WallConfig = field(default_factory=WallConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    admittance: AdmittanceConfig = field(default_factory=AdmittanceConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    pid: PidConfig = field(default_factory=PidConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    arm: ArmConfig = field(default_factory=ArmConfig)
    simulator: SimulatorConfig = field(default_factory=_default_simulator_config)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    # Injected faults (reliability studies); none by default.
    faults: list[FaultConfig] = field(default_factory=list)
    # Name of the scenario (informational).
    name: str = "custom"

    @property
    def controller_kind(self) -> str:
        """The force controller that runs: admittance.enabled = false means pid_only."""
        return self.controller.kind if self.admittance.enabled else "pid_only"


# --- keys and types ---------------------------------------------------------------------

INTEGRATION_SCHEMES = (
    "bogacki_shampine3",
    "explicit_euler",
    "implicit_euler",
    "radau1",
    "radau3",
    "runge_kutta2",
    "runge_kutta3",
    "runge_kutta5",
    "semi_explicit_euler",
    "velocity_implicit_euler",
)


def _fields_of(schema) -> dict[str, typing.Any]:
    """Field name -> type for a dataclass or a Drake config struct (SimulatorConfig)."""
    if dataclasses.is_dataclass(schema):
        hints = typing.get_type_hints(schema)
        return {f.name: hints[f.name] for f in dataclasses.fields(schema)}
    return {f.name: f.type for f in schema.__fields__}


def _is_struct(kind) -> bool:
    return dataclasses.is_dataclass(kind) or hasattr(kind, "__fields__")


def scenario_keys(schema=Scenario, prefix: str = "") -> dict[str, typing.Any]:
    """All dotted leaf keys of the scenario with their types."""
    keys = {}
    for name, kind in _fields_of(schema).items():
        key = prefix + name
        if _is_struct(kind):
            keys.update(scenario_keys(kind, key + "."))
        else:
            keys[key] = kind
    return keys


def _describe(kind) -> str:
    origin = typing.get_origin(kind)
    if origin is list:
        (item,) = typing.get_args(kind)
        return f"a list of {_describe(item)}"
    return {
        float: "a number",
        int: "an integer",
        bool: "true or false",
        str: "a string",
        StiffnessStep: "{time: s, stiffness: N/m} mappings",
        FaultConfig: "{kind, start, end, value} mappings",
    }.get(kind, getattr(kind, "__name__", str(kind)))


# The fields a list entry must give: left out, they would silently take the dataclass's
# default (a fault from 1 s to 1.5 s, a stiffness step to 1e5 N/m at 15 s).
_ENTRY_FIELDS = {
    StiffnessStep: ("time", "stiffness"),
    FaultConfig: ("kind", "start", "end"),
}
_ENTRY_DESCRIPTIONS = {
    StiffnessStep: "a stiffness step needs time (s) and stiffness (N/m)",
    FaultConfig: (
        "a fault needs kind, start and end (s), and value for " + ", ".join(FAULT_KINDS_WITH_VALUE)
    ),
}


def _check_entry_complete(key: str, entry: dict, kind) -> None:
    """Raises ScenarioError naming the first field that a list entry leaves out."""
    required = list(_ENTRY_FIELDS.get(kind, ()))
    if kind is FaultConfig and entry.get("kind") in FAULT_KINDS_WITH_VALUE:
        required.append("value")
    for name in required:
        if name not in entry:
            raise ScenarioError(f"{key}.{name}: missing; {_ENTRY_DESCRIPTIONS[kind]}")


def _check_type(key: str, value, kind):
    """Returns `value` converted to `kind`, or raises ScenarioError naming `key`."""
    origin = typing.get_origin(kind)
    if origin is list:
        (item,) = typing.get_args(kind)
        if not isinstance(value, list):
            raise ScenarioError(f"{key}: expected {_describe(kind)}, got {value!r}")
        return [_check_type(f"{key}[{i}]", v, item) for i, v in enumerate(value)]
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise ScenarioError(f"{key}: expected a mapping of {_describe(kind)}, got {value!r}")
        fields = _fields_of(kind)
        for name in value:
            if name not in fields:
                raise ScenarioError(
                    f"{key}.{name}: unknown key; allowed: {', '.join(sorted(fields))}"
                )
        _check_entry_complete(key, value, kind)
        return {name: _check_type(f"{key}.{name}", v, fields[name]) for name, v in value.items()}
    if kind is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise ScenarioError(f"{key}: expected true or false, got {value!r}")
    if kind in (int, float):
        expected = "an integer" if kind is int else "a number"
        if kind is int and isinstance(value, int) and not isinstance(value, bool):
            return value  # exactly: a float holds integers exactly only up to 2**53
        number = None
        if not isinstance(value, bool):
            try:
                number = float(value)
            except (TypeError, ValueError):
                pass
            except OverflowError:  # an integer beyond a float: out of every range
                number = math.inf if value > 0 else -math.inf
        if number is None or math.isnan(number) or (kind is int and not number.is_integer()):
            raise ScenarioError(f"{key}: expected {expected}, got {value!r}")
        return int(number) if kind is int else number
    if kind is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{key}: expected a string, got {value!r}")
        return value
    raise ScenarioError(f"{key}: cannot be set")  # pragma: no cover (no other leaf types)


def _unknown_key_error(key: str, valid: typing.Iterable[str]) -> ScenarioError:
    return ScenarioError(f"{key}: unknown scenario key{unknown_key_hint(key, valid)}")


def parse_value(text: str):
    """Parses a --set value: a number, true/false, a string, or a YAML list/mapping."""
    stripped = text.strip()
    if stripped[:1] in ("[", "{"):
        try:
            return yaml_load(data=f"value: {stripped}")["value"]
        except (RuntimeError, yaml.YAMLError) as error:
            problem = getattr(error, "problem", None) or str(error).splitlines()[0]
            raise ScenarioError(f"cannot parse {text!r} as YAML: {problem}") from None
    for convert in (int, float):
        try:
            return convert(stripped)
        except ValueError:
            pass
    if stripped.lower() in ("true", "false"):
        return stripped.lower() == "true"
    if stripped.lower() in (".inf", "inf"):
        return math.inf
    return stripped


def parse_overrides(overrides: typing.Sequence[str]) -> list[tuple[str, typing.Any]]:
    """(key, value) pairs of "KEY=VALUE" strings (as given to --set), values parsed."""
    pairs = []
    for text in overrides:
        key, sep, value = text.partition("=")
        if not sep or not key.strip():
            raise ScenarioError(f"--set {text!r}: expected KEY=VALUE")
        try:
            pairs.append((key.strip(), parse_value(value)))
        except ScenarioError as error:
            raise ScenarioError(f"{key.strip()}: {error}") from None
    return pairs


def _coerce_numbers(value):
    """YAML leaves numbers such as 1e5 as strings; turn numeric strings into floats."""
    if isinstance(value, dict):
        return {k: _coerce_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_coerce_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def _check_tree(data: dict, schema, prefix: str = "", valid: typing.Iterable[str] = ()) -> dict:
    """`data` checked against `schema`; `valid` (the root's keys) names the close matches."""
    fields = _fields_of(schema)
    checked = {}
    for name, value in data.items():
        key = prefix + name
        if name not in fields:
            raise _unknown_key_error(key, valid or scenario_keys())
        kind = fields[name]
        if _is_struct(kind):
            if not isinstance(value, dict):
                raise ScenarioError(f"{key}: expected a mapping, got {value!r}")
            checked[name] = _check_tree(value, kind, key + ".", valid)
        else:
            checked[name] = _check_type(key, value, kind)
    return checked


def _set_dotted(data: dict, key: str, value) -> None:
    node = data
    parts = key.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ScenarioError(f"{key}: cannot set inside a non-mapping value")
    node[parts[-1]] = value


# --- loading ----------------------------------------------------------------------------


def builtin_scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def _kind_of(value) -> str:
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return "a string"
    return "a number" if isinstance(value, int | float) else type(value).__name__


def _check_yaml_nodes(path: Path, text: str) -> None:
    """Raises ScenarioError for a key given twice in one mapping (YAML keeps the last one,
    silently) and for aliases (*name), which scenarios do not need."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return  # yaml_load reports the syntax error with its line
    visited = set()
    nodes = [root] if root is not None else []
    while nodes:
        node = nodes.pop()
        at = f"line {node.start_mark.line + 1}"
        if id(node) in visited:
            raise ScenarioError(
                f"scenario: {path}: the value at {at} is repeated by an alias (*name); "
                "scenario files take no YAML aliases: write the value out"
            )
        visited.add(id(node))
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    if key.value in seen:
                        raise ScenarioError(
                            f"scenario: {path} line {key.start_mark.line + 1}: key "
                            f"{key.value!r} is given twice in the same mapping"
                        )
                    seen.add(key.value)
                nodes += [key, value]
        elif isinstance(node, yaml.SequenceNode):
            nodes += node.value


def _read_yaml(path: Path) -> dict:
    """The mapping of scenario keys in the YAML file `path`, or one ScenarioError line."""
    try:
        status = path.stat()
    except OSError as error:
        raise ScenarioError(f"scenario: {path} cannot be read: {error.strerror}") from None
    # A sweep loads the same file once per point: parse it once.
    return copy.deepcopy(_parse_yaml(path, status.st_mtime_ns, status.st_size))


@functools.lru_cache(maxsize=16)
def _parse_yaml(path: Path, modified: int, size: int) -> dict:
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise ScenarioError(f"scenario: {path} cannot be read: {error.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ScenarioError(
            f"scenario: {path} is not UTF-8 text (byte 0x{raw[error.start]:02x} at offset "
            f"{error.start})"
        ) from None
    _check_yaml_nodes(path, text)
    try:
        data = yaml_load(data=text) if text.strip() else None
    except Exception as error:  # PyYAML's YAMLError (syntax) or pydrake's RuntimeError
        where = getattr(error, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ScenarioError(f"scenario: {path} is not valid YAML{at}: {problem}") from None
    if data is None:
        raise ScenarioError(
            f"scenario: {path} holds no scenario keys; write the keys that differ from the "
            "defaults, or {} for every default"
        )
    if not isinstance(data, dict):
        raise ScenarioError(
            f"scenario: {path} must hold a mapping of scenario keys, got {_kind_of(data)}"
        )
    return data


def _read_source(source: str | Path | None) -> tuple[dict, str]:
    if source is None:
        return {}, "custom"
    path = Path(source)
    if not path.suffix and str(source) in builtin_scenario_names():
        path = SCENARIO_DIR / f"{source}.yaml"
    if not path.is_file():
        names = ", ".join(builtin_scenario_names())
        raise ScenarioError(
            f"scenario: '{source}' is neither a built-in scenario ({names}) nor a YAML file"
        )
    data = _read_yaml(path)
    data.setdefault("name", path.stem)
    arm = data.get("arm")
    if isinstance(arm, dict) and isinstance(arm.get("urdf"), str):
        # A URDF named relative to the scenario file: resolve it against the file's folder.
        beside = path.resolve().parent / arm["urdf"]
        if not Path(arm["urdf"]).is_absolute() and beside.is_file():
            arm["urdf"] = str(beside)
    return data, path.stem


def load_scenario(
    source: str | Path | None = None,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
) -> Scenario:
    """Loads a scenario and applies dotted-key overrides.

    Args:
        source: a built-in scenario name, a YAML path, or None for the defaults.
        overrides: "key=value" strings (as given to --set) or a {key: value} mapping.

    A file whose top-level ``kind`` is ``grasp`` is a grasp scenario: it is loaded with
    its own schema (diagrams/grasp_scenario.py) and a GraspScenario is returned.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data, _ = _read_source(source)
    kind = data.pop("kind", "arm")
    if kind not in SCENARIO_KINDS:
        raise ScenarioError(f"kind: must be one of {', '.join(SCENARIO_KINDS)}, got {kind!r}")
    if kind == "grasp":
        from admittance.diagrams.grasp_scenario import load_grasp_scenario

        return load_grasp_scenario(data, overrides)
    data = _coerce_numbers(data)
    items = overrides.items() if isinstance(overrides, typing.Mapping) else None
    if items is None:
        items = parse_overrides(overrides)
    valid = scenario_keys()
    for key, value in items:
        if key not in valid:
            # Allow whole sub-trees such as wall.stiffness_steps.
            prefixes = {k.rsplit(".", i)[0] for k in valid for i in range(1, k.count(".") + 1)}
            if key not in prefixes:
                raise _unknown_key_error(key, valid)
        _set_dotted(data, key, value)
    checked = _check_tree(data, Scenario)
    scenario = yaml_load_typed(schema=Scenario, data=_dump(checked))
    from admittance.diagrams.scenario_validation import validate  # it imports this module

    return validate(scenario)


def _dump(data: dict) -> str:
    import json

    # JSON is YAML; inf is spelled .inf in YAML.
    text = json.dumps(data, allow_nan=True)
    return text.replace("Infinity", ".inf")


def scenario_to_yaml(scenario: Scenario) -> str:
    """The full scenario, every key, as YAML (written next to results)."""
    return yaml_dump_typed(scenario)
