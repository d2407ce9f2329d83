"""The scenario sections every robot shares, declared once.

``sensor``, ``controller``, ``admittance`` and ``pid`` (the keys of the loop at a
force-controlled point, whatever the robot), ``simulator`` (Drake's SimulatorConfig, with
an implicit integrator by default), ``safety`` (the safety layer, docs/evidence/safety.md),
``faults`` (injected faults, docs/evidence/reliability.md) and ``logging``. Each robot's scenario
(planar_arm, planar_gripper) includes the sections it runs, and a robot whose section
has more keys (the arm's ADC noise period, its baselines, its digital controller) or
other defaults (the gripper's two task coordinates) extends the shared one; a robot that
does not run a section (the gripper has no safety layer or faults yet) leaves it out, so
that no key is silently ignored.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

from dataclasses import dataclass, field
from typing import ClassVar

from pydrake.systems.analysis import SimulatorConfig

__all__ = [
    "AdmittanceSection",
    "ControllerSection",
    "FAULT_KINDS",
    "FAULT_KINDS_WITH_VALUE",
    "FaultConfig",
    "LoggingConfig",
    "NOISY_FAULT_KINDS",
    "PidSection",
    "SafetyConfig",
    "SensorSection",
    "implicit_simulator_config",
]


def implicit_simulator_config(max_step_size: float) -> SimulatorConfig:
    """Drake's radau3 with error control at accuracy 1e-4: the loops are stiff (a wall or a
    contact of 1e4-1e5 N/m, a 5 kHz sensor filter, Kd on light links), where an implicit
    integrator takes a few hundred steps and an explicit one ~150,000 (docs/evidence/speed.md,
    "Integrator")."""
    return SimulatorConfig(
        integration_scheme="radau3",
        accuracy=1e-4,
        max_step_size=max_step_size,
        use_error_control=True,
    )


@dataclass
class SensorSection:
    # "ideal" (the true force) or "flexiforce" (A201 + op-amp + analog filter + noise).
    kind: str = "flexiforce"
    # Standard deviation of the measured-force noise at the ADC, N.
    noise_std: float = 0.02
    # Cut-off of the analog low-pass filter after the op-amp, Hz.
    filter_cutoff: float = 5000.0
    # Latency of the reading, s: each sample reaches the controller this long after it
    # was taken (0 = the reading as it is, no sampling added; loop.point.AddSensorChain).
    latency: float = 0.0


@dataclass
class ControllerSection:
    # The force controller in front of each point's PID: optimal_admittance (the paper's
    # law) or pid_only (the PID on the plan alone), and the baselines a robot offers.
    kind: str = "optimal_admittance"


@dataclass
class AdmittanceSection:
    # Gamma of eq. 10 on each force-controlled axis (K is the PID's Kp on that axis).
    gamma: float = 1e-5
    # alpha of eq. 7 and 10 on each force-controlled axis, s.
    alpha: float = 0.1
    # Largest reference offset into the surface, m: a bound with anti-windup.
    max_push: float = 0.01
    # Largest reference offset away from the surface, m: bounds the integral's windup
    # when the sensor reads too high (e.g. saturated), so contact is regained quickly.
    max_retract: float = 0.1


@dataclass
class PidSection:
    # The Cartesian PID's gains on each task coordinate of a point, eq. 14.
    kp: list[float] = field(default_factory=list)
    kd: list[float] = field(default_factory=list)
    ki: list[float] = field(default_factory=list)


@dataclass
class SafetyConfig:
    # The safety layer (docs/evidence/safety.md): a bounded approach, a stiffness-aware Gamma and a
    # sensor monitor around the paper's law; false = the paper's law as printed.
    enabled: bool = False
    # Ke_max, the stated upper bound on the wall's stiffness, N/m: it sets the approach
    # speed and the damping along the normal.
    max_stiffness: float = 1e6
    # The factor between the reduced model's critical Gamma and the scheduled Gamma.
    stability_margin: float = 3.0
    # Damping ratio of the contact mode at max_stiffness (a first contact bounces below 0.19).
    damping_ratio: float = 0.25
    # An unmodelled payload or tool at the fingertip, kg: the layer adds it to the arm's
    # mass matrix as a point mass there (the approach speed and the damping follow).
    payload_mass: float = 0.0


FAULT_KINDS = (
    "sensor_nan",
    "sensor_stuck",
    "sensor_zero",
    "sensor_saturated",
    "wall_retract",
    "stiffness_jump",
    "joint_torque",
)


# The fault kinds that may keep the sensor's noise (`noisy`).
NOISY_FAULT_KINDS = ("sensor_stuck", "sensor_zero", "sensor_saturated")


# The fault kinds that read `value`.
FAULT_KINDS_WITH_VALUE = (
    "sensor_stuck",
    "sensor_saturated",
    "wall_retract",
    "stiffness_jump",
    "joint_torque",
)


@dataclass
class FaultConfig:
    # One of FAULT_KINDS: the sensor reads NaN / a stuck value / 0 N / a full-scale value;
    # the wall jumps back along +x by `value` m and returns; Ke becomes `value` N/m; an
    # external torque of `value` N m acts on joint `joint` (a link hitting something).
    kind: str = "sensor_nan"
    # When the fault starts and ends, s.
    start: float = 1.0
    end: float = 1.5
    # sensor_stuck and sensor_saturated: the reading (N); wall_retract: the jump (m);
    # stiffness_jump: Ke during the fault (N/m); joint_torque: the torque (N m, positive
    # along the joint's axis). Unused by sensor_nan and sensor_zero.
    value: float = 0.0
    # sensor_stuck, sensor_zero and sensor_saturated: keep the sensor's noise on the replaced
    # reading (a real dropout still shows the ADC's noise); false = a noise-free constant.
    noisy: bool = False
    # joint_torque: the joint's index in the arm's URDF, from the base (the planar arm:
    # 0 the shoulder, 1 the elbow, 2 the wrist). Unused by the other kinds.
    joint: int = 0

    ENTRY_SUMMARY: ClassVar[str] = "{kind, start, end, value[, joint]} mappings"
    MISSING_HINT: ClassVar[str] = (
        "a fault needs kind, start and end (s), value for "
        + ", ".join(FAULT_KINDS_WITH_VALUE)
        + ", and joint for joint_torque"
    )

    @staticmethod
    def required_fields(entry: dict) -> tuple[str, ...]:
        """kind, start and end, value for the kinds that read it, and joint for
        joint_torque: left out, they would silently take the defaults (a fault from 1 s to
        1.5 s, on the shoulder)."""
        value = ("value",) if entry.get("kind") in FAULT_KINDS_WITH_VALUE else ()
        joint = ("joint",) if entry.get("kind") == "joint_torque" else ()
        return ("kind", "start", "end", *value, *joint)


@dataclass
class LoggingConfig:
    # Logging period, s (0 = one sample per step: the integrator's, or a discrete plant's).
    period: float = 0.0
