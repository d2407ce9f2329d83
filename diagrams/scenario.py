"""Scenarios: typed YAML descriptions of one closed-loop run (README.md, "Scenarios").

A scenario is a tree of dataclasses loaded with Drake's ``yaml_load_typed``. Every field has
a default equal to the paper's value (Section VII-A); the built-in scenarios in
``diagrams/scenarios/`` override what differs. ``--set key=value`` overrides use the dotted
key of a field (``wall.stiffness``, ``admittance.gamma``, ...).

Every problem with user input raises ``ScenarioError`` with one line that names the key and
what is allowed; nothing deeper than this module sees unvalidated values.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import dataclasses
import difflib
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed
from pydrake.systems.analysis import SimulatorConfig

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


class ScenarioError(ValueError):
    """A scenario key has a missing, unknown, mistyped or impossible value."""


def _default_simulator_config() -> SimulatorConfig:
    # The loop is stiff (wall up to 1e5 N/m, Kd = 5 on a light last link: a pole near
    # -1e4 1/s); an implicit integrator with error control takes a few hundred steps where
    # an explicit one takes ~150,000. See README, "Integrator".
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
    # crossover Kp Gamma K, README "Comparison"); "manual" takes the values below.
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

    def urdf_path(self) -> Path:
        """The arm's URDF file: `arm.urdf` as a path if it names a file, else a built-in."""
        path = Path(self.arm.urdf).expanduser()
        if path.is_absolute() or path.is_file():
            return path
        return URDF_DIR / path


# --- keys and types ---------------------------------------------------------------------

