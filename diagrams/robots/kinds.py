"""The table of kinds: the only place that lists the robots.

A scenario file's top-level ``kind`` names its robot (no ``kind``: the first row). Each
row is a robot's package, whose ``record`` module defines ``ROBOT``
(:class:`~admittance.diagrams.robots.record.Robot`). A robot's package is imported only
when a scenario of it is loaded or its record is asked for, so that a program that runs one
robot (the hardware controller) loads no other. Adding a robot is one new package and one
row here.
"""

from __future__ import annotations

import importlib

from admittance.diagrams.robots.record import Robot

__all__ = ["KINDS", "DEFAULT_KIND", "every_robot", "robot", "robot_of"]

# kind -> the robot's package.
KINDS: dict[str, str] = {
    "arm": "admittance.diagrams.robots.planar_arm",
    "grasp": "admittance.diagrams.robots.planar_gripper",
    "spatial": "admittance.diagrams.robots.spatial_arm",
}
# The kind of a scenario file that gives none.
DEFAULT_KIND = next(iter(KINDS))


def robot(kind: str) -> Robot:
    """The record of the robot of `kind` (a key of KINDS)."""
    return importlib.import_module(f"{KINDS[kind]}.record").ROBOT


def every_robot() -> list[Robot]:
    """Every robot's record, in the table's order (imports every robot's package)."""
    return [robot(kind) for kind in KINDS]


def robot_of(scenario) -> Robot:
    """The record of the robot whose scenario (or result, through its ``scenario``) this is:
    the package that defines the scenario's type."""
    scenario = getattr(scenario, "scenario", scenario)
    module = type(scenario).__module__
    for kind, package in KINDS.items():
        if module == package or module.startswith(package + "."):
            found = robot(kind)
            if isinstance(scenario, found.scenario_type):
                return found
    raise TypeError(f"{type(scenario).__name__} is no robot's scenario ({', '.join(KINDS)})")
