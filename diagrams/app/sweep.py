"""`admittance sweep`: a grid or a Monte Carlo over scenario keys, in parallel, resumable.

A sweep is a base scenario (a built-in name or a YAML file, with ``--set`` overrides) and a
list of POINTS, each a mapping of dotted scenario keys to values that is applied on top of
the base (a point's value wins over a ``--set`` of the same key):

* ``--grid KEY=SPEC``: SPEC is a comma list (``1e4,5e4,1e5``, each value parsed as ``--set``
  parses it; ``[...]`` values may hold commas), ``linspace:A:B:N`` or ``logspace:A:B:N``
  (N values from A to B, evenly spaced in log for logspace; A and B in real units, not
  exponents). Several ``--grid`` flags form the Cartesian product, the last flag varying
  fastest.
* ``--random KEY=DIST`` with ``--samples N``: DIST is ``uniform:A:B``, ``loguniform:A:B``,
  ``normal:MEAN:STD``, ``randint:A:B`` (integers A..B inclusive) or ``choice:a,b,c``. The
  draws come from ``numpy.random.default_rng(seed)``: N values per ``--random`` flag, one
  flag after the other in the order given, so the same command always gives the same
  points. Combined with grids, every grid point runs the same N samples (common random
  numbers: differences between grid points are not sampling noise).

Every point is validated (``load_scenario``) before anything runs or is written; a bad
spec, key or value raises ``SweepError`` (a ``ScenarioError``: one line, exit status 2).

Each point is identified by a POINT ID, the first 16 hex digits of the SHA-256 of: the base
scenario's name and the SHA-256 of its YAML file, the ``--set`` list, the point's sorted
overrides and, for Monte Carlo points, the sample number. The same point of the same sweep
has the same id in every run, on every machine with the same numpy.

The folder ``--out DIR`` holds:

``sweep.json``
    The sweep's definition (``"definition"``: base scenario and its file's SHA-256,
    ``--set``, the ``--grid``/``--random`` specs, samples, seed, the number of points and
    a SHA-256 of their ids), written at the start, plus informational fields.
``points.jsonl``
    One JSON object per finished point, one line each, appended as the point finishes
    (one ``os.write`` of the whole line, then ``fsync``), in completion order::

        {"index": 3, "point_id": "9f0c...", "values": {"wall.stiffness": 1e5},
         "failed": false, "failure": null,
         "metrics": {"force_reference": 5.0, "peak_force": 37.4, ...}}

    ``metrics`` holds ``force_reference``, ``peak_force``, ``steady_state_force_error``,
    ``rms_force_error``, ``mean_abs_force_error_settled``, ``contact_losses``,
    ``first_contact_time``, ``force_min/max_while_wall_moves`` (wall moving), every other
    scalar of metrics.json but the integrator's bookkeeping, the settling time to 5 % of Fr
    after each event as ``settling_<kind>_<i>`` (``i`` counts events of that kind from 0;
    null = not settled before the next event), ``wall_time`` (the simulation's, as in
    metrics.json) and ``point_time`` (build + run + metrics, s). A
    point whose simulation diverges, or that raises ``ScenarioError``/``RuntimeError``,
    is recorded with ``"failed": true``, its one-line message in ``failure`` and only the
    times in ``metrics``; it does not stop the sweep.
``table.csv``
    One row per finished point, sorted by index: ``index, point_id``, the swept keys,
    ``failed, failure`` and the metrics (empty cell = null).
``summary.txt``
    What ``admittance sweep`` prints at the end: counts, failures, where tracking degrades
    (steady-state force error above 5 % of Fr), per range of each swept key, and the worst
    points by peak force and by RMS force error.
``summary_<key>.png``
    Per swept key: the metrics against the key's value (log axis for logspace/loguniform
    keys), failed points marked with red crosses along the bottom.

``table.csv``, ``summary.txt``, the plots and ``sweep.json`` are each written atomically
(a temporary file in DIR, then ``os.replace``).

RESUME. ``points.jsonl`` is the sweep's record. Run the same command again (after Ctrl-C, a
kill, a crash or a reboot) and every point already in it, failed ones included, is skipped;
only the others run. A torn last line (the process killed in the middle of a write) is
ignored and removed. If ``sweep.json`` describes a different sweep (another scenario file
content, ``--set``, spec, seed, ... or code that draws other points), the folder is refused
unless ``--force``, which starts over. Workers, engine and scheduler are not part of the
definition: a sweep started locally may be finished on a cluster. One sweep at a time may
run in a folder (a lock file, ``.sweep.lock``).

ENGINES. ``local`` (default) runs the points in a ``ProcessPoolExecutor`` of ``--workers``
processes (default: all cores), started with ``spawn`` (a fresh interpreter: no Drake state
is forked), one point at a time per worker. ``dask`` submits the same points to a
``dask.distributed`` cluster: the scheduler at ``--scheduler ADDRESS``, or a
``LocalCluster`` of ``--workers`` processes. Remote workers need this project installed, and
a YAML base scenario at the same absolute path (built-in names work anywhere).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import dataclasses
import fcntl
import hashlib
import io
import itertools
import json
import math
import multiprocessing
import os
import re
import signal
import statistics
import threading
import time
import typing
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from admittance.diagrams.app.result_folder import atomic_write, atomic_write_text, json_safe
from admittance.diagrams.scenario import (
    SCENARIO_DIR,
    ScenarioError,
    builtin_scenario_names,
    load_scenario,
    parse_overrides,
    parse_value,
)
from admittance.diagrams.simulation import settling_columns

__all__ = [
    "GRID_FORMS",
    "RANDOM_FORMS",
    "GridAxis",
    "RandomAxis",
    "SweepDefinition",
    "SweepError",
    "SweepOutcome",
    "SweepPoint",
    "SweepWorkerError",
    "define_sweep",
    "parse_grid",
    "parse_random",
    "read_points",
    "run_point",
    "run_sweep",
    "summarize",
]

GRID_FORMS = "a comma list (1e4,5e4,1e5), linspace:A:B:N or logspace:A:B:N"
RANDOM_FORMS = "uniform:A:B, loguniform:A:B, normal:MEAN:STD, randint:A:B or choice:a,b,c"
DEFINITION_FORMAT = 1
# Tracking "degrades" where the steady-state force error exceeds this fraction of Fr.
DEGRADED_FRACTION = 0.05
POINTS_FILE = "points.jsonl"
DEFINITION_FILE = "sweep.json"
TABLE_FILE = "table.csv"
SUMMARY_FILE = "summary.txt"
PLOT_PREFIX = "summary_"
LOCK_FILE = ".sweep.lock"
# Scalar metrics copied from metrics.json into a point's row, in table order.
SCALAR_METRICS = (
    "peak_force",
    "steady_state_force_error",
    "rms_force_error",
    "mean_abs_force_error_settled",
    "contact_losses",
    "first_contact_time",
    "force_min_while_wall_moves",
    "force_max_while_wall_moves",
)

# Bookkeeping of a run, not results: left out of the rows (wall_time is added last).
_UNTABLED_METRICS = frozenset(
    ("wall_time", "real_time_factor", "integrator_steps", "derivative_evaluations", "samples")
)


class SweepError(ScenarioError):
    """Bad sweep input (a spec, a flag, a point's value) or an --out folder that is refused."""


class SweepWorkerError(RuntimeError):
    """A worker process died (killed, out of memory, a crash): the sweep stopped."""


_WORKER_DIED = (
    "a worker process died while running a point (killed, out of memory or crashed); the "
    "finished points are kept in {points}: run the same command again to resume"
)


# --- specs --------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class GridAxis:
    """One ``--grid KEY=SPEC``: the key and its values, in order."""

    key: str
    spec: str
    values: tuple
    log: bool = False

    @property
    def flag(self) -> str:
        return f"--grid {self.key}={self.spec}"


@dataclasses.dataclass(frozen=True)
class RandomAxis:
    """One ``--random KEY=DIST``: the key, the distribution and its parameters."""

    key: str
    spec: str
    kind: str
    parameters: tuple
    log: bool = False

    @property
    def flag(self) -> str:
        return f"--random {self.key}={self.spec}"

    def draw(self, rng: np.random.Generator, count: int) -> list:
        """`count` values drawn from `rng` (one vectorized call: reproducible)."""
        if self.kind == "uniform":
            low, high = self.parameters
            return rng.uniform(low, high, size=count).tolist()
        if self.kind == "loguniform":
            low, high = self.parameters
            return np.exp(rng.uniform(math.log(low), math.log(high), size=count)).tolist()
        if self.kind == "normal":
            mean, std = self.parameters
            return rng.normal(mean, std, size=count).tolist()
        if self.kind == "randint":
            low, high = self.parameters
            return [int(v) for v in rng.integers(low, high + 1, size=count)]
        indices = rng.integers(0, len(self.parameters), size=count)
        return [self.parameters[i] for i in indices]


def _split_key(flag: str, text: str, placeholder: str, forms: str) -> tuple[str, str]:
    key, sep, spec = text.partition("=")
    key, spec = key.strip(), spec.strip()
    if not sep or not key or not spec:
        raise SweepError(f"{flag} {text!r}: expected KEY={placeholder}; {placeholder} is {forms}")
    return key, spec


def _split_list(text: str) -> list[str]:
    """Splits at commas outside [] and {} (so list values such as [0.2, -0.25, 1.57] stay)."""
    items, depth, current = [], 0, []
    for char in text:
        if char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        if char == "," and depth == 0:
            items.append("".join(current).strip())
            current = []
        else:
            current.append(char)
    items.append("".join(current).strip())
    return items


def _bad_spec(flag: str, text: str, problem: str, forms: str) -> SweepError:
    return SweepError(f"{flag} {text!r}: {problem}; allowed: {forms}")


def _numbers(flag: str, text: str, parts: Sequence[str], forms: str) -> list[float]:
    numbers = []
    for part in parts:
        try:
            number = float(part)
        except ValueError:
            raise _bad_spec(flag, text, f"{part!r} is not a number", forms) from None
        if not math.isfinite(number):
            raise _bad_spec(flag, text, f"{part!r} is not finite", forms)
        numbers.append(number)
    return numbers


def _spans_decades(values: Iterable) -> bool:
    numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    return bool(numbers) and min(numbers) > 0 and max(numbers) / min(numbers) >= 100


_FORM_PREFIX = re.compile(r"^([A-Za-z_]+):")


def parse_grid(text: str) -> GridAxis:
    """Parses ``KEY=SPEC`` of ``--grid``; raises SweepError naming the flag and the forms."""
    flag, forms = "--grid", GRID_FORMS
    key, spec = _split_key(flag, text, "SPEC", forms)
    form = _FORM_PREFIX.match(spec)
    if form and form.group(1) in ("linspace", "logspace"):
        parts = spec.split(":")
        if len(parts) != 4:
            raise _bad_spec(flag, text, f"{form.group(1)} takes A:B:N", forms)
        low, high = _numbers(flag, text, parts[1:3], forms)
        count = _numbers(flag, text, parts[3:], forms)[0]
        if not count.is_integer() or count < 1:
            raise _bad_spec(flag, text, f"N must be an integer >= 1, got {parts[3]!r}", forms)
        if form.group(1) == "logspace":
            if low <= 0 or high <= 0:
                raise _bad_spec(flag, text, "logspace needs A > 0 and B > 0", forms)
            values = np.geomspace(low, high, int(count)).tolist()
            return GridAxis(key, spec, tuple(values), log=True)
        return GridAxis(key, spec, tuple(np.linspace(low, high, int(count)).tolist()))
    if form:
        raise _bad_spec(flag, text, f"unknown form {form.group(1)!r}", forms)
    items = _split_list(spec)
    if any(item == "" for item in items):
        raise _bad_spec(flag, text, "empty value in the comma list", forms)
    try:
        values = [parse_value(item) for item in items]
    except ScenarioError as error:
        raise _bad_spec(flag, text, str(error), forms) from None
    seen = []
    for value in values:
        if value in seen:
            raise _bad_spec(flag, text, f"value {value!r} is listed twice", forms)
        seen.append(value)
    return GridAxis(key, spec, tuple(values), log=_spans_decades(values))


def parse_random(text: str) -> RandomAxis:
    """Parses ``KEY=DIST`` of ``--random``; raises SweepError naming the flag and the forms."""
    flag, forms = "--random", RANDOM_FORMS
    key, spec = _split_key(flag, text, "DIST", forms)
    kind, sep, rest = spec.partition(":")
    if not sep or kind not in ("uniform", "loguniform", "normal", "randint", "choice"):
        raise _bad_spec(flag, text, f"unknown distribution {kind!r}", forms)
    if kind == "choice":
        items = _split_list(rest)
        if any(item == "" for item in items):
            raise _bad_spec(flag, text, "empty value in the choice list", forms)
        try:
            values = tuple(parse_value(item) for item in items)
        except ScenarioError as error:
            raise _bad_spec(flag, text, str(error), forms) from None
        return RandomAxis(key, spec, kind, values, log=_spans_decades(values))
    parts = rest.split(":")
    if len(parts) != 2:
        names = {"normal": "MEAN:STD"}.get(kind, "A:B")
        raise _bad_spec(flag, text, f"{kind} takes {names}", forms)
    first, second = _numbers(flag, text, parts, forms)
    if kind in ("uniform", "loguniform") and not first < second:
        raise _bad_spec(flag, text, f"{kind} needs A < B", forms)
    if kind == "loguniform" and first <= 0:
        raise _bad_spec(flag, text, "loguniform needs A > 0", forms)
    if kind == "normal" and second <= 0:
        raise _bad_spec(flag, text, "normal needs STD > 0", forms)
    if kind == "randint":
        if not (first.is_integer() and second.is_integer() and first <= second):
            raise _bad_spec(flag, text, "randint needs integers A <= B", forms)
        first, second = int(first), int(second)
    return RandomAxis(key, spec, kind, (first, second), log=kind == "loguniform")


# --- the definition and its points --------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SweepPoint:
    """One point: its overrides (``values``), position in the sweep and stable id."""

    index: int
    point_id: str
    values: dict
    sample: int | None = None

    def describe(self) -> str:
        return ", ".join(f"{key}={_format_value(value)}" for key, value in self.values.items())


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


def _format_value(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, bool):
        return "true" if value else "false"
    return json.dumps(value) if isinstance(value, list | dict) else str(value)


def _scenario_file(scenario: str) -> Path | None:
    """The YAML file behind `scenario` (as load_scenario resolves it), or None."""
    path = Path(scenario)
    if not path.suffix and scenario in builtin_scenario_names():
        return SCENARIO_DIR / f"{scenario}.yaml"
    return path.resolve() if path.is_file() else None


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
    grid_axes = tuple(parse_grid(text) for text in grid)
    random_axes = tuple(parse_random(text) for text in random)
    if not grid_axes and not random_axes:
        raise SweepError("sweep: give at least one --grid KEY=SPEC or --random KEY=DIST")
    if random_axes and samples is None:
        raise SweepError("--samples: required with --random (Monte Carlo samples per grid point)")
    if samples is not None and not random_axes:
        raise SweepError("--samples: only used with --random KEY=DIST")
    if samples is not None and samples < 1:
        raise SweepError(f"--samples {samples}: must be an integer >= 1")
    if seed < 0:
        raise SweepError(f"--seed {seed}: must be an integer >= 0")
    seen: dict[str, str] = {}
    for axis in (*grid_axes, *random_axes):
        if axis.key in seen:
            raise SweepError(f"{axis.flag}: {axis.key} is already swept by {seen[axis.key]}")
        seen[axis.key] = axis.flag

    # The base scenario and --set alone first: their errors read as in `admittance simulate`.
    base = load_scenario(scenario, overrides)
    set_values = parse_overrides(overrides)
    file = _scenario_file(scenario)
    if file is None or file.parent == SCENARIO_DIR:
        source = file.stem if file is not None else scenario  # a built-in: by name
    else:
        source = str(file)  # a YAML file: by absolute path (workers may run elsewhere)
    digest = hashlib.sha256(file.read_bytes()).hexdigest() if file is not None else ""
    record = {
        "scenario": base.name if file is None else file.stem,
        "scenario_sha256": digest,
        "set": list(overrides),
    }
    # Each swept key alone (its first value) names the flag in its error.
    for axis in (*grid_axes, *random_axes):
        if isinstance(axis, GridAxis):
            trial = axis.values[0]
        else:
            trial = axis.draw(np.random.default_rng(seed), 1)[0]
        try:
            load_scenario(source, {**dict(set_values), axis.key: trial})
        except ScenarioError as error:
            message = str(error)
            if message.split(":", 1)[0] == axis.key and "unknown scenario key" not in message:
                message = f"{message} (at {axis.key}={_format_value(trial)})"
            raise SweepError(f"{axis.flag}: {message}") from None

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
        points=tuple(points),
    )
    for point in points:
        try:
            load_scenario(source, definition.overrides_of(point))
        except ScenarioError as error:
            raise SweepError(f"sweep point #{point.index} ({point.describe()}): {error}") from None
    return definition