_INTEGRATION_SCHEMES = (
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
        return {name: _check_type(f"{key}.{name}", v, fields[name]) for name, v in value.items()}
    if kind is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise ScenarioError(f"{key}: expected true or false, got {value!r}")
    if kind in (int, float):
        expected = "an integer" if kind is int else "a number"
        number = None
        if not isinstance(value, bool):
            try:
                number = float(value)
            except (TypeError, ValueError):
                pass
        if number is None or math.isnan(number) or (kind is int and not number.is_integer()):
            raise ScenarioError(f"{key}: expected {expected}, got {value!r}")
        return int(number) if kind is int else number
    if kind is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{key}: expected a string, got {value!r}")
        return value
    raise ScenarioError(f"{key}: cannot be set")  # pragma: no cover (no other leaf types)


def _unknown_key_error(key: str, valid: typing.Iterable[str]) -> ScenarioError:
    valid = list(valid)
    # Candidates: every full key and every section ("wall", "admittance", ...).
    sections = {k.rsplit(".", i)[0] for k in valid for i in range(1, k.count(".") + 1)}
    close = difflib.get_close_matches(key, valid + sorted(sections), n=1, cutoff=0.5)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    return ScenarioError(f"{key}: unknown scenario key{hint}")


def parse_value(text: str):
    """Parses a --set value: a number, true/false, a string, or a YAML list/mapping."""
    stripped = text.strip()
    if stripped[:1] in ("[", "{"):
        try:
            return yaml_load(data=f"value: {stripped}")["value"]
        except RuntimeError as error:
            raise ScenarioError(f"cannot parse {text!r}: {error}") from None
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
        pairs.append((key.strip(), parse_value(value)))
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


def _check_tree(data: dict, schema, prefix: str = "") -> dict:
    fields = _fields_of(schema)
    checked = {}
    for name, value in data.items():
        key = prefix + name
        if name not in fields:
            raise _unknown_key_error(key, scenario_keys())
        kind = fields[name]
        if _is_struct(kind):
            if not isinstance(value, dict):
                raise ScenarioError(f"{key}: expected a mapping, got {value!r}")
            checked[name] = _check_tree(value, kind, key + ".")
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


# --- validation -------------------------------------------------------------------------


def _require(condition: bool, key: str, allowed: str, value) -> None:
    if not condition:
        raise ScenarioError(f"{key}: must be {allowed}, got {value!r}")


def _require_one_of(value, key: str, choices: typing.Sequence[str]) -> None:
    _require(value in choices, key, "one of " + ", ".join(choices), value)


# Stiffer than any contact this arm can make (steel on steel at this scale is ~1e9 N/m).
MAX_STIFFNESS = 1e9


def validate(scenario: Scenario) -> Scenario:
    """Range checks of every key; raises ScenarioError naming the first bad key."""
    s = scenario
    finite = math.isfinite
    _require(finite(s.duration) and 0 < s.duration <= 1e5, "duration", "in (0, 1e5] s", s.duration)
    _require(s.seed >= 0, "seed", ">= 0", s.seed)
    _require(
        finite(s.force_reference) and s.force_reference > 0,
        "force_reference",
        "> 0 N (compressive)",
        s.force_reference,
    )
    w = s.wall
    _require(
        finite(w.position) and w.position > 0,
        "wall.position",
        "in front of the base (> 0 m along x)",
        w.position,
    )
    _require(
        finite(w.stiffness) and 0 < w.stiffness <= MAX_STIFFNESS,
        "wall.stiffness",
        f"in (0, {MAX_STIFFNESS:g}] N/m",
        w.stiffness,
    )
    previous = 0.0
    for i, step in enumerate(w.stiffness_steps):
        key = f"wall.stiffness_steps[{i}]"
        _require(
            finite(step.stiffness) and 0 < step.stiffness <= MAX_STIFFNESS,
            key + ".stiffness",
            f"in (0, {MAX_STIFFNESS:g}] N/m",
            step.stiffness,
        )
        _require(
            finite(step.time) and step.time >= previous,
            key + ".time",
            ">= 0 s and not before the previous step",
            step.time,
        )
        previous = step.time
    _require(
        finite(w.velocity) and abs(w.velocity) <= 1.0, "wall.velocity", "in [-1, 1] m/s", w.velocity
    )
    _require(
        finite(w.motion_start) and w.motion_start >= 0,
        "wall.motion_start",
        ">= 0 s",
        w.motion_start,
    )
    _require(
        w.motion_end >= w.motion_start, "wall.motion_end", ">= wall.motion_start", w.motion_end
    )
    t = s.trajectory
    _require(len(t.center) == 3, "trajectory.center", "3 values (x, y, theta)", t.center)
    _require(all(map(finite, t.center)), "trajectory.center", "finite", t.center)
    _require(len(t.amplitude) == 3, "trajectory.amplitude", "3 values", t.amplitude)
    _require(all(map(finite, t.amplitude)), "trajectory.amplitude", "finite", t.amplitude)
    _require(
        finite(t.frequency) and t.frequency >= 0, "trajectory.frequency", ">= 0 Hz", t.frequency
    )
    a = s.admittance
    _require(finite(a.gamma) and 0 < a.gamma <= 0.1, "admittance.gamma", "in (0, 0.1]", a.gamma)
    _require(finite(a.alpha) and 0 <= a.alpha <= 10, "admittance.alpha", "in [0, 10] s", a.alpha)
    _require(
        finite(a.period) and a.period >= 0, "admittance.period", ">= 0 s (0 = continuous)", a.period
    )
    _require(
        finite(a.max_push) and 0 < a.max_push <= 0.5,
        "admittance.max_push",
        "in (0, 0.5] m",
        a.max_push,
    )
    _require(
        finite(a.max_retract) and 0 < a.max_retract <= 0.5,
        "admittance.max_retract",
        "in (0, 0.5] m",
        a.max_retract,
    )
    _require(
        a.max_force > s.force_reference,
        "admittance.max_force",
        f"> force_reference ({s.force_reference:g} N), or .inf for no bound",
        a.max_force,
    )
    _require(
        finite(a.force_bound_gain) and 0 < a.force_bound_gain <= 100,
        "admittance.force_bound_gain",
        "in (0, 100]",
        a.force_bound_gain,
    )
    k = s.controller
    _require_one_of(k.kind, "controller.kind", CONTROLLER_KINDS)
    _require(
        k.tuning in ("matched", "manual"), "controller.tuning", "'matched' or 'manual'", k.tuning
    )
    _require(
        finite(k.wall_position_error) and abs(k.wall_position_error) <= 0.1,
        "controller.wall_position_error",
        "in [-0.1, 0.1] m",
        k.wall_position_error,
    )
    _require(
        finite(k.stiffness_error) and -0.9 <= k.stiffness_error <= 10,
        "controller.stiffness_error",
        "in [-0.9, 10] (relative)",
        k.stiffness_error,
    )
    for name, maximum in (("mass", 1e3), ("damping", 1e6), ("adaptation_rate", 1e4)):
        value = getattr(k, name)
        _require(
            finite(value) and 0 < value <= maximum,
            f"controller.{name}",
            f"in (0, {maximum:g}]",
            value,
        )
    _require(
        finite(k.stiffness) and 0 <= k.stiffness <= 1e6,
        "controller.stiffness",
        "in [0, 1e6] N/m",
        k.stiffness,
    )
    for i, fault in enumerate(s.faults):
        key = f"faults[{i}]"
        _require_one_of(fault.kind, key + ".kind", FAULT_KINDS)
        _require(finite(fault.start) and fault.start >= 0, key + ".start", ">= 0 s", fault.start)
        _require(finite(fault.end) and fault.end > fault.start, key + ".end", "> start", fault.end)
        _require(finite(fault.value), key + ".value", "finite", fault.value)
        if fault.kind == "stiffness_jump":
            _require(
                0 < fault.value <= MAX_STIFFNESS,
                key + ".value",
                f"in (0, {MAX_STIFFNESS:g}] N/m for stiffness_jump",
                fault.value,
            )
        if fault.kind == "wall_retract":
            _require(
                fault.value > 0, key + ".value", "> 0 m (the wall moves away, +x)", fault.value
            )
        if fault.kind == "sensor_saturated":
            _require(fault.value > 0, key + ".value", "> 0 N (the full-scale reading)", fault.value)
    p = s.pid
    for name, minimum, maximum in (("kp", 0.0, 1e6), ("kd", None, 1e5), ("ki", None, 1e6)):
        gains = getattr(p, name)
        key = f"pid.{name}"
        _require(len(gains) == 3, key, "3 values (x, y, theta)", gains)
        low = "> 0" if minimum is not None else ">= 0"
        ok = all(
            finite(g) and (g > 0 if minimum is not None else g >= 0) and g <= maximum for g in gains
        )
        _require(ok, key, f"{low} and <= {maximum:g} on every axis", gains)
    _require(finite(p.period) and p.period >= 0, "pid.period", ">= 0 s (0 = continuous)", p.period)
    if a.enabled:
        # Past max_push only the PID's slow integral could add force: Fr would not be reached.
        needed = s.force_reference / p.kp[0]
        _require(
            a.max_push > needed,
            "admittance.max_push",
            f"> force_reference / pid.kp[0] = {needed:.3g} m (the PID's push at the bound, "
            f"Kp max_push, must exceed Fr)",
            a.max_push,
        )
    n = s.sensor
    _require(n.kind in ("ideal", "flexiforce"), "sensor.kind", "'ideal' or 'flexiforce'", n.kind)
    if n.kind == "flexiforce":
        # A reference the sensor cannot read would wind the admittance up forever.
        from admittance.systems.flexiforce import FlexiForceSensor

        full_scale = FlexiForceSensor().saturation_force
        _require(
            s.force_reference < 0.9 * full_scale,
            "force_reference",
            f"< {0.9 * full_scale:.4g} N with sensor.kind=flexiforce (90 % of the A201's "
            f"{full_scale:.4g} N full scale)",
            s.force_reference,
        )
        _require(
            not finite(a.max_force) or a.max_force < full_scale,
            "admittance.max_force",
            f"< {full_scale:.4g} N with sensor.kind=flexiforce (a bound the A201 cannot read "
            "cannot be enforced), or .inf",
            a.max_force,
        )
    _require(
        finite(n.noise_std) and 0 <= n.noise_std <= 100,
        "sensor.noise_std",
        "in [0, 100] N",
        n.noise_std,
    )
    _require(
        finite(n.noise_period) and n.noise_period >= 1e-5,
        "sensor.noise_period",
        ">= 1e-5 s (a 100 kHz ADC)",
        n.noise_period,
    )
    _require(
        finite(n.filter_cutoff) and 0 < n.filter_cutoff <= 1e6,
        "sensor.filter_cutoff",
        "in (0, 1e6] Hz",
        n.filter_cutoff,
    )
    r = s.arm
    _require(s.urdf_path().is_file(), "arm.urdf", "an existing URDF file", r.urdf)
    _require(
        len(r.joint_guess) > 0 and all(map(finite, r.joint_guess)),
        "arm.joint_guess",
        "finite joint angles",
        r.joint_guess,
    )
    _require(
        len(r.initial_position) in (0, 3) and all(map(finite, r.initial_position)),
        "arm.initial_position",
        "empty or 3 finite values (x, y, theta)",
        r.initial_position,
    )
    c = s.simulator
    _require_one_of(c.integration_scheme, "simulator.integration_scheme", _INTEGRATION_SCHEMES)
    _require(
        finite(c.accuracy) and 0 < c.accuracy <= 0.1,
        "simulator.accuracy",
        "in (0, 0.1]",
        c.accuracy,
    )
    _require(
        finite(c.max_step_size) and c.max_step_size > 0,
        "simulator.max_step_size",
        "> 0 s",
        c.max_step_size,
    )
    _require(c.start_time == 0.0, "simulator.start_time", "0", c.start_time)
    _require(
        finite(s.logging.period) and s.logging.period >= 0,
        "logging.period",
        ">= 0 s (0 = every step)",
        s.logging.period,
    )
    _validate_safety(s)
    return scenario


def _validate_safety(s: Scenario) -> None:
    """Range checks of safety.*, and what the layer needs of the rest of the scenario."""
    g = s.safety
    finite = math.isfinite
    _require(
        finite(g.max_stiffness) and 0 < g.max_stiffness <= MAX_STIFFNESS,
        "safety.max_stiffness",
        f"in (0, {MAX_STIFFNESS:g}] N/m",
        g.max_stiffness,
    )
    _require(
        finite(g.stability_margin) and 1 <= g.stability_margin <= 100,
        "safety.stability_margin",
        "in [1, 100]",
        g.stability_margin,
    )
    _require(
        finite(g.damping_ratio) and 0.2 <= g.damping_ratio <= 2,
        "safety.damping_ratio",
        "in [0.2, 2] (a first contact bounces below 0.19)",
        g.damping_ratio,
    )
    if not g.enabled:
        return
    _require(
        s.controller_kind == "optimal_admittance",
        "safety.enabled",
        "used with the paper's controller (controller.kind optimal_admittance, "
        "admittance.enabled true)",
        g.enabled,
    )
    _require(
        finite(s.admittance.max_force),
        "admittance.max_force",
        "finite with safety.enabled (the layer keeps the force under it)",
        s.admittance.max_force,
    )
    _require(
        s.admittance.period == 0 and s.pid.period == 0,
        "safety.enabled",
        "used with the continuous controller (admittance.period and pid.period 0)",
        g.enabled,
    )


# --- loading ----------------------------------------------------------------------------


def builtin_scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


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
    try:
        data = yaml_load(filename=str(path))
    except Exception as error:  # PyYAML's YAMLError (syntax) or pydrake's RuntimeError
        where = getattr(error, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ScenarioError(f"scenario: {path} is not valid YAML{at}: {problem}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(f"scenario: {path} must hold a mapping of scenario keys")
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

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data, _ = _read_source(source)
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
    return validate(scenario)


def _dump(data: dict) -> str:
    import json

    # JSON is YAML; inf is spelled .inf in YAML.
    text = json.dumps(data, allow_nan=True)
    return text.replace("Infinity", ".inf")


def scenario_to_yaml(scenario: Scenario) -> str:
    """The full scenario, every key, as YAML (written next to results)."""
    return yaml_dump_typed(scenario)
