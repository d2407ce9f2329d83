"""A sweep's definition: the base scenario, its axes and every point, validated."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import typing
from collections.abc import Mapping, Sequence

import numpy as np

from admittance.diagrams.app.sweep.specs import (
    MAX_POINTS,
    GridAxis,
    RandomAxis,
    SweepError,
    parse_grid,
    parse_random,
)
from admittance.diagrams.scenario.files import load_scenario, scenario_file, worker_source
from admittance.diagrams.scenario.schema import ScenarioError, parse_overrides
from admittance.diagrams.views import formatting

__all__ = ["SweepDefinition", "SweepPoint", "define_sweep"]

# Version of the definition record in sweep.json (a resume needs the same).
DEFINITION_FORMAT = 1


@dataclasses.dataclass(frozen=True)
class SweepPoint:
    """One point: its overrides (``values``), position in the sweep and stable id."""

    index: int
    point_id: str
    values: dict
    sample: int | None = None

    def describe(self) -> str:
        return ", ".join(f"{key}={formatting.value(value)}" for key, value in self.values.items())


@dataclasses.dataclass(frozen=True)
class SweepDefinition:
    """A validated sweep: base scenario, --set, axes and every point."""

    scenario: str  # as given on the command line
    scenario_name: str
    scenario_source: str  # what workers load: a built-in name or an absolute YAML path
    scenario_sha256: str
    set_overrides: tuple[str, ...]
    set_values: tuple[tuple[str, typing.Any], ...]
    grid: tuple[GridAxis, ...]
    random: tuple[RandomAxis, ...]
    samples: int | None
    seed: int
    points: tuple[SweepPoint, ...]

    @property
    def keys(self) -> list[str]:
        return [axis.key for axis in self.grid] + [axis.key for axis in self.random]

    @property
    def log_keys(self) -> set[str]:
        return {axis.key for axis in (*self.grid, *self.random) if axis.log}

    def record(self) -> dict:
        """The part of sweep.json that must match for a resume (JSON-ready)."""
        ids = "\n".join(point.point_id for point in self.points)
        return {
            "format": DEFINITION_FORMAT,
            "scenario": self.scenario_name,
            "scenario_sha256": self.scenario_sha256,
            "set": list(self.set_overrides),
            "grid": [{"key": a.key, "spec": a.spec} for a in self.grid],
            "random": [{"key": a.key, "spec": a.spec} for a in self.random],
            "samples": self.samples,
            "seed": self.seed,
            "points": len(self.points),
            "points_sha256": hashlib.sha256(ids.encode()).hexdigest(),
        }

    def overrides_of(self, point: SweepPoint) -> dict:
        """The mapping given to load_scenario for `point`: --set, then the point's values."""
        overrides = dict(self.set_values)
        overrides.update(point.values)
        return overrides

    def describe(self) -> str:
        parts = [a.flag for a in self.grid] + [a.flag for a in self.random]
        if self.random:
            parts.append(f"--samples {self.samples} --seed {self.seed}")
        settings = " ".join(f"--set {s}" for s in self.set_overrides)
        return f"{self.scenario_name}{' ' + settings if settings else ''} {' '.join(parts)}"


