"""Progress lines on stderr: ``admittance <command>: <what it is doing>``.

Stdout keeps the results (summaries, tables, the files written); progress goes to stderr,
one line per stage, so that a long command says what it does and a pipe of its output stays
clean. ``--quiet`` silences it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from admittance.diagrams.views.formatting import number

__all__ = ["Progress"]

# A long simulation reports how far it got at most this often, s of wall time.
SIMULATION_REPORT_INTERVAL = 5.0


class Progress:
    """Writes progress lines of one command to stderr, unless quiet."""

    def __init__(self, command: str, quiet: bool = False) -> None:
        self.command = command
        self.quiet = quiet

    def __call__(self, text: str) -> None:
        if not self.quiet:
            print(f"admittance {self.command}: {text}", file=sys.stderr, flush=True)

    def simulation(
        self, name: str, duration: float, interval: float = SIMULATION_REPORT_INTERVAL
    ) -> Callable[[float], None] | None:
        """A callback for ``run_scenario(progress=...)``: a line when the simulation starts
        (its initial conditions accepted), then the simulated time every `interval` s of
        wall time (None when quiet)."""
        if self.quiet:
            return None
        next_report = None

        def report(simulated: float) -> None:
            nonlocal next_report
            now = time.monotonic()
            if next_report is None:
                self(f"simulating {name}: {number(duration, ' s')}")
                next_report = now + interval
            elif now >= next_report:
                next_report = now + interval
                percent = number(100.0 * simulated / duration, " %", digits=2)
                self(f"simulated {number(simulated, ' s')} of {number(duration, ' s')} ({percent})")

        return report