# --- one point (runs in a worker) ---------------------------------------------------------


def point_metrics(metrics: Mapping, force_reference: float) -> dict:
    """The flat metrics of a point's row from a run's metrics.json dictionary."""
    row: dict = {"force_reference": force_reference}
    for name in SCALAR_METRICS:
        if name in metrics:
            row[name] = metrics[name]
    for name, value in metrics.items():  # any other scalar metric (e.g. a new one)
        scalar = value is None or (isinstance(value, int | float) and not isinstance(value, bool))
        if scalar and name not in row and name not in _UNTABLED_METRICS:
            row[name] = value
    row.update(settling_columns(metrics))
    row["wall_time"] = metrics.get("wall_time")
    return row


def run_point(task: Mapping) -> dict:
    """Runs one point; returns its points.jsonl row. Failures are rows, not exceptions.

    `task` holds ``index``, ``point_id``, ``values``, ``scenario`` (a built-in name or an
    absolute YAML path) and ``overrides`` (the mapping for load_scenario). Runs in a worker
    process (or a Dask worker): it imports the project itself.
    """
    from admittance.diagrams.simulation import SimulationDivergedError, run_scenario

    start = time.perf_counter()
    row = {
        "index": task["index"],
        "point_id": task["point_id"],
        "values": dict(task["values"]),
        "failed": False,
        "failure": None,
        "metrics": {},
    }
    try:
        scenario = load_scenario(task["scenario"], task["overrides"])
        result = run_scenario(scenario)
        row["metrics"] = point_metrics(result.metrics, scenario.force_reference)
    except SimulationDivergedError as diverged:
        row.update(failed=True, failure=str(diverged).splitlines()[0])
        row["metrics"] = {"wall_time": diverged.result.wall_time}
    except (ScenarioError, RuntimeError) as error:
        message = str(error).splitlines()[0] if str(error) else ""
        row.update(failed=True, failure=f"{type(error).__name__}: {message}")
    row["metrics"]["point_time"] = time.perf_counter() - start
    return json_safe(row)


