"""The allowed values of every scenario key, and `validate`, which checks a scenario.

Most keys are one number in a range: :data:`RANGES` lists them, key by key, as the message
states them (``in (0, 1e5] s``, ``>= 0 s (0 = continuous)``). What is not a range follows
the table: lists (their length, each entry), choices among names, and the checks that
relate two keys (Fmax above Fr, the admittance's reach, what the sensor can read). Every
failed check raises ScenarioError with one line: ``<key>: must be <allowed>, got <value>``.
"""

from __future__ import annotations

import functools
import math
import re
import typing

from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from admittance.diagrams.robots.planar_arm.scenario import CONTROLLER_KINDS, Scenario
from admittance.diagrams.scenario.ranges import (
    MAX_STIFFNESS,
    PID_GAINS,
    RANGES,
    check_fault_timing,
    check_joint_torque_value,
    require,
    require_one_of,
    require_range,
    value_of,
)
from admittance.diagrams.scenario.schema import INTEGRATION_SCHEMES, ScenarioError, load_typed
from admittance.diagrams.scenario.sections import FAULT_KINDS, NOISY_FAULT_KINDS

__all__ = [
    "load_arm_scenario",
    "validate",
]

# The largest joint_torque fault, N m: twice the arm's largest actuator effort (30 N m).
MAX_JOINT_TORQUE = 60.0


def _check_lists(s: Scenario) -> None:
    """Lists of numbers: their lengths and values."""
    finite = math.isfinite
    t = s.trajectory
    require(len(t.center) == 3, "trajectory.center", "3 values (x, y, theta)", t.center)
    require(all(map(finite, t.center)), "trajectory.center", "finite", t.center)
    require(len(t.amplitude) == 3, "trajectory.amplitude", "3 values", t.amplitude)
    require(all(map(finite, t.amplitude)), "trajectory.amplitude", "finite", t.amplitude)
    for name, allowed in PID_GAINS.items():
        gains = getattr(s.pid, name)
        key = f"pid.{name}"
        require(len(gains) == 3, key, "3 values (x, y, theta)", gains)
        require(all(map(allowed.allows, gains)), key, allowed.allowed(), gains)
    r = s.arm
    require(
        len(r.joint_guess) > 0 and all(map(finite, r.joint_guess)),
        "arm.joint_guess",
        "finite joint angles",
        r.joint_guess,
    )
    require(
        len(r.initial_position) in (0, 3) and all(map(finite, r.initial_position)),
        "arm.initial_position",
        "empty or 3 finite values (x, y, theta)",
        r.initial_position,
    )


def _check_entries(s: Scenario) -> None:
    """The entries of wall.stiffness_steps and faults."""
    finite = math.isfinite
    previous = 0.0
    for i, step in enumerate(s.wall.stiffness_steps):
        key = f"wall.stiffness_steps[{i}]"
        require_range(step.stiffness, key + ".stiffness", RANGES["wall.stiffness"])
        require(
            finite(step.time) and step.time >= previous,
            key + ".time",
            ">= 0 s and not before the previous step",
            step.time,
        )
        previous = step.time
    for i, fault in enumerate(s.faults):
        key = f"faults[{i}]"
        check_fault_timing(fault, key, FAULT_KINDS)
        if fault.kind == "stiffness_jump":
            require(
                0 < fault.value <= MAX_STIFFNESS,
                key + ".value",
                f"in (0, {MAX_STIFFNESS:g}] N/m for stiffness_jump",
                fault.value,
            )
        if fault.kind == "wall_retract":
            require(fault.value > 0, key + ".value", "> 0 m (the wall moves away, +x)", fault.value)
        if fault.kind == "sensor_saturated":
            require(fault.value > 0, key + ".value", "> 0 N (the full-scale reading)", fault.value)
        if fault.noisy:
            require(
                fault.kind in NOISY_FAULT_KINDS,
                key + ".noisy",
                f"false for {fault.kind} (only {', '.join(NOISY_FAULT_KINDS)} keep the noise)",
                fault.noisy,
            )
            require(
                s.sensor.kind == "flexiforce" and s.sensor.noise_std > 0,
                key + ".noisy",
                "false unless sensor.kind is flexiforce with sensor.noise_std > 0 (no noise to "
                "keep)",
                fault.noisy,
            )
        if fault.kind == "joint_torque":
            check_joint_torque_value(fault, key, MAX_JOINT_TORQUE)


