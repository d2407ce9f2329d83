"""The axes of a sweep: ``--grid KEY=SPEC`` and ``--random KEY=DIST``, parsed and checked."""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterable, Sequence

import numpy as np

from admittance.diagrams.scenario.schema import ScenarioError, parse_value

__all__ = [
    "GRID_FORMS",
    "MAX_POINTS",
    "RANDOM_FORMS",
    "GridAxis",
    "RandomAxis",
    "SweepError",
    "parse_grid",
    "parse_random",
]

# The most points a sweep may have: validating them alone takes minutes, running them
# days on one machine (a few seconds each).
MAX_POINTS = 100_000

GRID_FORMS = "a comma list (1e4,5e4,1e5), linspace:A:B:N or logspace:A:B:N"
RANDOM_FORMS = "uniform:A:B, loguniform:A:B, normal:MEAN:STD, randint:A:B or choice:a,b,c"


class SweepError(ScenarioError):
    """Bad sweep input (a spec, a flag, a point's value) or an --out folder that is refused."""


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
        if not count.is_integer() or not 1 <= count <= MAX_POINTS:
            raise _bad_spec(
                flag, text, f"N must be an integer in [1, {MAX_POINTS}], got {parts[3]!r}", forms
            )
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