def _task(definition: SweepDefinition, point: SweepPoint) -> dict:
    return {
        "index": point.index,
        "point_id": point.point_id,
        "values": point.values,
        "scenario": definition.scenario_source,
        "overrides": definition.overrides_of(point),
    }


# --- the folder: definition, points.jsonl, lock -------------------------------------------


def read_points(path: str | Path) -> tuple[dict[str, dict], int]:
    """Reads points.jsonl: (rows by point id, number of unreadable lines ignored).

    A torn last line (a write killed midway) and any other line that is not a complete
    JSON object with a point id are ignored; the first row of a point id wins.
    """
    path = Path(path)
    if not path.exists():
        return {}, 0
    data = path.read_bytes()
    rows: dict[str, dict] = {}
    bad = 0
    lines = data.split(b"\n")
    for number, raw in enumerate(lines):
        if not raw.strip():
            continue
        torn = number == len(lines) - 1  # no newline after it
        try:
            row = json.loads(raw)
        except ValueError:
            row = None
        if torn or not isinstance(row, dict) or not isinstance(row.get("point_id"), str):
            bad += 1
            continue
        rows.setdefault(row["point_id"], row)
    return rows, bad


def _rewrite_points(path: Path, rows: Iterable[dict]) -> None:
    lines = "".join(_line(row) for row in rows)
    atomic_write_text(path, lines)


