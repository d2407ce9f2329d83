"""The allowed values of scenario keys: :class:`Range` (an interval or a bound, as the
message states it), the ranges of the keys every robot shares, and the one-line checks
(``<key>: must be <allowed>, got <value>``) every robot's validation uses.
"""

from __future__ import annotations

import dataclasses
import math
import re
import typing

from admittance.diagrams.scenario.schema import ScenarioError

__all__ = [
    "MAX_SEED",
    "MAX_STIFFNESS",
    "PID_GAINS",
    "RANGES",
    "Range",
    "check_fault_timing",
    "check_joint_torque_value",
    "require",
    "require_one_of",
    "require_range",
    "value_of",
]


# Stiffer than any contact a robot here can make (steel on steel at this scale is ~1e9 N/m).
MAX_STIFFNESS = 1e9


# Drake's RandomGenerator (a 32-bit Mersenne twister) takes the seed modulo 2**32.
MAX_SEED = 2**32 - 1


_INTERVAL = re.compile(r"^([(\[])\s*(\S+),\s*(\S+)\s*([)\]])$")


_BOUND = re.compile(r"^(>=|>|<=|<)\s*(\S+)$")


@dataclasses.dataclass(frozen=True)
class Range:
    """The allowed values of one number: an interval such as ``(0, 1e5]`` or a bound such
    as ``>= 0``; always finite.

    Attributes:
        spec: the interval or bound, as the message writes it.
        note: unit and explanation written after it (``s``, ``N (compressive)``).
        text: the whole allowed-text, where it reads better than spec and note.
    """

    spec: str
    note: str = ""
    text: str | None = None
    # 0 is allowed too (it switches the feature off: a continuous controller, no pacing).
    or_zero: bool = False

    def allows(self, value: float) -> bool:
        try:
            if not math.isfinite(value):
                return False
        except OverflowError:  # an integer beyond any float
            return False
        if self.or_zero and value == 0:
            return True
        interval = _INTERVAL.match(self.spec)
        if interval:
            opening, low, high, closing = interval.groups()
            above = value > float(low) if opening == "(" else value >= float(low)
            below = value < float(high) if closing == ")" else value <= float(high)
            return above and below
        operator, bound = _BOUND.match(self.spec).groups()
        bound = float(bound)
        return {
            ">=": value >= bound,
            ">": value > bound,
            "<=": value <= bound,
            "<": value < bound,
        }[operator]

    def allowed(self) -> str:
        if self.text is not None:
            return self.text
        prefix = "in " if _INTERVAL.match(self.spec) else ""
        return prefix + self.spec + (f" {self.note}" if self.note else "")


