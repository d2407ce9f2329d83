"""Grasp scenarios: Drake's planar gripper holding its brick with one force loop per finger.

A grasp scenario is a YAML file whose top-level ``kind`` is ``grasp`` (an arm scenario has
no ``kind``, or ``kind: arm``). It is loaded by the same ``load_scenario`` (and so by
``admittance simulate``), with its own schema below: a grasp has no wall and no arm
trajectory, and an arm has no brick or fingers, so neither schema carries keys that the
other would silently ignore, and every key is checked against its own schema (unknown keys,
types and ranges, one line naming the key). The arm's schema is left as it was.

The fingers are numbered as in Drake's model (planar_gripper.sdf): finger1 and finger2
above the brick on either side, finger3 below it. Per-finger lists are in that order.
"""

# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import math
import typing
from dataclasses import dataclass, field

from pydrake.systems.analysis import SimulatorConfig

from admittance.diagrams.scenario.ranges import (
    RANGES,
    Range,
    require,
    require_one_of,
    require_range,
    value_of,
)
from admittance.diagrams.scenario.schema import (
    INTEGRATION_SCHEMES,
    load_typed,
)
from admittance.diagrams.scenario.sections import (
    AdmittanceSection,
    ControllerSection,
    LoggingConfig,
    PidSection,
    SensorSection,
    implicit_simulator_config,
)

__all__ = [
    "FINGERS",
    "GRASP_CONTROLLER_KINDS",
    "GRASP_DISTURBANCE_KINDS",
    "GraspAdmittanceConfig",
    "GraspBrickConfig",
    "GraspContactConfig",
    "GraspControllerConfig",
    "GraspDisturbanceConfig",
    "GraspPidConfig",
    "GraspPlanConfig",
    "GraspScenario",
    "GraspSensorConfig",
    "load_grasp_scenario",
    "validate_grasp",
]

#: The fingers of Drake's planar gripper, in the order of every per-finger list.
FINGERS = ("finger1", "finger2", "finger3")
#: controller.kind of a grasp: the paper's law on each finger, or position-only fingers.
GRASP_CONTROLLER_KINDS = ("optimal_admittance", "pid_only")
#: disturbance.kind of a grasp.
GRASP_DISTURBANCE_KINDS = ("none", "force_pulse", "mass_step")


@dataclass
class GraspBrickConfig:
    # How much larger the real brick is than the plan assumes, along both of its edges in
    # the plane of the hand, m (+ = larger; the real brick is Drake's 0.1 m x 0.1 m).
    size_error: float = 0.0
    # Real contact stiffness over the one the plan assumes (contact.stiffness): 10 = ten
    # times stiffer than planned, 0.1 = ten times softer.
    stiffness_error: float = 1.0


@dataclass
class GraspContactConfig:
    # Point-contact stiffness of a fingertip on the brick that the plan assumes (fingertip
    # cover, sensor and brick in series), N/m.
    stiffness: float = 1.0e4
    # Hunt-Crossley dissipation of that contact, s/m.
    dissipation: float = 10.0
    # Coulomb friction coefficient between fingertip and brick (static = dynamic).
    friction: float = 0.5
    # The discrete plant's stiction tolerance v_s, m/s (Drake's default): SAP regularizes
    # friction, so a tip carrying a tangential load slips at a speed of the order of
    # v_s f_t / (mu N), or of SAP's own floor where that is larger (docs/evidence/grasp.md, "The
    # creep of a held brick").
    stiction_tolerance: float = 1.0e-4


@dataclass
class GraspPlanConfig:
    # Gap between each side fingertip and its planned face at t = 0, m.
    open_distance: float = 0.01
    # Time the side fingers take to close on the planned brick, s.
    close_time: float = 0.5
    # After closing, time over which every desired force ramps from the force read at
    # t = 0 to its force_reference, s.
    force_ramp_time: float = 0.5
    # Height of the side contacts above the brick's planned centre, m.
    side_contact_height: float = 0.02