def _line(row: Mapping) -> str:
    return json.dumps(json_safe(dict(row)), separators=(",", ":"), allow_nan=False) + "\n"


class _PointsFile:
    """points.jsonl opened for appending: one os.write per line, then fsync."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def append(self, row: Mapping) -> None:
        data = _line(row).encode()
        written = os.write(self.fd, data)  # one call: a kill leaves at most a torn last line
        while written < len(data):  # a short write (not seen on local disks): finish it
            written += os.write(self.fd, data[written:])
        os.fsync(self.fd)

    def close(self) -> None:
        os.close(self.fd)


@contextlib.contextmanager
def _locked(out_dir: Path):
    """An exclusive lock on `out_dir` for the whole sweep (one sweep per folder)."""
    fd = os.open(out_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SweepError(
                f"--out {out_dir}: another sweep is running in this folder; wait for it or "
                f"choose another folder"
            ) from None
        yield
    finally:
        os.close(fd)


def _our_files(out_dir: Path) -> list[Path]:
    names = [DEFINITION_FILE, POINTS_FILE, TABLE_FILE, SUMMARY_FILE]
    files = [out_dir / name for name in names if (out_dir / name).exists()]
    files += sorted(out_dir.glob(f"{PLOT_PREFIX}*.png"))
    return files


def _prepare_folder(definition: SweepDefinition, out_dir: Path, force: bool) -> None:
    """Checks (or, with force, clears) the folder and writes sweep.json. Called locked."""
    for stale in out_dir.glob(".*.tmp"):  # temporary files of a killed run
        stale.unlink(missing_ok=True)
    wanted = definition.record()
    definition_path = out_dir / DEFINITION_FILE
    if definition_path.exists() and not force:
        try:
            stored = json.loads(definition_path.read_text()).get("definition")
        except (ValueError, AttributeError):
            stored = None
        if stored != json.loads(json.dumps(wanted)):
            differ = (
                [k for k in wanted if not isinstance(stored, dict) or stored.get(k) != wanted[k]]
                if isinstance(stored, dict)
                else ["unreadable"]
            )
            raise SweepError(
                f"--out {out_dir}: holds another sweep (its {DEFINITION_FILE} differs in: "
                f"{', '.join(differ)}); pass --force to start over, or choose another folder"
            )
    if force:
        for file in _our_files(out_dir):
            file.unlink()
    document = {
        "definition": wanted,
        "scenario_path": definition.scenario_source,
        "keys": definition.keys,
        "log_keys": sorted(definition.log_keys),
        "command": "admittance sweep " + definition.describe(),
    }
    atomic_write_text(definition_path, json.dumps(document, indent=2) + "\n")


# --- engines ------------------------------------------------------------------------------


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_pool(executor: concurrent.futures.ProcessPoolExecutor) -> None:
    """Cancels pending points and terminates the workers (a point in progress is lost)."""
    # ProcessPoolExecutor has no public terminate before Python 3.14.
    processes = list(getattr(executor, "_processes", {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
            process.join(timeout=5)


def _run_local(tasks: list[dict], workers: int, on_row: Callable[[dict], None]) -> None:
    context = multiprocessing.get_context("spawn")  # a fresh interpreter: no forked Drake
    executor = concurrent.futures.ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=context, initializer=_ignore_sigint
    )
    try:
        futures = [executor.submit(run_point, task) for task in tasks]
        for future in concurrent.futures.as_completed(futures):
            on_row(future.result())
    except concurrent.futures.process.BrokenProcessPool:
        _stop_pool(executor)
        raise SweepWorkerError(_WORKER_DIED) from None
    except BaseException:
        _stop_pool(executor)
        raise
    executor.shutdown(wait=True)


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise SweepError(
            "--engine dask: dask.distributed is not installed; install it with "
            "`pip install -e .[dask]` (or `pip install distributed`)"
        ) from None
    return distributed


def _run_dask(
    tasks: list[dict], workers: int, scheduler: str | None, on_row: Callable[[dict], None]
) -> None:
    distributed = _import_distributed()
    cluster = None
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as error:
            message = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise SweepError(f"--scheduler {scheduler}: cannot connect: {message}") from None
    else:
        cluster = distributed.LocalCluster(
            n_workers=min(workers, len(tasks)),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
        )
        client = distributed.Client(cluster)
    futures = []
    try:
        run = uuid.uuid4().hex[:8]
        futures = [
            client.submit(run_point, task, key=f"admittance-sweep-{run}-{task['point_id']}")
            for task in tasks
        ]
        for future in distributed.as_completed(futures):
            on_row(future.result())
    except distributed.KilledWorker:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise SweepWorkerError(_WORKER_DIED) from None
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# --- the table, the summary and the plots -------------------------------------------------


def _ordered_metric_names(rows: Sequence[Mapping]) -> list[str]:
    names = ["force_reference", *SCALAR_METRICS]
    seen = set(names)
    extra = []
    for row in rows:
        for name in row.get("metrics", {}):
            if name not in seen:
                seen.add(name)
                extra.append(name)
    settling = [n for n in extra if n.startswith("settling_")]
    times = ("wall_time", "point_time")
    rest = [n for n in extra if not n.startswith("settling_") and n not in times]
    present = {name for row in rows for name in row.get("metrics", {})}
    names = [n for n in names if n in present]
    return names + settling + rest + [n for n in times if n in present]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | dict):
        return json.dumps(value)
    return str(value)


def table_text(keys: Sequence[str], rows: Sequence[Mapping]) -> str:
    """table.csv: one row per point, sorted by index."""
    metric_names = _ordered_metric_names(rows)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["index", "point_id", *keys, "failed", "failure", *metric_names])
    for row in sorted(rows, key=lambda r: r["index"]):
        values, metrics = row.get("values", {}), row.get("metrics", {})
        writer.writerow(
            [row["index"], row["point_id"]]
            + [_cell(values.get(key)) for key in keys]
            + [_cell(row.get("failed")), _cell(row.get("failure"))]
            + [_cell(metrics.get(name)) for name in metric_names]
        )
    return buffer.getvalue()


def _number(value) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _degraded(row: Mapping) -> bool:
    """Failed, or steady-state force error above 5 % of the point's Fr."""
    if row.get("failed"):
        return True
    metrics = row.get("metrics", {})
    error = _number(metrics.get("steady_state_force_error"))
    reference = _number(metrics.get("force_reference"))
    return error is None or reference is None or error > DEGRADED_FRACTION * reference


