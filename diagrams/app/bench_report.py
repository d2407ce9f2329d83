"""The file of ``admittance bench --json``: an earlier bench report is replaced (no
--force needed), nothing else ever is.

The benchmark and its report for people are each robot's: ``run_benchmark`` in
``robots.planar_arm.bench`` and ``format_benchmark`` (with ``load_benchmark_report`` for
``--before FILE``) in ``robots.planar_arm.bench_report``; the spatial arm's in
``robots.spatial_arm.bench``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from admittance.diagrams.results.folder import check_output_file

__all__ = [
    "check_bench_file",
]


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