def _check_choices(s: Scenario) -> None:
    """Keys that name one of a few things, and the URDF file."""
    require_one_of(s.controller.kind, "controller.kind", CONTROLLER_KINDS)
    require(
        s.controller.tuning in ("matched", "manual"),
        "controller.tuning",
        "'matched' or 'manual'",
        s.controller.tuning,
    )
    require(
        s.sensor.kind in ("ideal", "flexiforce"),
        "sensor.kind",
        "'ideal' or 'flexiforce'",
        s.sensor.kind,
    )
    require(s.arm.urdf_path().is_file(), "arm.urdf", "an existing URDF file", s.arm.urdf)
    _check_urdf(s.arm)
    require(
        s.name not in ("", ".", "..") and not _NOT_IN_A_NAME.search(s.name),
        "name",
        "a file name (results/<name> is the default --out)",
        s.name,
    )
    require_one_of(
        s.simulator.integration_scheme, "simulator.integration_scheme", INTEGRATION_SCHEMES
    )
    require(s.simulator.start_time == 0.0, "simulator.start_time", "0", s.simulator.start_time)


# A scenario's name is a folder name: no separator, no control character.
_NOT_IN_A_NAME = re.compile(r"[/\\\x00-\x1f]")


@functools.lru_cache(maxsize=16)
def _urdf_problem(path: str, modified: int, size: int, fingertip_frame: str):
    """(key, problem) of the URDF file `path` for the closed loop, or None if it is fine.

    Drake parses it into a plant of its own; cached by the file's modification time and
    size, so that a sweep's thousand points parse it once.
    """
    plant = MultibodyPlant(time_step=0.0)
    try:
        Parser(plant).AddModels(path)
        plant.Finalize()
    except RuntimeError as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        detail = re.sub(r"^(.*?:\d+: )?error: ", "", message)  # "<file>:<line>: error: "
        return "arm.urdf", f"{path} is not a URDF that Drake reads: {detail}"
    velocities, actuators = plant.num_velocities(), plant.num_actuators()
    if velocities < 3 or actuators != velocities:
        return (
            "arm.urdf",
            f"must be a fully actuated arm of at least 3 joints (the PID drives x, y and theta "
            f"of the fingertip), got {velocities} joint velocities and {actuators} actuators "
            f"in {path}",
        )
    if not plant.HasFrameNamed(fingertip_frame):
        return "arm.fingertip_frame", f"the URDF has no frame named '{fingertip_frame}'"
    return None


def _check_urdf(arm) -> None:
    """The arm's URDF can be read, Drake parses it, and the PID can drive what it holds."""
    path = arm.urdf_path()
    try:
        with path.open("rb") as file:
            file.read(1)
        status = path.stat()
    except OSError as error:
        raise ScenarioError(f"arm.urdf: {path} cannot be read: {error.strerror}") from None
    problem = _urdf_problem(str(path), status.st_mtime_ns, status.st_size, arm.fingertip_frame)
    if problem is not None:
        key, message = problem
        raise ScenarioError(f"{key}: {message}")


@functools.lru_cache(maxsize=16)
def _urdf_joint_count(path: str, modified: int, size: int) -> int:
    """The number of joint velocities of the URDF `path` (read once per file version)."""
    plant = MultibodyPlant(time_step=0.0)
    Parser(plant).AddModels(path)
    plant.Finalize()
    return plant.num_velocities()