def _point_id(record: dict, values: Mapping, sample: int | None) -> str:
    identity = {
        "scenario": record["scenario"],
        "scenario_sha256": record["scenario_sha256"],
        "set": record["set"],
        "point": sorted([key, value] for key, value in values.items()),
        "sample": sample,
    }
    text = json.dumps(identity, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def define_sweep(
    scenario: str,
    overrides: Sequence[str] = (),
    *,
    grid: Sequence[str] = (),
    random: Sequence[str] = (),
    samples: int | None = None,
    seed: int = 0,
) -> SweepDefinition:
    """Parses the specs, expands the points and validates every one of them.

    Args:
        scenario: a built-in scenario name or a YAML path.
        overrides: ``--set`` strings, applied to every point.
        grid: ``--grid KEY=SPEC`` strings (Cartesian product, the last varying fastest).
        random: ``--random KEY=DIST`` strings, drawn ``samples`` times each.
        samples: Monte Carlo samples (required with `random`).
        seed: seed of ``numpy.random.default_rng`` for the draws.

    Raises:
        ScenarioError: (or its SweepError) one line naming the flag, key or point.
    """
    grid_axes, random_axes = _parse_axes(grid, random, samples, seed)
    # The base scenario and --set alone first: their errors read as in `admittance simulate`.
    base = load_scenario(scenario, overrides)
    set_values = parse_overrides(overrides)
    file = scenario_file(scenario)
    source = worker_source(scenario)
    digest = hashlib.sha256(file.read_bytes()).hexdigest() if file is not None else ""
    record = {
        "scenario": base.name if file is None else file.stem,
        "scenario_sha256": digest,
        "set": list(overrides),
    }
    _check_each_axis(source, set_values, (*grid_axes, *random_axes), seed)
    definition = SweepDefinition(
        scenario=scenario,
        scenario_name=record["scenario"],
        scenario_source=source,
        scenario_sha256=digest,
        set_overrides=tuple(overrides),
        set_values=tuple(set_values),
        grid=grid_axes,
        random=random_axes,
        samples=samples,
        seed=seed,
        points=_expand_points(record, grid_axes, random_axes, samples, seed),
    )
    for point in definition.points:
        try:
            load_scenario(source, definition.overrides_of(point))
        except ScenarioError as error:
            raise SweepError(f"sweep point #{point.index} ({point.describe()}): {error}") from None
    return definition


def _parse_axes(
    grid: Sequence[str], random: Sequence[str], samples: int | None, seed: int
) -> tuple[tuple[GridAxis, ...], tuple[RandomAxis, ...]]:
    """The axes of the flags, checked together: at least one, --samples with --random
    only, at most MAX_POINTS points, a seed >= 0, no key swept twice."""
    grid_axes = tuple(parse_grid(text) for text in grid)
    random_axes = tuple(parse_random(text) for text in random)
    if not grid_axes and not random_axes:
        raise SweepError("sweep: give at least one --grid KEY=SPEC or --random KEY=DIST")
    if random_axes and samples is None:
        raise SweepError("--samples: required with --random (Monte Carlo samples per grid point)")
    if samples is not None and not random_axes:
        raise SweepError("--samples: only used with --random KEY=DIST")
    if samples is not None and not 1 <= samples <= MAX_POINTS:
        raise SweepError(f"--samples {samples}: must be an integer in [1, {MAX_POINTS}]")
    total = math.prod(len(axis.values) for axis in grid_axes) * (samples or 1)
    if total > MAX_POINTS:
        flags = " x ".join(
            [f"{len(a.values)} ({a.flag})" for a in grid_axes]
            + ([f"{samples} (--samples)"] if random_axes else [])
        )
        raise SweepError(f"sweep: {flags} = {total} points; at most {MAX_POINTS} (split the sweep)")
    if seed < 0:
        raise SweepError(f"--seed {seed}: must be an integer >= 0")
    seen: dict[str, str] = {}
    for axis in (*grid_axes, *random_axes):
        if axis.key in seen:
            raise SweepError(f"{axis.flag}: {axis.key} is already swept by {seen[axis.key]}")
        seen[axis.key] = axis.flag
    return grid_axes, random_axes


def _check_each_axis(source: str, set_values, axes, seed: int) -> None:
    """Each swept key alone (its first value) on the base scenario and --set: its error
    names the flag."""
    for axis in axes:
        if isinstance(axis, GridAxis):
            trial = axis.values[0]
        else:
            trial = axis.draw(np.random.default_rng(seed), 1)[0]
        try:
            load_scenario(source, {**dict(set_values), axis.key: trial})
        except ScenarioError as error:
            message = str(error)
            if message.split(":", 1)[0] == axis.key and "unknown scenario key" not in message:
                message = f"{message} (at {axis.key}={formatting.value(trial)})"
            raise SweepError(f"{axis.flag}: {message}") from None


def _expand_points(
    record: dict,
    grid_axes: tuple[GridAxis, ...],
    random_axes: tuple[RandomAxis, ...],
    samples: int | None,
    seed: int,
) -> tuple[SweepPoint, ...]:
    """Every point: the grid's Cartesian product, each combination with its `samples`
    draws of the random axes (drawn once, in order, from one generator of `seed`)."""
    rng = np.random.default_rng(seed)
    draws = [axis.draw(rng, samples) for axis in random_axes]
    grid_points = list(itertools.product(*(axis.values for axis in grid_axes)))
    points = []
    for combination in grid_points:
        values = {axis.key: value for axis, value in zip(grid_axes, combination, strict=True)}
        for sample in range(samples) if random_axes else [None]:
            point_values = dict(values)
            if sample is not None:
                for axis, drawn in zip(random_axes, draws, strict=True):
                    point_values[axis.key] = drawn[sample]
            point_id = _point_id(record, point_values, sample)
            points.append(SweepPoint(len(points), point_id, point_values, sample))
    return tuple(points)