# Every key that is one number in a range, in the order they are checked.
RANGES: dict[str, Range] = {
    "duration": Range("(0, 1e5]", "s"),
    # Drake's RandomGenerator keeps 32 bits of a seed: 2**32 would repeat seed 0.
    "seed": Range(f"[0, {MAX_SEED}]", "(a 32-bit seed)"),
    "force_reference": Range("> 0", "N (compressive)"),
    "wall.position": Range("> 0", text="in front of the base (> 0 m along x)"),
    "wall.stiffness": Range(f"(0, {MAX_STIFFNESS:g}]", "N/m"),
    "wall.velocity": Range("[-1, 1]", "m/s"),
    "wall.motion_start": Range(">= 0", "s"),
    # The joint velocity limits bound it further (robots.planar_arm.loop.CheckTrajectoryReachable).
    "trajectory.frequency": Range("[0, 100]", "Hz"),
    "admittance.gamma": Range("(0, 0.1]"),
    "admittance.alpha": Range("[0, 10]", "s"),
    "admittance.period": Range(
        ">= 1e-5", or_zero=True, text="0 (continuous) or >= 1e-5 s (a 100 kHz controller)"
    ),
    "admittance.max_push": Range("(0, 0.5]", "m"),
    "admittance.max_retract": Range("(0, 0.5]", "m"),
    "admittance.force_bound_gain": Range("(0, 100]"),
    "controller.wall_position_error": Range("[-0.1, 0.1]", "m"),
    "controller.stiffness_error": Range("[-0.9, 10]", "(relative)"),
    "controller.mass": Range("(0, 1000]"),
    "controller.damping": Range("(0, 1e+06]"),
    "controller.adaptation_rate": Range("(0, 10000]"),
    "controller.stiffness": Range("[0, 1e6]", "N/m"),
    "pid.period": Range(
        ">= 1e-5", or_zero=True, text="0 (continuous) or >= 1e-5 s (a 100 kHz controller)"
    ),
    "sensor.noise_std": Range("[0, 100]", "N"),
    "sensor.noise_period": Range(">= 1e-5", "s (a 100 kHz ADC)"),
    "sensor.filter_cutoff": Range("(0, 1e6]", "Hz"),
    "sensor.hysteresis": Range("[0, 0.1]", "(fraction of the force)"),
    "sensor.drift": Range("[0, 0.1]", "(fraction per decade of time under load)"),
    # From the sample to the controller: up to 20 ms (a slow fieldbus).
    "sensor.latency": Range("[0, 0.02]", "s"),
    # Finer than 1e-8 the implicit integrator crawls (1e-10: ten times slower than 1e-8)
    # or gives up at the start.
    "simulator.accuracy": Range("[1e-8, 0.1]"),
    "simulator.max_step_size": Range(">= 1e-6", "s"),
    # A pace of the run relative to real time: a tiny one would never finish.
    "simulator.target_realtime_rate": Range(
        ">= 0.01", or_zero=True, text="0 (as fast as possible) or >= 0.01 (x real time)"
    ),
    # The metrics average over 1 s windows: at least ten samples in each.
    "logging.period": Range("[1e-5, 0.1]", or_zero=True, text="0 (every step) or in [1e-5, 0.1] s"),
    "safety.max_stiffness": Range(f"(0, {MAX_STIFFNESS:g}]", "N/m"),
    "safety.stability_margin": Range("[1, 100]"),
    # A first contact bounces below 0.19 (systems/contact_model.py).
    "safety.damping_ratio": Range("[0.2, 2]", "(a first contact bounces below 0.19)"),
    # A point mass at the fingertip that the URDF does not carry (a tool, a grasped part).
    "safety.payload_mass": Range("[0, 10]", "kg"),
    "arm.payload_mass": Range("[0, 10]", "kg"),
    # Viscous friction at the motor shaft (docs/evidence/safety-sensor-faults.md, section 3: 2.4e-6
    # stated).
    "arm.motor_damping": Range("[0, 1e-3]", "N m s/rad"),
}


# The PID's gains, each axis.
PID_GAINS: dict[str, Range] = {
    "kp": Range("(0, 1e6]", text="> 0 and <= 1e+06 on every axis"),
    "kd": Range("[0, 1e5]", text=">= 0 and <= 100000 on every axis"),
    "ki": Range("[0, 1e6]", text=">= 0 and <= 1e+06 on every axis"),
}


def require(condition: bool, key: str, allowed: str, value) -> None:
    if not condition:
        raise ScenarioError(f"{key}: must be {allowed}, got {value!r}")


def require_one_of(value, key: str, choices: typing.Sequence[str]) -> None:
    require(value in choices, key, "one of " + ", ".join(choices), value)


def require_range(value, key: str, allowed: Range) -> None:
    require(allowed.allows(value), key, allowed.allowed(), value)


def value_of(scenario, key: str):
    value = scenario
    for part in key.split("."):
        value = getattr(value, part)
    return value


def check_fault_timing(fault, key: str, kinds) -> None:
    """A fault entry's kind (one of `kinds`), its start (>= 0 s), end (> start) and a
    finite value; what each kind asks of its value is the robot's to check."""
    finite = math.isfinite
    require_one_of(fault.kind, key + ".kind", kinds)
    require(finite(fault.start) and fault.start >= 0, key + ".start", ">= 0 s", fault.start)
    require(finite(fault.end) and fault.end > fault.start, key + ".end", "> start", fault.end)
    require(finite(fault.value), key + ".value", "finite", fault.value)


def check_joint_torque_value(fault, key: str, max_torque: float) -> None:
    """A joint_torque fault's value: non-zero and within +-`max_torque` N m."""
    require(
        fault.value != 0 and abs(fault.value) <= max_torque,
        key + ".value",
        f"non-zero and within +-{max_torque:g} N m for joint_torque",
        fault.value,
    )