def _fmt(value, unit: str = "", digits: int = 3) -> str:
    number = _number(value)
    return "n/a" if number is None else f"{number:.{digits}g}{unit}"


def _bins(values: list, log: bool, count: int = 5) -> list[tuple[str, Callable[[object], bool]]]:
    """Ranges of a swept key's values: each distinct value if few, else `count` ranges."""
    distinct = []
    for value in values:
        if value not in distinct:
            distinct.append(value)
    numbers = [_number(v) for v in distinct]
    if len(distinct) <= 8 or any(n is None for n in numbers):
        ordered = sorted(distinct, key=lambda v: (_number(v) is None, _number(v) or 0, str(v)))
        return [(f"= {_format_value(v)}", lambda x, v=v: x == v) for v in ordered]
    low, high = min(numbers), max(numbers)
    if log and low > 0:
        edges = np.geomspace(low, high, count + 1)
    else:
        edges = np.linspace(low, high, count + 1)
    result = []
    for i in range(count):
        a, b = float(edges[i]), float(edges[i + 1])
        last = i == count - 1
        label = f"in [{a:.3g}, {b:.3g}{']' if last else ')'}"

        def inside(x, a=a, b=b, last=last):
            n = _number(x)
            return n is not None and a <= n and (n <= b if last else n < b)

        result.append((label, inside))
    return result


