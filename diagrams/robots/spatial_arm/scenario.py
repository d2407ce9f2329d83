"""Spatial-arm scenarios: a real arm's tool pressing and sliding on a table in six dimensions.

A spatial scenario is a YAML file whose top-level ``kind`` is ``spatial``. It describes a
serial arm loaded from a URDF or SDF file (a path, or a ``package://`` URL: the packages of
example-robot-data, ``panda_description`` and ``ur_description``, are registered in Drake's
package map automatically when the optional extra ``robots`` is installed), a tool welded to
its flange, and a table met through Drake's contact engine whose real pose differs from the
plan. The task space is the tool tip's pose in a control frame E at the planned surface
point: X = (x, y, z, rx, ry, rz), z along the planned inward normal (into the table), the
orientation as a rotation vector; the paper's law acts on z, the PID alone on the others.

Keys are named by frames and axes as ros2's admittance_controller names its parameters
(``base_frame``, ``flange_frame``, the control frame at the surface); the shared sections
(``controller``, ``admittance``, ``pid``, ``sensor``, ``logging``) are those of every robot.
Every key is checked against this schema (unknown keys, types, ranges), one line naming it,
by the package's :mod:`.validation` (``load_spatial_scenario``, ``validate_spatial``).
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

from dataclasses import dataclass, field

from admittance.diagrams.scenario.ranges import RANGES, Range
from admittance.diagrams.scenario.sections import (
    AdmittanceSection,
    ControllerSection,
    FaultConfig,
    LoggingConfig,
    PidSection,
    SafetyConfig,
    SensorSection,
)

__all__ = [
    "SPATIAL_CONTROLLER_KINDS",
    "SPATIAL_COORDINATES",
    "SPATIAL_RANGES",
    "SPATIAL_SENSOR_KINDS",
    "TOOL_SHAPES",
    "SpatialAdmittanceConfig",
    "SpatialArmConfig",
    "SpatialControllerConfig",
    "SpatialPidConfig",
    "SpatialPostureConfig",
    "SpatialSafetyConfig",
    "SpatialScenario",
    "SpatialSensorConfig",
    "SurfaceConfig",
    "ToolConfig",
    "TrajectoryPlanConfig",
]

#: The task coordinates of the tool tip in the control frame, in the order of every
#: 6-vector of gains: position of its origin, then the rotation vector of its orientation.
SPATIAL_COORDINATES = ("x", "y", "z", "rx", "ry", "rz")
#: controller.kind of a spatial arm.
SPATIAL_CONTROLLER_KINDS = ("optimal_admittance", "pid_only", "classical_admittance")
#: sensor.kind of a spatial arm: the contact engine's force along the control frame's z
#: (ideal), or the wrist's 6-axis force/torque sensor (wrench).
SPATIAL_SENSOR_KINDS = ("ideal", "wrench")
#: tool.shape.
TOOL_SHAPES = ("sphere", "disc")


@dataclass
class SpatialArmConfig:
    # The arm's description: a URDF or SDF file path (relative to the current folder, or in
    # a scenario file to that file's folder), or a package:// URL (example-robot-data's
    # panda_description and ur_description are registered when installed).
    urdf: str = "package://panda_description/urdf/panda.urdf"
    # The frame of the description welded to the world (the arm's base).
    base_frame: str = "panda_link0"
    # Where the base frame is welded, world x, y, z, m.
    base_position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # The frame the tool is welded to (its z axis points out of the arm, along the tool).
    flange_frame: str = "panda_link8"
    # Joint angles at t = 0, rad, one per actuated joint in the model's order; empty = the
    # inverse kinematics of the plan's start from joint_guess.
    initial_joints: list[float] = field(default_factory=list)
    # The inverse kinematics' starting guess (and its cost's centre), rad; empty = zeros.
    joint_guess: list[float] = field(
        default_factory=lambda: [0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.785398]
    )
    # The actuated joints' viscous damping, N m s/rad (the gearboxes' friction), added to
    # what the description states.
    joint_damping: float = 0.0


@dataclass
class SpatialPostureConfig:
    # The null-space posture task of a redundant arm (n > 6): joint stiffness, N m/rad, and
    # damping, N m s/rad, towards the initial joints, through the PID's null space.
    kp: float = 10.0
    kd: float = 2.0


@dataclass
class ToolConfig:
    # sphere (a ball on a shaft) or disc (a flat cylinder whose face touches the table).
    shape: str = "sphere"
    # Radius of the sphere or of the disc, m.
    radius: float = 0.01
    # Distance from the flange to the sphere's centre or the disc's centre, along the
    # flange's z axis, m (the Panda's hand reaches 0.11 m beyond its flange).
    length: float = 0.15
    # The disc's thickness, m.
    thickness: float = 0.005
    # The tool's mass, kg, at the middle of its length (the F/T sensor sees its weight).
    mass: float = 0.2


@dataclass
class SurfaceConfig:
    # The planned contact point, world x and y, m: the start of the slide.
    position: list[float] = field(default_factory=lambda: [0.5, 0.0])
    # The planned height of the table's top there, world z, m.
    height: float = 0.2
    # The real table's top is this much higher than planned at that point, m (+ = higher).
    height_error: float = 0.0
    # The real table is tilted about world x, then about world y, through the planned
    # point, degrees (the plan assumes it level).
    tilt_x: float = 0.0
    tilt_y: float = 0.0
    # Point-contact stiffness of the tool on the table (tool, pad and table in series),
    # N/m.
    stiffness: float = 1.0e5
    # Hunt-Crossley dissipation of that contact, s/m (at 10 N: 200 N s/m of damping).
    dissipation: float = 20.0
    # Coulomb friction coefficient between tool and table (static = dynamic).
    friction: float = 0.2
    # The discrete plant's stiction tolerance v_s, m/s.
    stiction_tolerance: float = 1.0e-3


@dataclass
class TrajectoryPlanConfig:
    # The tool tip starts this far above the planned surface, m, at rest.
    approach_height: float = 0.02
    # Time to move down onto the planned surface, s.
    approach_time: float = 1.0
    # Then the desired force ramps from 0 to force_reference over this time, s.
    force_ramp_time: float = 1.0
    # Then the press is held this long before the slide, s.
    press_time: float = 2.0
    # Slide along the table by this distance and back, m (0 = press only).
    slide_distance: float = 0.0
    # At this speed, m/s.
    slide_speed: float = 0.02
    # Direction of the slide in the table's plane, degrees from world x towards world y.
    slide_direction: float = 0.0
    # Time to reach the slide speed and to stop, s (cubic blends).
    blend_time: float = 0.5


@dataclass
class SpatialControllerConfig(ControllerSection):
    # optimal_admittance (the paper's law on z), pid_only (the PID on the plan alone) or
    # classical_admittance (mass-damper-spring on the force error, as ros2's
    # admittance_controller), with its gains:
    kind: str = "optimal_admittance"
    # classical_admittance: virtual mass, kg,
    mass: float = 0.9
    # damping, N s/m (matched to the paper's law: 1 / (Gamma K) = 83 N s/m gives the same
    # integral action; the mass makes the force loop critically damped, D^2 / (4 k_eff)),
    damping: float = 83.0
    # virtual spring, N/m (0 = mass-damper).
    stiffness: float = 0.0


@dataclass
class SpatialAdmittanceConfig(AdmittanceSection):
    # Gamma of eq. 10 on z (K is pid.kp[2]): the force loop crosses over near
    # Gamma K k_eff = 24 rad/s (k_eff, the PID's stiffness in series with the contact's),
    # under the contact's resonance (~220 rad/s with the arm's apparent mass); 2e-5
    # bounces on the first contact (docs/evidence/spatial-arm.md).
    gamma: float = 6.0e-6
    # alpha of eq. 7 and 10, s (sampled at time_step: 0, as the gripper's).
    alpha: float = 0.0
    # Largest reference offset into the table, m (a table 5 mm low and tilted 10 degrees
    # across a 10 cm slide needs about 28 mm).
    max_push: float = 0.05
    # Largest reference offset away from it, m.
    max_retract: float = 0.05


@dataclass
class SpatialPidConfig(PidSection):
    # The Cartesian PID's gains on (x, y, z, rx, ry, rz) of the tool tip in the control
    # frame, eq. 14: N/m and N m/rad, and their D and I counterparts.
    kp: list[float] = field(default_factory=lambda: [5000.0, 5000.0, 2000.0, 100.0, 100.0, 60.0])
    kd: list[float] = field(default_factory=lambda: [150.0, 150.0, 100.0, 4.0, 4.0, 2.0])
    ki: list[float] = field(default_factory=lambda: [20000.0, 20000.0, 0.0, 200.0, 200.0, 100.0])


@dataclass
class SpatialSensorConfig(SensorSection):
    # ideal: the contact engine's force of the tool on the table along the control frame's
    # z (no noise, no filter); wrench: a 6-axis force/torque sensor at the weld between the
    # flange and the tool (tool_weld), its weight compensated from tool.mass, its force
    # read along the control frame's z.
    kind: str = "ideal"
    # wrench: the noise's standard deviation on each force axis, N,
    noise_std: float = 0.0
    # and on each torque axis, N m.
    torque_noise_std: float = 0.0
    # wrench: cut-off of its first-order low-pass, Hz (0 = none).
    filter_cutoff: float = 0.0
    # wrench: its readout period, s (0 = time_step).
    period: float = 0.0
    # wrench: its constant bias (fx, fy, fz in N, tx, ty, tz in N m), in its own frame.
    bias: list[float] = field(default_factory=lambda: [0.0] * 6)


@dataclass
class SpatialSafetyConfig(SafetyConfig):
    # The shared keys (enabled; max_stiffness, Ke_max of the table and the tool in
    # series, N/m; stability_margin; damping_ratio; payload_mass at the tool tip, kg), and:
    # Fmax, the bound on the force along the planned normal, N (the planar arm's is
    # admittance.max_force): the approach speed v_max is the one whose impact on a table
    # of max_stiffness peaks at it, with the arm's apparent mass along the normal with the
    # PID's other axes held (docs/evidence/safety-spatial.md, section 10).
    max_force: float = 20.0


@dataclass
class SpatialScenario:
    # Scenario kind: always "spatial" here.
    kind: str = "spatial"
    # Simulated time, s (at least the approach, the ramp and the press; the slide's metrics
    # are taken over the part of the slide it covers).
    duration: float = 6.0
    # Seed of every noise source.
    seed: int = 0
    # Fr: the desired force of the tool on the table along the planned normal, N.
    force_reference: float = 10.0
    # Step of the discrete plant (SAP, point contact) and period of the controllers, s.
    time_step: float = 0.001
    arm: SpatialArmConfig = field(default_factory=SpatialArmConfig)
    posture: SpatialPostureConfig = field(default_factory=SpatialPostureConfig)
    tool: ToolConfig = field(default_factory=ToolConfig)
    surface: SurfaceConfig = field(default_factory=SurfaceConfig)
    trajectory: TrajectoryPlanConfig = field(default_factory=TrajectoryPlanConfig)
    controller: SpatialControllerConfig = field(default_factory=SpatialControllerConfig)
    admittance: SpatialAdmittanceConfig = field(default_factory=SpatialAdmittanceConfig)
    pid: SpatialPidConfig = field(default_factory=SpatialPidConfig)
    sensor: SpatialSensorConfig = field(default_factory=SpatialSensorConfig)
    safety: SpatialSafetyConfig = field(default_factory=SpatialSafetyConfig)
    # Injected faults of the force reading (the shared section's sensor kinds: the reading
    # along the control frame's z reads NaN, a stuck value, 0 N or a full-scale value);
    # none by default.
    faults: list[FaultConfig] = field(default_factory=list)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    # Name of the scenario (informational).
    name: str = "custom_spatial"

    @property
    def press_start(self) -> float:
        """When the tool has reached the planned surface and Fr starts its ramp, s."""
        return self.trajectory.approach_time

    @property
    def slide_start(self) -> float:
        """When the press has been held for press_time and the slide starts, s."""
        t = self.trajectory
        return t.approach_time + t.force_ramp_time + t.press_time

    @property
    def slide_end(self) -> float:
        """When the slide is back at its start (= slide_start without a slide), s."""
        t = self.trajectory
        if t.slide_distance == 0:
            return self.slide_start
        return self.slide_start + 2.0 * (t.slide_distance / t.slide_speed + t.blend_time)


# Every key that is one number in a range, in the order they are checked.
SPATIAL_RANGES: dict[str, Range] = {
    "duration": Range("(0, 1e4]", "s"),
    "seed": RANGES["seed"],
    "force_reference": Range("(0, 100]", "N"),
    "time_step": Range("[1e-4, 5e-3]", "s"),
    "arm.joint_damping": Range("[0, 100]", "N m s/rad"),
    "posture.kp": Range("[0, 1e4]", "N m/rad"),
    "posture.kd": Range("[0, 1e3]", "N m s/rad"),
    "tool.radius": Range("[0.002, 0.1]", "m"),
    "tool.length": Range("[0, 0.5]", "m"),
    "tool.thickness": Range("[0.001, 0.05]", "m"),
    "tool.mass": Range("(0, 5]", "kg"),
    "surface.height": Range("[-1, 2]", "m"),
    "surface.height_error": Range("[-0.02, 0.02]", "m"),
    "surface.tilt_x": Range("[-30, 30]", "degrees"),
    "surface.tilt_y": Range("[-30, 30]", "degrees"),
    "surface.stiffness": Range("[1e3, 1e7]", "N/m"),
    "surface.dissipation": Range("[0, 1000]", "s/m"),
    "surface.friction": Range("[0, 2]"),
    "surface.stiction_tolerance": Range("[1e-7, 0.01]", "m/s"),
    "trajectory.approach_height": Range("[0, 0.2]", "m"),
    "trajectory.approach_time": Range("(0, 100]", "s"),
    "trajectory.force_ramp_time": Range("(0, 100]", "s"),
    "trajectory.press_time": Range("[0, 1000]", "s"),
    "trajectory.slide_distance": Range("[0, 1]", "m"),
    "trajectory.slide_speed": Range("(0, 0.5]", "m/s"),
    "trajectory.slide_direction": Range("[-360, 360]", "degrees"),
    "trajectory.blend_time": Range("(0, 10]", "s"),
    "controller.mass": Range("(0, 1000]", "kg"),
    "controller.damping": Range("(0, 1e6]", "N s/m"),
    "controller.stiffness": Range("[0, 1e6]", "N/m"),
    "admittance.gamma": Range("(0, 0.001]"),
    "admittance.alpha": Range("[0, 1]", "s"),
    "admittance.max_push": Range("(0, 0.1]", "m"),
    "admittance.max_retract": Range("(0, 0.2]", "m"),
    "sensor.noise_std": Range("[0, 10]", "N"),
    "sensor.torque_noise_std": Range("[0, 1]", "N m"),
    "sensor.filter_cutoff": Range("[0, 1e6]", "Hz", text="0 (none) or in (0, 1e6] Hz"),
    "sensor.period": Range("[1e-4, 0.1]", or_zero=True, text="0 (time_step) or in [1e-4, 0.1] s"),
    "logging.period": RANGES["logging.period"],
    "safety.max_stiffness": Range("(0, 1e7]", "N/m"),
    "safety.max_force": Range("(0, 1000]", "N"),
    "safety.stability_margin": RANGES["safety.stability_margin"],
    "safety.damping_ratio": RANGES["safety.damping_ratio"],
    "safety.payload_mass": RANGES["safety.payload_mass"],
}