@dataclass
class GraspControllerConfig(ControllerSection):
    # optimal_admittance (the paper's law on every finger) or pid_only (position-only
    # fingers on the plan, which presses each planned face by Fr / contact.stiffness, the
    # paper's eq. 6 on the planned brick).
    kind: str = "optimal_admittance"


@dataclass
class GraspAdmittanceConfig(AdmittanceSection):
    # Gamma of eq. 10 on each finger's normal axis (K is the finger's pid.kp[0]).
    gamma: float = 1.0e-5
    # alpha of eq. 7 and 10, s. Sampled at time_step, alpha passes each force sample
    # straight to the PID and excites the brick's contact resonance: with Ke = 1e5 N/m
    # 0.02 oscillates and 0.01 holds (docs/evidence/grasp.md), so 0, as the arm's 1 kHz
    # digital controller.
    alpha: float = 0.0
    # Largest reference offset into the brick, m (bounded, with anti-windup).
    max_push: float = 0.005
    # Largest reference offset away from the brick, m.
    max_retract: float = 0.02


@dataclass
class GraspPidConfig(PidSection):
    # Each finger's tip PID gains on (normal, tangent) of its face, eq. 14 (the paper's
    # x-y simulation values).
    kp: list[float] = field(default_factory=lambda: [2500.0, 2500.0])
    kd: list[float] = field(default_factory=lambda: [50.0, 50.0])
    ki: list[float] = field(default_factory=lambda: [200.0, 200.0])


@dataclass
class GraspSensorConfig(SensorSection):
    # "ideal" (the contact engine's force) or "flexiforce" (A201 + op-amp + filter + noise),
    # read by the ADC once per time_step.
    kind: str = "flexiforce"
    # Standard deviation of the measured-force noise, N.
    noise_std: float = 0.02
    # Cut-off of the analog low-pass filter after the op-amp, Hz.
    filter_cutoff: float = 5000.0


@dataclass
class GraspDisturbanceConfig:
    # none, force_pulse (a force on the brick's centre during [start, start + duration])
    # or mass_step (the brick's mass times mass_scale from start on).
    kind: str = "none"
    # When the disturbance starts, s.
    start: float = 4.0
    # force_pulse: how long it lasts, s.
    duration: float = 0.1
    # force_pulse: the force on the brick (world y, world z; gravity is -z), N.
    force: list[float] = field(default_factory=lambda: [0.0, -1.0])
    # mass_step: the brick's mass from `start` on, over its model mass.
    mass_scale: float = 2.0


def _default_simulator_config() -> SimulatorConfig:
    # Used only with time_step = 0 (a continuous plant and controllers): the contact and
    # the 5 kHz sensor filter make the loop stiff, so an implicit integrator.
    return implicit_simulator_config(max_step_size=0.01)


@dataclass
class GraspScenario:
    # Scenario kind: always "grasp" here (arm scenarios have no kind).
    kind: str = "grasp"
    # Simulated time, s.
    duration: float = 12.0
    # Seed of every noise source.
    seed: int = 0
    # Fr per finger (finger1, finger2, finger3): desired normal force on the brick, N.
    force_reference: list[float] = field(default_factory=lambda: [2.0, 2.0, 1.0])
    # Step of the discrete plant (SAP, point contact) and period of the sampled
    # controllers and sensor readout, s; 0 = a continuous plant and controllers, integrated
    # by `simulator` (about 20 times slower; docs/evidence/grasp.md).
    time_step: float = 0.001
    brick: GraspBrickConfig = field(default_factory=GraspBrickConfig)
    contact: GraspContactConfig = field(default_factory=GraspContactConfig)
    plan: GraspPlanConfig = field(default_factory=GraspPlanConfig)
    controller: GraspControllerConfig = field(default_factory=GraspControllerConfig)
    admittance: GraspAdmittanceConfig = field(default_factory=GraspAdmittanceConfig)
    pid: GraspPidConfig = field(default_factory=GraspPidConfig)
    sensor: GraspSensorConfig = field(default_factory=GraspSensorConfig)
    disturbance: GraspDisturbanceConfig = field(default_factory=GraspDisturbanceConfig)
    simulator: SimulatorConfig = field(default_factory=_default_simulator_config)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    # Name of the scenario (informational).
    name: str = "custom_grasp"

    @property
    def controller_kind(self) -> str:
        return self.controller.kind

    @property
    def true_contact_stiffness(self) -> float:
        """The real contact stiffness, N/m: the planned one times brick.stiffness_error."""
        return self.contact.stiffness * self.brick.stiffness_error

    @property
    def force_ramp_end(self) -> float:
        """When every desired force has reached its force_reference, s."""
        return self.plan.close_time + self.plan.force_ramp_time