def _metric_values(rows: Iterable[Mapping], name: str) -> list[float]:
    """The finite values of metric `name` over the rows that did not fail."""
    values = (_number(r.get("metrics", {}).get(name)) for r in rows if not r.get("failed"))
    return [v for v in values if v is not None]


def _bin_line(label: str, members: Sequence[Mapping], moving: bool) -> str:
    """One line of the per-key table of summarize()."""
    errors = _metric_values(members, "steady_state_force_error")
    peaks = _metric_values(members, "peak_force")
    losses = sum(1 for v in _metric_values(members, "contact_losses") if v > 0)
    failures = sum(bool(r.get("failed")) for r in members)
    line = (
        f"      {label:32s} {len(members):6d} {sum(map(_degraded, members)):8d} {failures:6d}"
        f"  {_fmt(statistics.median(errors) if errors else None, ' N'):>15s}"
        f"  {_fmt(max(peaks) if peaks else None, ' N'):>8s}  {losses:12d}"
    )
    if moving:
        low = _metric_values(members, "force_min_while_wall_moves")
        line += f"  {_fmt(min(low) if low else None, ' N'):>19s}"
    return line


def _point_label(row: Mapping, keys: Sequence[str]) -> str:
    values = row.get("values", {})
    described = ", ".join(f"{k}={_format_value(values.get(k))}" for k in keys)
    return f"#{row['index']} ({described})"


def summarize(definition: SweepDefinition, rows: Sequence[Mapping], worst: int = 5) -> str:
    """The sweep's summary: counts, failures, where tracking degrades, the worst points."""
    keys = definition.keys
    rows = sorted(rows, key=lambda r: r["index"])
    total = len(definition.points)
    failed = [r for r in rows if r.get("failed")]
    finished = [r for r in rows if not r.get("failed")]
    degraded = [r for r in rows if _degraded(r)]
    lines = [
        f"sweep {definition.describe()}",
        f"  {total} points, {len(rows)} finished, {len(failed)} failed"
        + (f", {total - len(rows)} not run" if len(rows) < total else ""),
    ]
    times = [_number(r.get("metrics", {}).get("point_time")) for r in rows]
    times = [t for t in times if t is not None]
    if times:
        lines.append(
            f"  compute: {sum(times):.1f} s in all, median {statistics.median(times):.2f} s "
            f"per point, longest {max(times):.1f} s"
        )
    if finished:
        lines.append("  over the points that ran (min / median / max):")
        for name, unit in (
            ("peak_force", " N"),
            ("steady_state_force_error", " N"),
            ("rms_force_error", " N"),
            ("mean_abs_force_error_settled", " N"),
            ("contact_losses", ""),
            ("settling_first_contact_0", " s"),
            ("force_min_while_wall_moves", " N"),
            ("force_max_while_wall_moves", " N"),
        ):
            values = [_number(r["metrics"].get(name)) for r in finished]
            values = [v for v in values if v is not None]
            if values:
                lines.append(
                    f"    {name:30s} {_fmt(min(values), unit)} / "
                    f"{_fmt(statistics.median(values), unit)} / {_fmt(max(values), unit)}"
                )
        losses = [r for r in finished if (_number(r["metrics"].get("contact_losses")) or 0) > 0]
        unsettled = [
            r
            for r in finished
            if any(
                k.startswith("settling_") and v is None and not k.startswith("settling_wall_starts")
                for k, v in r["metrics"].items()
            )
        ]
        lines.append(
            f"  contact lost at {len(losses)} points; not settled within 5 % of Fr after an "
            f"event (wall_starts excepted: a moving wall leaves a ramp error) at "
            f"{len(unsettled)} points"
        )
    percent = f"{100 * DEGRADED_FRACTION:g} %"
    lines.append(
        f"  tracking degrades (steady-state force error > {percent} of Fr, or failed) at "
        f"{len(degraded)} of {len(rows)} points"
    )
    moving = any("force_min_while_wall_moves" in r.get("metrics", {}) for r in rows)
    for key in keys:
        values = [r.get("values", {}).get(key) for r in rows]
        header = (
            f"    {'by ' + key:34s} points degraded failed  median ss error  max peak  contact lost"
        )
        lines.append(header + ("  min F, wall moving" if moving else ""))
        for label, inside in _bins(values, key in definition.log_keys):
            members = [r for r in rows if inside(r.get("values", {}).get(key))]
            if members:
                lines.append(_bin_line(label, members, moving))
    shown = [r for r in degraded if not r.get("failed")]
    shown.sort(key=lambda r: -(_number(r["metrics"].get("steady_state_force_error")) or 0))
    if shown:
        lines.append("  the worst steady-state force errors:")
        for row in shown[:worst]:
            metrics = row["metrics"]
            lines.append(
                f"    {_point_label(row, keys)}: "
                f"{_fmt(metrics.get('steady_state_force_error'), ' N')} "
                f"(Fr {_fmt(metrics.get('force_reference'), ' N')})"
            )
    for name, title in (("peak_force", "peak force"), ("rms_force_error", "RMS force error")):
        ranked = [r for r in finished if _number(r["metrics"].get(name)) is not None]
        ranked.sort(key=lambda r: -_number(r["metrics"][name]))
        if ranked:
            lines.append(f"  the worst {title}:")
            for row in ranked[:worst]:
                lines.append(f"    {_point_label(row, keys)}: {_fmt(row['metrics'][name], ' N')}")
    if failed:
        lines.append("  failed points:")
        for row in failed[:10]:
            lines.append(f"    {_point_label(row, keys)}: {row.get('failure')}")
        if len(failed) > 10:
            lines.append(f"    ... and {len(failed) - 10} more (table.csv, column failure)")
    return "\n".join(lines) + "\n"


