"""The control cycle's timing: period jitter, status-to-command latency, missed deadlines
and CPU time per cycle, summarized as ``timing.json``.

Per status message the controller records the wall (monotonic) time it began handling it,
the time its command was published and the CPU time the cycle took. The period jitter is
|arrival interval - period|; a cycle misses its deadline when its command goes out later
than one period after its status arrived (the next status is then due before it is done);
a status that a newer one replaced before its cycle ran is skipped (``skipped_statuses``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["CycleTiming", "quantiles"]


def quantiles(values: np.ndarray) -> dict[str, float | None]:
    if values.size == 0:
        return {"p50": None, "p99": None, "max": None}
    return {
        "p50": float(np.percentile(values, 50)),
        "p99": float(np.percentile(values, 99)),
        "max": float(np.max(values)),
    }


class CycleTiming:
    """Records each cycle's wall times and CPU time; summarizes them."""

    def __init__(self, period: float) -> None:
        self.period = float(period)
        self._arrivals: list[float] = []
        self._published: list[float] = []
        self._cpu: list[float] = []
        self._status_times: list[float] = []
        # Statuses received but not answered: a newer one came before the cycle ran.
        self.skipped = 0
        # Statuses between two answered ones that were not answered (skipped or never
        # received), counted from the gaps in utime.
        self.gaps = 0

    def record(self, arrival: float, published: float, cpu: float, status_time=math.nan) -> None:
        self._arrivals.append(arrival)
        self._published.append(published)
        self._cpu.append(cpu)
        self._status_times.append(status_time)

    def measured(self, since: int = 0) -> dict | None:
        """What the cycles from index `since` on measured, for the sampled-loop check
        (None with fewer than 10):

        * ``period``: the p99 of the status-clock interval between two answered statuses
          (the time a command is held), s;
        * ``latency``: the p99 of status arrival to command publication (wall), s;
        * ``status_interval``: the median wall time per period of the status clock, s;
        * ``delay_periods``: N, the periods from a status to its command acting, the p99
          over the cycles of 1 + the statuses that came while it computed (its latency
          over the wall time until the next status arrived, per period of the status
          clock): a robot's statuses keep coming at its rate, while a simulated station
          that waits for each answer sends the next only after it (N = 1).
        """
        times = np.asarray(self._status_times[since:])
        arrivals = np.asarray(self._arrivals[since:])
        if times.size < 10 or not np.all(np.isfinite(times)):
            return None
        latency = np.asarray(self._published[since:]) - arrivals
        intervals = np.diff(times)
        periods = np.maximum(np.round(intervals / self.period), 1.0)
        per_period = np.diff(arrivals) / periods
        waited = np.floor(latency[:-1] / np.maximum(per_period, 1e-9) + 1e-9)
        return {
            "cycles": int(times.size),
            "period": float(np.percentile(intervals, 99)),
            "latency": float(np.percentile(latency, 99)),
            "status_interval": float(np.median(per_period)),
            "delay_periods": int(1 + np.percentile(waited, 99, method="higher")),
        }

    @property
    def cycles(self) -> int:
        return len(self._arrivals)

    def summary(self) -> dict:
        """The figures of timing.json (seconds)."""
        arrivals = np.asarray(self._arrivals)
        latency = np.asarray(self._published) - arrivals
        jitter = np.abs(np.diff(arrivals) - self.period) if arrivals.size > 1 else np.array([])
        cpu = np.asarray(self._cpu)
        return {
            "period": self.period,
            "cycles": int(arrivals.size),
            "period_jitter": quantiles(jitter),
            "latency": quantiles(latency),
            "cpu_per_cycle": quantiles(cpu),
            "missed_deadlines": int(np.count_nonzero(latency > self.period)),
            "skipped_statuses": self.skipped,
            "unanswered_statuses": self.gaps,
            "achieved_rate": (
                float((arrivals.size - 1) / (arrivals[-1] - arrivals[0]))
                if arrivals.size > 1 and arrivals[-1] > arrivals[0]
                else None
            ),
        }

    def write(self, path: Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.summary(), indent=2) + "\n")
        return path
