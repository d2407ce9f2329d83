"""The hardware split's settings: a spatial scenario (the robot, its tool, the table, the
plan and the gains, ``kind: spatial``, e.g. the built-in ``panda_surface_press``) and the
keys that are the hardware's own (the command interface, the watchdogs, the pacing), in a
``hardware`` section of the scenario file.

``--set key=value`` overrides one key: a hardware key by its name (``command_wait=0``), any
other the scenario's (``surface.height_error=0.002``); ``rate=R`` is the scenario's
``time_step=1/R`` (the robot's status rate is the loop's period). ``duration`` is the run's
length (the scenario's by default): a run may be shorter than the scenario's plan (a test
of the station alone) or longer (a controller started before its station); the plan holds
its last point after its end.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import dataclasses
import math
from pathlib import Path

import yaml

from admittance.diagrams.robots.kinds import robot_of
from admittance.diagrams.robots.record import HardwareParts
from admittance.diagrams.scenario.files import load_scenario, load_scenario_data
from admittance.diagrams.scenario.schema import ScenarioError, load_typed, parse_value

__all__ = [
    "BUILTIN_HARDWARE_SCENARIOS",
    "HardwareConfig",
    "load_hardware_config",
    "hardware_parts",
    "scenario_of",
]

# The built-in spatial scenarios the hardware split runs by name.
BUILTIN_HARDWARE_SCENARIOS = ("panda_surface_press",)
CONTROL_MODES = ("torque", "position")


@dataclasses.dataclass
class HardwareConfig:
    # The station's command interface: torque (commanded torques plus the station's own
    # gravity compensation) or position (the station's joint PD tracks commanded positions).
    mode: str = "torque"
    # Real-time pacing of the station (Simulator target rate; 0 = as fast as it can).
    realtime_rate: float = 1.0
    # Wall time the station gives the controller to answer each status, s (the robot gives
    # it one cycle, 0.001; a simulated station on a loaded machine more, so that the plant
    # sees a one-period delay); a later command is counted late, the station goes on.
    command_wait: float = 0.02
    # The station's command watchdog: no fresh command for this long holds the arm, s.
    command_timeout: float = 0.02
    # Joint stiffness of the station's PD (position mode and hold), N m/rad.
    joint_stiffness: float = 600.0
    # Joint damping of the station's PD, N m s/rad.
    joint_damping: float = 40.0
    # Force bound Fmax of the law, N (inf: none, as the scenario's law).
    max_force: float = math.inf
    # Exterior-penalty gain mu above the guard level (Fr + Fmax) / 2.
    force_bound_gain: float = 4.0
    # The controller's watchdog: periods without a status before it commands a hold.
    status_timeout_periods: int = 10
    # Seconds without a status after which the controller decides the station is gone.
    station_timeout: float = 0.5
    # A wrench older than this (by its timestamp against the status clock) is stale, s.
    wrench_timeout: float = 0.01
    # The controller checks its gains against the sampled loop at the start (refusing
    # gains beyond its bounds) and while it runs (holding the law); false: it only logs
    # what the checks find (to measure a loop beyond the bounds on a simulated station).
    gain_check: bool = True
    # The station serves Meshcat on localhost: the arm, and sliders for Fr, Gamma, alpha
    # and Fmax that publish the parameter message when they move.
    meshcat: bool = False
    # --- from the scenario (set by load_hardware_config; not keys of the section) ---
    # The scenario: a built-in name or a YAML file, and the overrides given to it.
    scenario: str = "panda_surface_press"
    scenario_overrides: list[str] = dataclasses.field(default_factory=list)
    # Name of the run (the result folder's default name).
    name: str = "panda_surface_press"
    # Length of the run, s (the station's simulated time; the controller stops with it).
    duration: float = 6.0
    # The robot's status and command rate, Hz: 1 / the scenario's time_step.
    rate: float = 1000.0
    # Fr, N.
    force_reference: float = 10.0


_SECTION_KEYS = (
    "mode",
    "realtime_rate",
    "command_wait",
    "command_timeout",
    "joint_stiffness",
    "joint_damping",
    "max_force",
    "force_bound_gain",
    "status_timeout_periods",
    "station_timeout",
    "wrench_timeout",
    "gain_check",
    "meshcat",
)
_POSITIVE = (
    "command_timeout",
    "joint_stiffness",
    "joint_damping",
    "max_force",
    "force_bound_gain",
    "station_timeout",
    "wrench_timeout",
)
_NON_NEGATIVE = ("command_wait", "realtime_rate")


def _validate(config: HardwareConfig) -> HardwareConfig:
    for key in _POSITIVE:
        value = getattr(config, key)
        if not (value > 0) or (math.isinf(value) and key != "max_force"):
            raise ScenarioError(f"{key}: must be a finite number > 0, got {value}")
    for key in _NON_NEGATIVE:
        value = getattr(config, key)
        if not (math.isfinite(value) and value >= 0):
            raise ScenarioError(f"{key}: must be a finite number >= 0, got {value}")
    if config.mode not in CONTROL_MODES:
        raise ScenarioError(f"mode: must be one of {', '.join(CONTROL_MODES)}, got {config.mode!r}")
    if config.max_force <= config.force_reference:
        raise ScenarioError(
            f"max_force: must be above force_reference ({config.force_reference} N), "
            f"got {config.max_force}"
        )
    if not 1 <= config.status_timeout_periods <= 1000:
        raise ScenarioError(
            f"status_timeout_periods: must be an integer in [1, 1000], "
            f"got {config.status_timeout_periods}"
        )
    return config


def _split(source, overrides) -> tuple[dict, dict, list[str]]:
    """(the scenario file's mapping or {} for a built-in, its hardware section, the
    scenario's overrides); the hardware overrides go into the section."""
    data: dict = {}
    if source is not None and str(source) not in BUILTIN_HARDWARE_SCENARIOS:
        path = Path(source)
        if not path.is_file():
            raise ScenarioError(
                f"scenario: '{source}' is neither a hardware scenario "
                f"({', '.join(BUILTIN_HARDWARE_SCENARIOS)}) nor a spatial scenario's YAML file"
            )
        data = yaml.safe_load(path.read_text()) or {}
        if not isinstance(data, dict):
            raise ScenarioError(f"scenario: {path} must hold a mapping of scenario keys")
        data.setdefault("name", path.stem)
    section = data.pop("hardware", None) or {}
    if not isinstance(section, dict):
        raise ScenarioError("hardware: must be a mapping of the hardware keys")
    rest = []
    for item in overrides:
        key, _, value = str(item).partition("=")
        if key in _SECTION_KEYS or key == "duration":
            section[key] = parse_value(value)
        elif key == "rate":
            rate = float(value)
            if not rate > 0:
                raise ScenarioError(f"rate: must be a number > 0 (Hz), got {value}")
            rest.append(f"time_step={1.0 / rate!r}")
        else:
            rest.append(str(item))
    return data, section, rest


def scenario_of(config: HardwareConfig):
    """The scenario `config` was loaded from, with its overrides."""
    data, _, _ = _split(config.scenario, ())
    if not data:
        return load_scenario(config.scenario, config.scenario_overrides)
    return load_scenario_data(data, config.scenario_overrides)


def hardware_parts(scenario) -> HardwareParts:
    """What the split needs of the scenario's robot (its record's)."""
    return robot_of(scenario).hardware


def _check_robot(scenario, source) -> None:
    """One line for a scenario whose robot the split cannot drive."""
    robot = robot_of(scenario)
    if robot.hardware is None:
        raise ScenarioError(
            f"kind: the hardware runs a robot with LCM drivers; '{source}' is {robot.noun} "
            f"scenario (kind: {robot.kind})"
        )


def _check_what_the_hardware_runs(scenario) -> None:
    """Refuses, in one line, what a scenario asks for that the split does not run: the
    safety layer (the controller runs the paper's law with its watchdogs, not the layer:
    a user who set it must not believe the robot is guarded by it) and injected faults
    (the station publishes its wrist sensor's whole wrench, and its plant takes no
    injected torques)."""
    if scenario.safety.enabled:
        raise ScenarioError(
            "safety.enabled: the hardware controller runs the paper's law with its watchdogs, "
            "not the safety layer (docs/evidence/hardware.md); set it to false, or run the layer "
            "with admittance simulate"
        )
    if scenario.faults:
        raise ScenarioError(
            "faults: the station publishes its wrist sensor's wrench and steps its plant "
            "without injected faults; remove them (admittance simulate runs them)"
        )


def load_hardware_config(source: str | Path | None = None, overrides=()) -> HardwareConfig:
    """The hardware settings of a spatial scenario (a built-in name or a YAML file; None:
    ``panda_surface_press``), with --set overrides.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    source = "panda_surface_press" if source is None else str(source)
    _, section, rest = _split(source, overrides)
    duration = section.pop("duration", None)
    unknown = sorted(set(section) - set(_SECTION_KEYS))
    if unknown:
        raise ScenarioError(
            f"hardware.{unknown[0]}: unknown key; the hardware keys are {', '.join(_SECTION_KEYS)}"
        )
    config = load_typed(section, HardwareConfig, ())
    config.scenario, config.scenario_overrides = source, rest
    scenario = scenario_of(config)
    _check_robot(scenario, source)
    _check_what_the_hardware_runs(scenario)
    config.name = scenario.name
    config.duration = scenario.duration if duration is None else duration
    if not (isinstance(config.duration, int | float) and 0 < config.duration < math.inf):
        raise ScenarioError(f"duration: must be a finite number > 0 (s), got {duration!r}")
    config.rate = 1.0 / scenario.time_step
    config.force_reference = scenario.force_reference
    return _validate(config)