PLOTTED_METRICS = (
    ("peak_force", "peak force (N)"),
    ("steady_state_force_error", "steady-state |F - Fr| (N)"),
    ("rms_force_error", "RMS force error (N)"),
    ("mean_abs_force_error_settled", "settled mean |F - Fr| (N)"),
    ("contact_losses", "contact losses"),
    ("settling_first_contact_0", "settling after first contact (s)"),
    ("force_min_while_wall_moves", "min force while the wall moves (N)"),
    ("force_max_while_wall_moves", "max force while the wall moves (N)"),
)


def _plot_name(key: str) -> str:
    return PLOT_PREFIX + re.sub(r"[^A-Za-z0-9_.-]", "_", key) + ".png"


def plot_summary(definition: SweepDefinition, rows: Sequence[Mapping], out_dir: Path) -> list[Path]:
    """One PNG per swept key: the metrics against the key; failed points as red crosses."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator, NullFormatter
    from matplotlib.transforms import blended_transform_factory

    written = []
    rows = sorted(rows, key=lambda r: r["index"])
    references = {_number(r.get("metrics", {}).get("force_reference")) for r in rows}
    references.discard(None)
    for key in definition.keys:
        raw = [r.get("values", {}).get(key) for r in rows]
        numeric = all(_number(v) is not None for v in raw)
        if numeric:
            positions = [_number(v) for v in raw]
            categories = None
        else:
            categories = []
            for value in raw:
                if _format_value(value) not in categories:
                    categories.append(_format_value(value))
            positions = [categories.index(_format_value(v)) for v in raw]
        log_x = numeric and key in definition.log_keys and min(positions) > 0
        present = {name for row in rows for name in row.get("metrics", {})}
        plotted = [(name, label) for name, label in PLOTTED_METRICS if name in present]
        if not plotted:  # every point failed: show where
            plotted = PLOTTED_METRICS[:1]
        grid_rows = math.ceil(len(plotted) / 2)
        figure = Figure(figsize=(11, 2.7 * grid_rows + 0.5))
        axes = figure.subplots(grid_rows, 2, sharex=True, squeeze=False).ravel()
        if len(plotted) % 2:
            axes[-1].set_visible(False)
            axes = axes[:-1]
        for axis, (name, label) in zip(axes, plotted, strict=True):
            xs, ys = [], []
            failed_xs = []
            for x, row in zip(positions, rows, strict=True):
                if row.get("failed"):
                    failed_xs.append(x)
                    continue
                y = _number(row.get("metrics", {}).get(name))
                if y is not None:
                    xs.append(x)
                    ys.append(y)
            axis.plot(xs, ys, "o", ms=4, alpha=0.7, label="finished")
            if failed_xs:
                bottom = blended_transform_factory(axis.transData, axis.transAxes)
                axis.plot(
                    failed_xs,
                    [0.03] * len(failed_xs),
                    "x",
                    color="red",
                    ms=7,
                    transform=bottom,
                    label="failed",
                )
            if name == "steady_state_force_error" and len(references) == 1:
                axis.axhline(
                    DEGRADED_FRACTION * next(iter(references)),
                    color="k",
                    ls="--",
                    lw=1,
                    label=f"{100 * DEGRADED_FRACTION:g} % of Fr",
                )
            positive = [y for y in ys if y > 0]
            if (
                name != "contact_losses"
                and positive
                and len(positive) == len(ys)
                and max(positive) / min(positive) > 100
            ):
                axis.set_yscale("log")
            if name == "contact_losses":
                axis.yaxis.set_major_locator(MaxNLocator(integer=True))
                axis.set_ylim(-0.5, max([1.0, *ys]) + 0.5)
            if log_x:
                axis.set_xscale("log")
                axis.xaxis.set_minor_formatter(NullFormatter())
            elif numeric:
                axis.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
            axis.set_ylabel(label)
            axis.grid(True, alpha=0.3)
            if failed_xs or name == "steady_state_force_error":
                axis.legend(loc="best", fontsize=7)
        for axis in axes[-2:]:
            axis.set_xlabel(key)
            axis.tick_params(labelbottom=True)
            if categories is not None:
                axis.set_xticks(range(len(categories)), categories)
                axis.set_xlim(-0.5, len(categories) - 0.5)
        figure.suptitle(f"sweep of {definition.scenario_name}: metrics against {key}")
        figure.tight_layout()
        path = out_dir / _plot_name(key)
        atomic_write(path, lambda temporary, f=figure: f.savefig(temporary, format="png", dpi=100))
        written.append(path)
    return written


# --- running a sweep ----------------------------------------------------------------------


@contextlib.contextmanager
def _sigterm_interrupts():
    """While running points, SIGTERM (plain `kill`) stops the sweep as Ctrl-C does."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@dataclasses.dataclass
