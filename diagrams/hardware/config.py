"""The hardware split's settings: the station (the robot, or its simulation) and the
controller process, read from a YAML file or the built-in ``panda_surface_press`` defaults.

Until the spatial scenario kind lands in ``admittance.diagrams.scenario``, the station and
the controller read this small schema of their own: what a spatial scenario must give them
(docs/hardware.md, "What the spatial scenario needs"). Every key has a default; a YAML file
names only what differs, and ``--set key=value`` overrides one key.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import dataclasses
import math
from pathlib import Path

import yaml

from admittance.diagrams.scenario.schema import ScenarioError, load_typed

__all__ = ["BUILTIN_HARDWARE_SCENARIOS", "HardwareConfig", "load_hardware_config"]

# The scenarios the hardware split knows by name (the defaults below).
BUILTIN_HARDWARE_SCENARIOS = ("panda_surface_press",)
CONTROL_MODES = ("torque", "position")


@dataclasses.dataclass
class HardwareConfig:
    # Name of the run (the result folder's default name).
    name: str = "panda_surface_press"
    # Length of the run, s (the station's simulated time; the controller stops with it).
    duration: float = 4.0
    # The station's command interface: torque (commanded torques plus the station's own
    # gravity compensation) or position (the station's joint PD tracks commanded positions).
    mode: str = "torque"
    # The robot's status and command rate, Hz (the Panda's and the iiwa's: 1 kHz).
    rate: float = 1000.0
    # Real-time pacing of the station (Simulator target rate; 0 = as fast as it can).
    realtime_rate: float = 1.0
    # Wall time the station gives the controller to answer each status, s (the robot gives
    # it one cycle, 0.001; a simulated station on a loaded machine more, so that the plant
    # sees a one-period delay); a later command is counted late, the station goes on.
    command_wait: float = 0.02
    # Height of the table's top above the robot's base, m.
    table_height: float = 0.335
    # Point-contact stiffness of the tool tip on the table, N/m.
    contact_stiffness: float = 2.0e4
    # Hunt-Crossley dissipation of that contact, s/m.
    contact_dissipation: float = 20.0
    # The station's command watchdog: no fresh command for this long holds the arm, s.
    command_timeout: float = 0.02
    # Joint stiffness of the station's PD (position mode and hold), N m/rad.
    joint_stiffness: float = 600.0
    # Joint damping of the station's PD, N m s/rad.
    joint_damping: float = 40.0
    # Desired normal force on the table, N (the paper's Fr).
    force_reference: float = 10.0
    # Gradient-flow gain of the law (eq. 10), m/(N^2 s) per unit stiffness.
    gamma: float = 3.0e-6
    # Weight of dE/dt in the law's cost, s.
    alpha: float = 0.02
    # Force bound Fmax, N (inf: no bound).
    max_force: float = 20.0
    # Exterior-penalty gain mu above the guard level (Fr + Fmax) / 2.
    force_bound_gain: float = 4.0
    # Furthest the law's offset may push past the plan, m.
    max_push: float = 0.08
    # Cartesian PD stiffness (translation, N/m; rotation, N m/rad).
    translational_stiffness: float = 1000.0
    rotational_stiffness: float = 20.0
    # Cartesian PD damping (translation, N s/m; rotation, N m s/rad). The rotation's damping
    # reaches the wrist's last joint (0.0067 kg m^2) almost alone: with the command one
    # period late it needs d T / M_77 below about 1 (1.5 N m s/rad holds down to 250 Hz).
    translational_damping: float = 80.0
    rotational_damping: float = 1.5
    # Null-space posture stiffness and damping of the redundant joint, N m/rad, N m s/rad.
    posture_stiffness: float = 5.0
    posture_damping: float = 2.0
    # The controller's watchdog: periods without a status before it commands a hold.
    status_timeout_periods: int = 10
    # Seconds without a status after which the controller decides the station is gone.
    station_timeout: float = 0.5
    # A wrench older than this (by its timestamp against the status clock) is stale, s.
    wrench_timeout: float = 0.01


_POSITIVE = (
    "duration",
    "rate",
    "contact_stiffness",
    "command_timeout",
    "joint_stiffness",
    "joint_damping",
    "force_reference",
    "gamma",
    "max_force",
    "force_bound_gain",
    "max_push",
    "translational_stiffness",
    "rotational_stiffness",
    "translational_damping",
    "rotational_damping",
    "station_timeout",
    "wrench_timeout",
)
_NON_NEGATIVE = (
    "command_wait",
    "realtime_rate",
    "contact_dissipation",
    "alpha",
    "posture_stiffness",
    "posture_damping",
)


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


def load_hardware_config(source: str | Path | None = None, overrides=()) -> HardwareConfig:
    """The hardware settings of a built-in name or a YAML file, with --set overrides.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data: dict = {}
    if source is not None and str(source) not in BUILTIN_HARDWARE_SCENARIOS:
        path = Path(source)
        if not path.is_file():
            raise ScenarioError(
                f"scenario: '{source}' is neither a hardware scenario "
                f"({', '.join(BUILTIN_HARDWARE_SCENARIOS)}) nor a YAML file"
            )
        data = yaml.safe_load(path.read_text()) or {}
        if not isinstance(data, dict):
            raise ScenarioError(f"scenario: '{source}' must hold a YAML mapping of keys")
        data.setdefault("name", path.stem)
    elif source is not None:
        data = {"name": str(source)}
    return _validate(load_typed(data, HardwareConfig, overrides))