# Every key that is one number in a range, in the order they are checked (the arm's
# validation.Range: the message states the range as written here).
GRASP_RANGES: dict[str, Range] = {
    "duration": Range("(0, 1e4]", "s"),
    "seed": RANGES["seed"],
    # SAP is stable at any step, but the sampled controllers and the FlexiForce readout run
    # at this period too.
    "time_step": Range("[1e-4, 5e-3]", or_zero=True, text="0 (continuous) or in [0.0001, 0.005] s"),
    # The fingertips reach faces within about 1 cm of the planned ones.
    "brick.size_error": Range("[-0.01, 0.01]", "m"),
    "brick.stiffness_error": Range("[0.01, 100]", "(ratio)"),
    "contact.stiffness": Range("(0, 1e7]", "N/m"),
    "contact.dissipation": Range("[0, 1000]", "s/m"),
    "contact.friction": Range("(0, 2]"),
    # Drake needs v_s > 0; above 1 cm/s a tip slips visibly under any tangential load.
    "contact.stiction_tolerance": Range("[1e-7, 0.01]", "m/s"),
    "plan.open_distance": Range("[0, 0.03]", "m"),
    "plan.close_time": Range("(0, 10]", "s"),
    "plan.force_ramp_time": Range("(0, 10]", "s"),
    "plan.side_contact_height": Range("[-0.03, 0.03]", "m"),
    "admittance.gamma": Range("(0, 0.001]"),
    "admittance.alpha": Range("[0, 1]", "s"),
    "admittance.max_push": Range("(0, 0.02]", "m"),
    "admittance.max_retract": Range("(0, 0.05]", "m"),
    "sensor.noise_std": Range("[0, 10]", "N"),
    "sensor.filter_cutoff": Range("(0, 1e6]", "Hz"),
    "sensor.latency": RANGES["sensor.latency"],
    "disturbance.duration": Range("(0, 1000]", "s"),
    "disturbance.mass_scale": Range("(0, 10]"),
    "simulator.accuracy": RANGES["simulator.accuracy"],
    "simulator.max_step_size": RANGES["simulator.max_step_size"],
    "logging.period": RANGES["logging.period"],
}
# Each finger's PID gains on (normal, tangent).
GRASP_PID_GAINS: dict[str, Range] = {
    "kp": Range("(0, 1e5]", text="2 values (normal, tangent), > 0 and <= 1e+05"),
    "kd": Range("[0, 1e4]", text="2 values (normal, tangent), >= 0 and <= 10000"),
    "ki": Range("[0, 1e5]", text="2 values (normal, tangent), >= 0 and <= 1e+05"),
}
# The real contact stiffness (planned times brick.stiffness_error), N/m.
MAX_CONTACT_STIFFNESS = 1e7


def validate_grasp(scenario: GraspScenario) -> GraspScenario:
    """Every key checked; raises ScenarioError naming the first bad key and what is allowed.

    The ranges of GRASP_RANGES first, then lists, choices, and the checks that relate keys.
    """
    s = scenario
    require(s.kind == "grasp", "kind", "'grasp' for a grasp scenario", s.kind)
    for key, allowed in GRASP_RANGES.items():
        require_range(value_of(s, key), key, allowed)
    _check_grasp_lists(s)
    _check_grasp_choices(s)
    _check_grasp_dependent_keys(s)
    return scenario


