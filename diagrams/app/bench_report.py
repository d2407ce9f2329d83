"""The report of ``admittance bench`` for people: a table, and an earlier run beside it.

``format_benchmark(report, before)`` renders a ``bench.run_benchmark`` report as a readable
table; given the report of an earlier run (``--before FILE``, read by
``load_benchmark_report``: the same scenario on other code, measured the same day), it also
prints both side by side, the per-callback profile included.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from admittance.diagrams.results.folder import check_output_file

__all__ = [
    "check_bench_file",
]

# --- the table --------------------------------------------------------------------------


def _is_bench_report(path: Path) -> bool:
    """A JSON file with the keys of a bench report (what `bench --json` writes)."""
    try:
        report = json.loads(path.read_text())
        report["scenario"]["name"], report["closed_loop"], report["python"]["callbacks"]
        report["ratio_to_floor"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return True


def check_bench_file(path: str | os.PathLike) -> None:
    """bench --json replaces an earlier bench report (no --force needed), nothing else."""
    check_output_file(path, "--json", _is_bench_report, "a bench report", overwrite=True)
