"""What a robot's package hands the rest of the code: one :class:`Robot` record.

A robot is one package under ``diagrams/robots/`` (its scenario sections and validation,
plant, loop, metrics, analysis, figures, replay, report and bench parts); its ``record``
module defines ``ROBOT``, and the table of kinds (:mod:`.kinds`) lists the packages. The
command line, the run path and the views reach a robot only through its record: what a
command needs of a robot is a field here, and a command the robot does not support is
absent from ``commands`` (the command line derives its refusals from that).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["BenchParts", "HardwareParts", "Robot", "StabilityOptions", "time_and_force"]


@dataclass(frozen=True)
class StabilityOptions:
    """What ``admittance stability`` asks of a robot's analysis."""

    # Skip the slow parts (fewer map points, no nonlinear confirmation runs).
    quick: bool = False
    # Evaluate V = 1/2 (E + alpha dE/dt)^2 along a simulated run (where the robot has one).
    trajectory: bool = True


@dataclass(frozen=True)
class BenchParts:
    """A robot's ``admittance bench``: the timed runs and their table."""

    # (scenario, repeat, progress) -> the report (a JSON-able dict).
    run: Callable[..., dict]
    # (report, the report of an earlier run or None) -> the table for people.
    format: Callable[[dict, dict | None], str]
    # (path, scenario) -> an earlier report of the same scenario (``--before FILE``), or
    # None where the robot's reports cannot be compared that way.
    load_before: Callable[[Any, Any], dict] | None = None


@dataclass(frozen=True)
class HardwareParts:
    """What the hardware split (``hardware/``) needs of a robot it can drive over LCM."""

    # (scenario, **the controller's settings) -> the controller's law: the plan, the force
    # law and the PID over the robot's model (``step`` per status, ``check_gains``).
    control_law: Callable[..., Any]
    # scenario -> the joints at t = 0, where the simulated loop starts the robot.
    start_positions: Callable[[Any], Any]
    # (builder, scenario) -> (plant, scene_graph, geometry): the station's robot and scene.
    add_plant: Callable[..., tuple]
    # (scenario, plant, initial positions) -> the force-controlled point (its sensor).
    point: Callable[..., Any]
    # A posture at rest (joint positions) for a status stream without a simulation.
    home_positions: tuple[float, ...]
    # The body the wrist sensor measures, the tool's tip frame, the control frame, and the
    # axis of the control frame along the surface's normal.
    tool_body: str
    tip_frame: str
    control_frame: str
    normal_axis: int


def _no_check(scenario) -> None:
    pass


def time_and_force(result) -> dict:
    """What a sweep or a comparison keeps of a point by default: the time and the force."""
    return {"time": result.time, "force": result.force}


@dataclass(frozen=True)
class Robot:
    """One robot, as the shared code sees it (see the module's docstring)."""

    # The value of a scenario file's top-level ``kind`` that selects this robot.
    kind: str
    # What a scenario of it is called in a message ("a grasp scenario"), and its robots in
    # a list of what a command runs ("grasps: simulate, diagram, ...").
    noun: str
    plural: str
    # The scenario's dataclass (the root of its typed YAML tree).
    scenario_type: type
    # (the YAML file's mapping without ``kind``, --set overrides) -> a validated scenario.
    load: Callable[..., Any]
    # scenario -> its loop (``.diagram`` the closed loop of Fig. 1); ``analysis=True``
    # where the robot builds one for Linearize.
    build: Callable[..., Any]
    # (scenario, progress=None) -> its result (``time``, ``columns()``, ``metrics``,
    # ``scenario``); raises SimulationDivergedError with the partial result.
    run: Callable[..., Any]
    # result -> a few lines for the terminal.
    summary: Callable[[Any], str]
    # File name -> a function of the result that draws the figure and returns its axes.
    figures: Mapping[str, Callable]
    # (result, path) -> the Meshcat replay written to path.
    replay: Callable[..., Any]
    # The commands of ``admittance`` that take a scenario of this robot.
    commands: tuple[str, ...]
    # Checks that the scenario can start (its plan within reach), before a command runs it
    # many times over (bench, stability, compare): one line naming the key, or nothing.
    check_start: Callable[[Any], None] = _no_check
    # (scenario, out folder, StabilityOptions, overwrite, progress) -> (the text to print,
    # the result folder written).
    stability: Callable[..., tuple[str, Any]] | None = None
    bench: BenchParts | None = None
    # The robot's comparison command (``compare``, ``grasp-compare``): (scenario source,
    # --set overrides, out folder, **the command's options, workers, overwrite, progress)
    # -> (the text to print, the result folder written).
    compare: Callable[..., tuple[str, Any]] | None = None
    # (result) -> the time series a sweep or a comparison keeps of a point.
    series: Callable[[Any], dict] = time_and_force
    # What the hardware split needs of the robot (``station``, ``control``), or None.
    hardware: HardwareParts | None = None

    def supports(self, command: str) -> bool:
        return command in self.commands
