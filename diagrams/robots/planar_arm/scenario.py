"""The planar arm's scenario: the paper's 3-DOF arm pressing its compliant wall.

A tree of dataclasses loaded with Drake's ``yaml_load_typed``. Every field has a default
equal to the paper's value (Section VII-A); the built-in scenarios override what differs.
``--set`` overrides use the dotted key of a field (``wall.stiffness``, ``admittance.gamma``).
The sections every robot shares (``logging``, ``safety``) are declared once in
:mod:`admittance.diagrams.scenario.sections`.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from pydrake.systems.analysis import SimulatorConfig

from admittance.diagrams.scenario.sections import (
    AdmittanceSection,
    ControllerSection,
    FaultConfig,
    LoggingConfig,
    PidSection,
    SafetyConfig,
    SensorSection,
    implicit_simulator_config,
)
from admittance.urdf import URDF_DIR

__all__ = [
    "AdmittanceConfig",
    "ArmConfig",
    "CONTROLLER_KINDS",
    "ControllerConfig",
    "PidConfig",
    "Scenario",
    "SensorConfig",
    "StiffnessStep",
    "TrajectoryConfig",
    "WallConfig",
]


def _default_simulator_config() -> SimulatorConfig:
    # The loop is stiff (wall up to 1e5 N/m, Kd = 5 on a light last link: a pole near
    # -1e4 1/s), so the implicit integrator, with steps up to 50 ms.
    return implicit_simulator_config(max_step_size=0.05)


@dataclass
class StiffnessStep:
    # Time at which the wall stiffness jumps, s.
    time: float = 15.0
    # Wall stiffness from that time on, N/m.
    stiffness: float = 1e5

    # How a list of them is described, and what an entry must give: left out, a field
    # would silently take its default (a step to 1e5 N/m at 15 s).
    ENTRY_SUMMARY: ClassVar[str] = "{time: s, stiffness: N/m} mappings"
    MISSING_HINT: ClassVar[str] = "a stiffness step needs time (s) and stiffness (N/m)"

    @staticmethod
    def required_fields(entry: dict) -> tuple[str, ...]:
        return ("time", "stiffness")


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


@dataclass
class AdmittanceConfig(AdmittanceSection):
    # The shared keys (gamma, alpha on the wall-normal axis; max_push into the wall, +x;
    # max_retract away from it, -x), and:
    # false = the PID alone on Xd (the unsafe baseline).
    enabled: bool = True
    # Sampling period of a digital admittance block, s (0 = continuous, the paper's law).
    period: float = 0.0
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
class ControllerConfig(ControllerSection):
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
    # crossover Kp Gamma K, docs/evidence/comparison.md); "manual" takes the values below.
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
class PidConfig(PidSection):
    # Cartesian PID gains on (x, y, theta), eq. 14 (Section VII-A's simulation values).
    kp: list[float] = field(default_factory=lambda: [2500.0, 2500.0, 1000.0])
    kd: list[float] = field(default_factory=lambda: [50.0, 50.0, 5.0])
    ki: list[float] = field(default_factory=lambda: [200.0, 200.0, 200.0])
    # Sampling period of a digital PID, s (0 = continuous).
    period: float = 0.0


@dataclass
class SensorConfig(SensorSection):
    # The shared keys (kind, noise_std, filter_cutoff), and:
    # Sampling period of the noise (the ADC period), s.
    noise_period: float = 0.005
    # The FlexiForce's loading-unloading band, a fraction of the force (datasheet: < 4.5 %
    # of full scale; 0 = none, the model of systems/flexiforce.py).
    hysteresis: float = 0.0
    # The FlexiForce's drift, a fraction of the reading per decade of time under load
    # (datasheet: < 5 % per logarithmic time scale; 0 = none).
    drift: float = 0.0


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
    # A point mass welded at the fingertip frame, kg: a tool or a grasped part the URDF does
    # not carry. The simulated arm has it; the safety layer's model of the arm does not
    # (safety.payload_mass is what the layer is told).
    payload_mass: float = 0.0
    # Viscous friction of each motor, N m s/rad at the motor shaft: joint i gets N_i^2 times
    # it (N_i its gear ratio in the URDF), as Drake joint damping. 0 = none (the paper's
    # model); docs/evidence/safety-sensor-faults.md section 3 states a value for the URDF's motors
    # and gearheads.
    motor_damping: float = 0.0
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
