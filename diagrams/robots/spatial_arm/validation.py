"""`validate_spatial`, which checks a spatial-arm scenario, and `load_spatial_scenario`.

The ranges of the schema's ``SPATIAL_RANGES`` (:mod:`.scenario`) first, then the PID's
gains, the arm's model file and frames, the lists and the choices among names, the keys
that depend on others, and what the safety layer and the faults need. Every failed check
raises ScenarioError with one line: ``<key>: must be <allowed>, got <value>``.
"""

from __future__ import annotations

import math
import re
import typing

from admittance.diagrams.robots.spatial_arm.scenario import (
    SPATIAL_CONTROLLER_KINDS,
    SPATIAL_COORDINATES,
    SPATIAL_RANGES,
    SPATIAL_SENSOR_KINDS,
    TOOL_SHAPES,
    SpatialArmConfig,
    SpatialScenario,
)
from admittance.diagrams.scenario.ranges import (
    PID_GAINS,
    check_fault_timing,
    check_joint_torque_value,
    require,
    require_one_of,
    require_range,
    value_of,
)
from admittance.diagrams.scenario.schema import load_typed

__all__ = [
    "SPATIAL_FAULT_KINDS",
    "load_spatial_scenario",
    "validate_spatial",
]

_NOT_IN_A_NAME = re.compile(r"[/\\\x00-\x1f]")


def _finite_list(values, size: int | None = None) -> bool:
    return (size is None or len(values) == size) and all(math.isfinite(v) for v in values)


def validate_spatial(scenario: SpatialScenario) -> SpatialScenario:
    """Every key checked; raises ScenarioError naming the first bad key and what is allowed.

    The model file itself (its frames, its actuators) is checked where it is loaded
    (robots.spatial_arm.model), with the same one-line errors.
    """
    s = scenario
    require(s.kind == "spatial", "kind", "'spatial' for a spatial-arm scenario", s.kind)
    for key, allowed in SPATIAL_RANGES.items():
        require_range(value_of(s, key), key, allowed)
    for name, allowed in PID_GAINS.items():
        gains = getattr(s.pid, name)
        require(
            len(gains) == len(SPATIAL_COORDINATES) and all(map(allowed.allows, gains)),
            f"pid.{name}",
            f"6 values (x, y, z, rx, ry, rz), {allowed.allowed()}",
            gains,
        )
    _check_spatial_arm(s.arm)
    _check_spatial_choices(s)
    _check_spatial_dependent_keys(s)
    _check_spatial_safety(s)
    _check_spatial_faults(s)
    return scenario


def _check_spatial_arm(a: SpatialArmConfig) -> None:
    """arm: the model's file or URL, its frames, the base's position and the joint lists."""
    require(a.urdf.strip() != "", "arm.urdf", "a URDF or SDF file, or a package:// URL", a.urdf)
    require(
        a.urdf.startswith("package://") or a.urdf.lower().endswith((".urdf", ".sdf", ".xml")),
        "arm.urdf",
        "a .urdf or .sdf file, or a package:// URL",
        a.urdf,
    )
    for key in ("base_frame", "flange_frame"):
        require(getattr(a, key).strip() != "", f"arm.{key}", "a frame of the model", "")
    require(
        _finite_list(a.base_position, 3),
        "arm.base_position",
        "3 finite values (world x, y, z, m)",
        a.base_position,
    )
    require(_finite_list(a.initial_joints), "arm.initial_joints", "finite angles", a.initial_joints)
    require(_finite_list(a.joint_guess), "arm.joint_guess", "finite angles", a.joint_guess)


