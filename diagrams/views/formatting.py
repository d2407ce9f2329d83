"""How the application writes numbers and scenario values for people to read.

One formatter for every table, summary and progress line of the command line: a number
to a few significant digits with its unit, and a placeholder where there is none (a
metric that does not apply, a run that failed). Files meant for programs (metrics.json,
table.csv, points.jsonl) keep full precision and do not pass through here.
"""

from __future__ import annotations

import json
import math

__all__ = ["MISSING", "number", "seconds", "value"]

# What a table or summary shows where a number is missing (None, NaN, not a number).
MISSING = "n/a"


def number(x, unit: str = "", *, digits: int = 3, missing: str = MISSING) -> str:
    """`x` to `digits` significant digits followed by `unit` (integers in full).

    None, NaN, infinities given as None by json_safe, booleans and non-numbers give
    `missing`; an infinity prints as inf.
    """
    if isinstance(x, bool) or not isinstance(x, int | float):
        return missing
    if isinstance(x, int):
        return f"{x:,}{unit}"
    if math.isnan(x):
        return missing
    return f"{x:.{digits}g}{unit}"


def seconds(x, *, digits: int = 3, missing: str = MISSING) -> str:
    """A duration in s, ms or us, whichever puts the number at 1 or more (whole seconds
    from 10**digits s on, not 1.23e+03 s)."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return number(x, " s", digits=digits, missing=missing)
    if abs(x) >= 10**digits:
        return f"{x:.0f} s"
    if x == 0 or abs(x) >= 1.0:
        return number(float(x), " s", digits=digits)
    if abs(x) >= 1e-3:
        return number(1e3 * x, " ms", digits=digits)
    return number(1e6 * x, " us", digits=digits)


def value(x) -> str:
    """A scenario key's value as a --set would spell it (1e+05, true, [0.2, -0.25, 1.57])."""
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, float):
        return number(x, digits=4)
    if isinstance(x, list | dict):
        return json.dumps(x)
    return str(x)