def _check_grasp_lists(s: GraspScenario) -> None:
    """The lists: one Fr per finger, the PID's two gains, the disturbance's force."""
    require(
        len(s.force_reference) == len(FINGERS)
        and all(math.isfinite(f) and 0 < f <= 50 for f in s.force_reference),
        "force_reference",
        f"{len(FINGERS)} values in (0, 50] N (finger1, finger2, finger3)",
        s.force_reference,
    )
    for name, allowed in GRASP_PID_GAINS.items():
        gains = getattr(s.pid, name)
        require(
            len(gains) == 2 and all(map(allowed.allows, gains)),
            f"pid.{name}",
            allowed.allowed(),
            gains,
        )
    d = s.disturbance
    require(
        len(d.force) == 2 and all(math.isfinite(f) and abs(f) <= 20 for f in d.force),
        "disturbance.force",
        "2 values (world y, world z) within [-20, 20] N",
        d.force,
    )


def _check_grasp_choices(s: GraspScenario) -> None:
    """The choices among names: controller, sensor, disturbance, integration scheme."""
    require_one_of(s.controller.kind, "controller.kind", GRASP_CONTROLLER_KINDS)
    require_one_of(s.sensor.kind, "sensor.kind", ("ideal", "flexiforce"))
    require_one_of(s.disturbance.kind, "disturbance.kind", GRASP_DISTURBANCE_KINDS)
    require_one_of(
        s.simulator.integration_scheme, "simulator.integration_scheme", INTEGRATION_SCHEMES
    )


def _check_grasp_dependent_keys(s: GraspScenario) -> None:
    """The keys that depend on others: the start, the real contact stiffness, the duration,
    the disturbance's start, the reach, and what the sensor can read."""
    d = s.disturbance
    require(s.simulator.start_time == 0.0, "simulator.start_time", "0", s.simulator.start_time)
    require(
        s.true_contact_stiffness <= MAX_CONTACT_STIFFNESS,
        "brick.stiffness_error",
        f"<= {MAX_CONTACT_STIFFNESS / s.contact.stiffness:.3g} with contact.stiffness = "
        f"{s.contact.stiffness:g} N/m (the real stiffness stays <= {MAX_CONTACT_STIFFNESS:g} "
        "N/m)",
        s.brick.stiffness_error,
    )
    require(
        s.force_ramp_end < s.duration,
        "duration",
        f"> plan.close_time + plan.force_ramp_time = {s.force_ramp_end:g} s",
        s.duration,
    )
    require(
        d.kind == "none" or (math.isfinite(d.start) and 0 <= d.start < s.duration),
        "disturbance.start",
        f"in [0, duration = {s.duration:g}) s",
        d.start,
    )
    if s.controller.kind == "optimal_admittance":
        needed = max(s.force_reference) / s.pid.kp[0]
        require(
            s.admittance.max_push > needed,
            "admittance.max_push",
            f"> max(force_reference) / pid.kp[0] = {needed:.3g} m (the PID's push at the "
            "bound must exceed Fr)",
            s.admittance.max_push,
        )
    require(
        s.time_step > 0 or s.sensor.kind == "flexiforce",
        "sensor.kind",
        "flexiforce with time_step = 0 (a continuous plant's contact results depend on its "
        "actuation: the sensor's filter breaks that loop)",
        s.sensor.kind,
    )
    if s.sensor.kind == "flexiforce":
        from admittance.systems.flexiforce import FlexiForceSensor

        full_scale = FlexiForceSensor().saturation_force
        require(
            max(s.force_reference) < 0.9 * full_scale,
            "force_reference",
            f"< {0.9 * full_scale:.4g} N with sensor.kind=flexiforce (90 % of full scale)",
            s.force_reference,
        )


def load_grasp_scenario(
    data: dict,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
) -> GraspScenario:
    """A validated grasp scenario from a YAML file's mapping and dotted-key overrides.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data = dict(data)
    data.setdefault("kind", "grasp")
    return validate_grasp(load_typed(data, GraspScenario, overrides))