def _check_spatial_choices(s: SpatialScenario) -> None:
    """The surface's position, the choices among names, the sensor's bias and noise, and
    the scenario's name."""
    require(
        _finite_list(s.surface.position, 2),
        "surface.position",
        "2 finite values (world x, y, m)",
        s.surface.position,
    )
    require_one_of(s.tool.shape, "tool.shape", TOOL_SHAPES)
    require_one_of(s.controller.kind, "controller.kind", SPATIAL_CONTROLLER_KINDS)
    require_one_of(s.sensor.kind, "sensor.kind", SPATIAL_SENSOR_KINDS)
    require(
        _finite_list(s.sensor.bias, 6) and all(abs(b) <= 100 for b in s.sensor.bias),
        "sensor.bias",
        "6 finite values (fx, fy, fz N, tx, ty, tz N m) within +-100",
        s.sensor.bias,
    )
    require(
        s.sensor.kind == "wrench" or (s.sensor.noise_std == 0 and s.sensor.torque_noise_std == 0),
        "sensor.noise_std",
        "0 with sensor.kind ideal (the ideal sensor has no noise; use wrench)",
        s.sensor.noise_std,
    )
    require(
        s.name not in ("", ".", "..") and not _NOT_IN_A_NAME.search(s.name),
        "name",
        "a file name (results/<name> is the default --out)",
        s.name,
    )


def _check_spatial_dependent_keys(s: SpatialScenario) -> None:
    """The keys that depend on others: the slide's blends, the duration, the reach."""
    t = s.trajectory
    if t.slide_distance > 0:
        require(
            t.slide_distance > t.slide_speed * t.blend_time,
            "trajectory.slide_distance",
            f"> slide_speed * blend_time = {t.slide_speed * t.blend_time:.3g} m (the blends "
            "must fit in the slide)",
            t.slide_distance,
        )
    require(
        s.duration > s.slide_start,
        "duration",
        f"> trajectory.approach_time + force_ramp_time + press_time = {s.slide_start:g} s",
        s.duration,
    )
    if s.controller.kind == "optimal_admittance":
        needed = s.force_reference / s.pid.kp[2]
        require(
            s.admittance.max_push > needed,
            "admittance.max_push",
            f"> force_reference / pid.kp[2] = {needed:.3g} m (the PID's push at the bound "
            "must exceed Fr)",
            s.admittance.max_push,
        )


#: The fault kinds a spatial arm takes: the force reading's, and a torque on a joint (a
#: link hitting something).
SPATIAL_FAULT_KINDS = (
    "sensor_nan",
    "sensor_stuck",
    "sensor_zero",
    "sensor_saturated",
    "joint_torque",
)
# The largest joint_torque fault, N m: beyond the Panda's and the UR5's largest efforts.
MAX_SPATIAL_JOINT_TORQUE = 300.0


def _check_spatial_faults(s: SpatialScenario) -> None:
    """faults: the kinds above, timed, with a finite value; no `noisy` (the wrist sensor's
    noise is 6-D, drawn in its own frame, not the reading's). A joint_torque's joint is
    checked against the model where it is loaded (robots.spatial_arm.loop)."""
    for i, fault in enumerate(s.faults):
        key = f"faults[{i}]"
        check_fault_timing(fault, key, SPATIAL_FAULT_KINDS)
        require(not fault.noisy, key + ".noisy", "false on a spatial arm", fault.noisy)
        if fault.kind == "joint_torque":
            check_joint_torque_value(fault, key, MAX_SPATIAL_JOINT_TORQUE)


def _check_spatial_safety(s: SpatialScenario) -> None:
    """What the safety layer needs of the rest of the scenario (safety.enabled)."""
    if not s.safety.enabled:
        return
    require(
        s.controller.kind == "optimal_admittance",
        "safety.enabled",
        "used with the paper's controller (controller.kind optimal_admittance)",
        s.safety.enabled,
    )
    require(
        s.safety.max_force > s.force_reference,
        "safety.max_force",
        f"> force_reference = {s.force_reference:g} N (the bound must leave room for Fr)",
        s.safety.max_force,
    )


def load_spatial_scenario(
    data: dict,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
) -> SpatialScenario:
    """A validated spatial scenario from a YAML file's mapping and dotted-key overrides.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data = dict(data)
    data.setdefault("kind", "spatial")
    return validate_spatial(load_typed(data, SpatialScenario, overrides))