class SweepOutcome:
    """What a (finished) run of a sweep did and wrote."""

    out_dir: Path
    total: int
    skipped: int
    ran: int
    failed: int
    elapsed: float
    summary: str
    files: list[Path]


def run_sweep(
    definition: SweepDefinition,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    engine: str = "local",
    scheduler: str | None = None,
    force: bool = False,
    log: Callable[[str], None] = print,
) -> SweepOutcome:
    """Runs the points of `definition` not yet in `out_dir`/points.jsonl; writes the table.

    Raises:
        SweepError: bad workers/engine/scheduler, a folder holding another sweep (without
            `force`), dask missing; before any point runs.
        KeyboardInterrupt: (Ctrl-C or SIGTERM) the workers are stopped first; points.jsonl
            keeps every finished point, so running the same sweep again resumes.
        SweepWorkerError: a worker process died; the finished points are kept likewise.
    """
    if workers is None:
        workers = os.cpu_count() or 1
    if workers < 1:
        raise SweepError(f"--workers {workers}: must be an integer >= 1")
    if engine not in ("local", "dask"):
        raise SweepError(f"--engine {engine}: must be 'local' or 'dask'")
    if scheduler and engine != "dask":
        raise SweepError("--scheduler: only used with --engine dask")
    if engine == "dask":
        _import_distributed()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise SweepError(f"--out {out_dir}: exists and is not a folder")
    if out_dir.is_dir() and not force and not (out_dir / DEFINITION_FILE).exists():
        if any(p.name != LOCK_FILE for p in out_dir.iterdir()):
            raise SweepError(
                f"--out {out_dir}: exists and is not a sweep folder (no {DEFINITION_FILE}); "
                f"choose another folder or pass --force"
            )
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with _locked(out_dir):
        _prepare_folder(definition, out_dir, force)
        points_path = out_dir / POINTS_FILE
        rows, bad = read_points(points_path)
        if bad:
            _rewrite_points(points_path, rows.values())
            log(f"ignored {bad} unreadable line(s) of {points_path} (a run killed mid-write)")
        wanted = {point.point_id for point in definition.points}
        done = {point_id for point_id in rows if point_id in wanted}
        todo = [point for point in definition.points if point.point_id not in done]
        total = len(definition.points)
        if done:
            log(
                f"resuming {out_dir}: skipped {len(done)} finished points of {total}; "
                f"{len(todo)} to run"
            )
        if todo:
            where = f"dask at {scheduler}" if scheduler else f"{engine}, {workers} workers"
            log(f"running {len(todo)} points ({where})")
        finished = len(done)
        failed_now = 0
        points_file = _PointsFile(points_path)

        def on_row(row: dict) -> None:
            nonlocal finished, failed_now
            points_file.append(row)
            rows[row["point_id"]] = row
            finished += 1
            failed_now += bool(row["failed"])
            metrics = row["metrics"]
            outcome = (
                f"FAILED: {row['failure']}"
                if row["failed"]
                else f"peak {_fmt(metrics.get('peak_force'), ' N')}, steady-state error "
                f"{_fmt(metrics.get('steady_state_force_error'), ' N')}"
            )
            point = definition.points[row["index"]]
            log(
                f"[{finished:{len(str(total))}d}/{total}] #{row['index']} ({point.describe()}) "
                f"in {_fmt(metrics.get('point_time'), ' s')}: {outcome}"
            )

        try:
            with _sigterm_interrupts():
                tasks = [_task(definition, point) for point in todo]
                if tasks and engine == "local":
                    _run_local(tasks, workers, on_row)
                elif tasks:
                    _run_dask(tasks, workers, scheduler, on_row)
        except SweepWorkerError as error:
            raise SweepWorkerError(str(error).format(points=points_path)) from None
        finally:
            points_file.close()
        ours = [rows[point.point_id] for point in definition.points if point.point_id in rows]
        summary = summarize(definition, ours)
        table = out_dir / TABLE_FILE
        atomic_write_text(table, table_text(definition.keys, ours))
        atomic_write_text(out_dir / SUMMARY_FILE, summary)
        plots = plot_summary(definition, ours, out_dir) if ours else []
    return SweepOutcome(
        out_dir=out_dir,
        total=total,
        skipped=len(done),
        ran=len(todo),
        failed=sum(bool(r.get("failed")) for r in ours),
        elapsed=time.perf_counter() - start,
        summary=summary,
        files=[points_path, table, out_dir / SUMMARY_FILE, *plots],
    )