def _check_joint_faults(s: Scenario) -> None:
    """A joint_torque fault names a joint of the arm's URDF (read and checked by now)."""
    for i, fault in enumerate(s.faults):
        if fault.kind != "joint_torque":
            continue
        path = s.arm.urdf_path()
        status = path.stat()
        joints = _urdf_joint_count(str(path), status.st_mtime_ns, status.st_size)
        require(
            0 <= fault.joint < joints,
            f"faults[{i}].joint",
            f"a joint index in [0, {joints - 1}] (0 = the joint at the base; the planar "
            "arm: 0 shoulder, 1 elbow, 2 wrist)",
            fault.joint,
        )


def _check_relations(s: Scenario) -> None:
    """Checks that relate two keys (each key alone is valid by now)."""
    w, a = s.wall, s.admittance
    require(w.motion_end >= w.motion_start, "wall.motion_end", ">= wall.motion_start", w.motion_end)
    require(
        a.max_force > s.force_reference,
        "admittance.max_force",
        f"> force_reference ({s.force_reference:g} N), or .inf for no bound",
        a.max_force,
    )
    if a.enabled:
        # Past max_push only the PID's slow integral could add force: Fr would not be reached.
        needed = s.force_reference / s.pid.kp[0]
        require(
            a.max_push > needed,
            "admittance.max_push",
            f"> force_reference / pid.kp[0] = {needed:.3g} m (the PID's push at the bound, "
            f"Kp max_push, must exceed Fr)",
            a.max_push,
        )
    if s.sensor.kind == "flexiforce":
        # A reference the sensor cannot read would wind the admittance up forever.
        from admittance.systems.flexiforce import FlexiForceSensor

        full_scale = FlexiForceSensor().saturation_force
        require(
            s.force_reference < 0.9 * full_scale,
            "force_reference",
            f"< {0.9 * full_scale:.4g} N with sensor.kind=flexiforce (90 % of the A201's "
            f"{full_scale:.4g} N full scale)",
            s.force_reference,
        )
        require(
            not math.isfinite(a.max_force) or a.max_force < full_scale,
            "admittance.max_force",
            f"< {full_scale:.4g} N with sensor.kind=flexiforce (a bound the A201 cannot read "
            "cannot be enforced), or .inf",
            a.max_force,
        )


def _check_safety(s: Scenario) -> None:
    """What the safety layer needs of the rest of the scenario (safety.enabled)."""
    if not s.safety.enabled:
        return
    require(
        s.controller_kind == "optimal_admittance",
        "safety.enabled",
        "used with the paper's controller (controller.kind optimal_admittance, "
        "admittance.enabled true)",
        s.safety.enabled,
    )
    require(
        math.isfinite(s.admittance.max_force),
        "admittance.max_force",
        "finite with safety.enabled (the layer keeps the force under it)",
        s.admittance.max_force,
    )
    require(
        s.admittance.period == s.pid.period,
        "pid.period",
        "equal to admittance.period with safety.enabled (the layer and the PID run in one "
        "tick: both continuous or both sampled)",
        s.pid.period,
    )
    require(
        s.sensor.latency == 0 or s.admittance.period > 0,
        "sensor.latency",
        "0 with safety.enabled and the continuous controller (the layer's margin for a "
        "latency is the sampled loop's: set admittance.period and pid.period)",
        s.sensor.latency,
    )


def validate(scenario: Scenario) -> Scenario:
    """Checks every key of `scenario`; raises ScenarioError naming the first bad key."""
    for key, allowed in RANGES.items():
        require_range(value_of(scenario, key), key, allowed)
    _check_lists(scenario)
    _check_entries(scenario)
    _check_choices(scenario)
    _check_joint_faults(scenario)
    _check_relations(scenario)
    _check_safety(scenario)
    return scenario


def load_arm_scenario(
    data: dict, overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = ()
) -> Scenario:
    """A validated planar-arm scenario from a YAML file's mapping and dotted-key overrides."""
    return validate(load_typed(data, Scenario, overrides))
