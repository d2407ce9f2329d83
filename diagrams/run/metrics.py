"""Metrics shared by every robot: time-weighted means, windows, settling, contact.

The thresholds that define "settled", "steady state" and "in contact" are stated once here
and used by the arm's and the hand's metrics alike.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "CONTACT_FRACTION",
    "SETTLE_AVERAGE_SAMPLES",
    "SETTLE_BAND",
    "STEADY_WINDOW",
    "contact_loss_indices",
    "final_window",
    "first_contact_time",
    "in_contact",
    "least_squares_slope",
    "settled_from",
    "settling_time",
    "time_mean",
    "trailing_average",
    "until_mask",
    "window_mask",
    "settling_columns",
]

# Window over which "steady state" and "before an event" errors are averaged, s.
STEADY_WINDOW = 1.0
# Band around Fr that counts as settled (relative).
SETTLE_BAND = 0.05
# With sensor noise, settling is judged on the force averaged over this many noise samples,
# so that the ripple the noise leaves on the force (which no controller removes) does not
# hide that the loop has settled. Without noise the raw force is used.
SETTLE_AVERAGE_SAMPLES = 4
# A force above this fraction of Fr counts as contact (the tip may start touching the wall
# with zero force, which is not yet a contact).
CONTACT_FRACTION = 0.01


def time_mean(time: np.ndarray, values: np.ndarray) -> float:
    """Time-weighted mean (trapezoid) of samples at irregular times."""
    if time.size < 2 or time[-1] <= time[0]:
        return float(np.mean(values)) if values.size else math.nan
    return float(np.trapezoid(values, time) / (time[-1] - time[0]))


def window_mask(time: np.ndarray, start: float, end: float) -> np.ndarray:
    return (time >= start) & (time <= end)


def until_mask(time: np.ndarray, start: float, end: float) -> np.ndarray:
    """Samples in [start, end): at `end` the next event has happened (a sample logged at
    that very instant, as a sampled controller's step gives, already shows it). The run's
    last sample is kept when `end` is the end of the run."""
    if time.size and end >= time[-1]:
        return window_mask(time, start, end)
    return (time >= start) & (time < end)


def trailing_average(time: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """Mean of `values` over [t - window, t] at each sample (trapezoid, irregular times)."""
    integral = np.concatenate([[0.0], np.cumsum(np.diff(time) * 0.5 * (values[1:] + values[:-1]))])
    start = np.maximum(time - window, time[0])
    span = time - start
    averaged = values.astype(float).copy()
    ok = span > 0
    averaged[ok] = (integral[ok] - np.interp(start[ok], time, integral)) / span[ok]
    return averaged


def settled_from(time, force, reference, start, end=math.inf) -> float | None:
    """The time from which |F - Fr| <= SETTLE_BAND Fr holds until `end` (exclusive; the
    run's last sample counts when `end` is the run's end), looking from `start` on.

    Returns `start` itself if the force never leaves the band, None if it is outside the
    band at the end (or there is no sample). `force` may be averaged first to ignore noise
    ripple (see the arm's compute_metrics).
    """
    mask = until_mask(time, start, end)
    t = time[mask]
    outside = np.abs(force[mask] - reference) > SETTLE_BAND * reference
    if t.size == 0 or outside[-1]:
        return None
    if not outside.any():
        return start
    return float(t[np.nonzero(outside)[0][-1] + 1])


def settling_time(time, force, reference, event_time, end_time) -> float | None:
    """Time after `event_time` from which |F - Fr| <= 5 % Fr until `end_time` (exclusive):
    :func:`settled_from`, counted from the event (None: not settled)."""
    settled = settled_from(time, force, reference, event_time, end_time)
    return None if settled is None else float(settled - event_time)


def in_contact(force: np.ndarray, reference) -> np.ndarray:
    """Samples in contact: a force above CONTACT_FRACTION of Fr (a tip may touch with zero
    force, which is not yet a contact)."""
    return force > CONTACT_FRACTION * reference


def first_contact_time(time: np.ndarray, contact: np.ndarray) -> float | None:
    """The time of the first sample in contact (None: never)."""
    indices = np.nonzero(contact)[0]
    return float(time[indices[0]]) if indices.size else None


def contact_loss_indices(contact: np.ndarray) -> np.ndarray:
    """The samples after which contact is lost (in contact there, not at the next one)."""
    return np.nonzero(contact[:-1] & ~contact[1:])[0]


def final_window(time: np.ndarray) -> np.ndarray:
    """The samples of the run's last STEADY_WINDOW, where steady state is measured."""
    duration = float(time[-1])
    return window_mask(time, duration - STEADY_WINDOW, duration)


def least_squares_slope(time: np.ndarray, values: np.ndarray) -> float:
    """The least-squares slope of `values` over `time` (a creep or slip rate; 0 with fewer
    than two samples)."""
    if time.size < 2:
        return 0.0
    return float(np.polyfit(time - time[0], values, 1)[0])


def settling_columns(metrics: dict) -> dict[str, float | None]:
    """The settling time after each event of `metrics` as flat columns.

    ``settling_<kind>_<i>`` (s; None = not settled before the next event), ``i`` counting
    the events of that kind from 0: the names of the sweep's and the comparison's tables.
    """
    columns: dict[str, float | None] = {}
    counts: dict[str, int] = {}
    for event in metrics.get("events", []):
        kind = event["kind"]
        columns[f"settling_{kind}_{counts.get(kind, 0)}"] = event["settling_time"]
        counts[kind] = counts.get(kind, 0) + 1
    return columns
