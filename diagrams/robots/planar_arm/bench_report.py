"""The planar arm's ``admittance bench`` report for people: a table, and an earlier run
beside it (``--before FILE``, read by ``load_benchmark_report``: the same scenario on
other code, measured the same day), the per-callback profile included.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.views.formatting import number, seconds

__all__ = ["format_benchmark", "load_benchmark_report"]


def _signed_percent(fraction: float) -> str:
    return ("+" if fraction >= 0 else "") + number(100 * fraction, " %", digits=2)


def load_benchmark_report(path: str | os.PathLike, scenario: Scenario) -> dict:
    """The report of an earlier ``admittance bench --json`` run of the same scenario.

    Raises:
        ValueError: one line naming the file: it cannot be read, is not a benchmark
            report, or measured another scenario (name, duration or sensor).
    """
    try:
        report = json.loads(Path(path).read_text())
        measured = report["scenario"]
        report["closed_loop"], report["python"]["callbacks"], report["ratio_to_floor"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        reason = error.strerror if isinstance(error, OSError) else "not a benchmark report"
        raise ValueError(f"--before {path}: {reason}") from None
    wanted = {"name": scenario.name, "duration": scenario.duration, "sensor": scenario.sensor.kind}
    found = {key: measured.get(key) for key in wanted}
    if found != wanted:
        raise ValueError(
            f"--before {path}: a benchmark of {found['name']} ({found['duration']} s, sensor "
            f"{found['sensor']}), not of {wanted['name']} ({wanted['duration']} s, sensor "
            f"{wanted['sensor']})"
        )
    return report


def _format_before(report: dict, before: dict) -> list[str]:
    """The earlier run beside this one: headline ratios and the per-callback profile."""
    now_loop, before_loop = report["closed_loop"], before["closed_loop"]
    now_python, before_python = report["python"], before["python"]

    def speedup(earlier: float | None, later: float | None) -> str:
        return f"{earlier / later:.2f} x" if earlier and later else "-"

    lines = [
        "",
        "against the earlier run (--before; each run's ratios use its own floor):",
        f"  {'':40}{'before':>12}{'now':>12}{'before / now':>16}",
    ]

    def row(label: str, earlier, later, ratio: bool = True) -> None:
        lines.append(
            f"  {label:40}{number(earlier):>12}{number(later):>12}"
            + (f"{speedup(earlier, later):>16}" if ratio else "")
        )

    row("wall time / floor (x)", before["ratio_to_floor"], report["ratio_to_floor"])
    row(
        "per derivative evaluation / floor (x)",
        before["per_evaluation_ratio_to_floor"],
        report["per_evaluation_ratio_to_floor"],
    )
    row("CPU time / floor (x)", before.get("cpu_ratio_to_floor"), report["cpu_ratio_to_floor"])
    row(
        "  per derivative evaluation (x)",
        before.get("cpu_per_evaluation_ratio_to_floor"),
        report["cpu_per_evaluation_ratio_to_floor"],
    )
    before_one, now_one = before.get("one_evaluation") or {}, report.get("one_evaluation") or {}
    row("one evaluation alone / floor (x)", before_one.get("ratio"), now_one.get("ratio"))
    row(
        "wall time per derivative eval. (us)",
        before_loop["wall_time_per_derivative_evaluation_us"],
        now_loop["wall_time_per_derivative_evaluation_us"],
    )
    row(
        "Python callbacks per evaluation",
        before_python["callbacks_per_derivative_evaluation"],
        now_python["callbacks_per_derivative_evaluation"],
    )
    row("integrator steps", before_loop["integrator_steps"], now_loop["integrator_steps"], False)
    row(
        "derivative evaluations",
        before_loop["derivative_evaluations"],
        now_loop["derivative_evaluations"],
        False,
    )
    lines += [
        "",
        "  Python callbacks before and now (calls per derivative evaluation, mean time; "
        "profiling runs)",
        f"  {'callback':46}{'before':>10}{'mean':>10}{'now':>10}{'mean':>10}",
    ]
    earlier = {entry["name"]: entry for entry in before_python["callbacks"]}
    later = {entry["name"]: entry for entry in now_python["callbacks"]}

    def cells(entry: dict | None) -> str:
        if entry is None:
            return f"{number(None):>10}{'':>10}"
        return (
            f"{number(entry['per_derivative_evaluation']):>10}"
            f"{seconds(1e-6 * entry['mean_us']):>10}"
        )

    names = list(earlier) + [name for name in later if name not in earlier]
    for name in names:
        lines.append(f"  {name:46}{cells(earlier.get(name))}{cells(later.get(name))}")
    return lines


def format_benchmark(report: dict, before: dict | None = None) -> str:
    """A readable table of a ``run_benchmark`` report (and of an earlier one beside it)."""
    lines = _header_lines(report)
    lines += _table_lines(report["closed_loop"], report["floor"])
    lines += _ratio_lines(report)
    lines += _python_lines(report["python"])
    lines += _logging_lines(report)
    lines += _memory_lines(report)
    if before is not None:
        lines += _format_before(report, before)
    environment = report["environment"]
    lines.append(
        f"Python {environment['python']}, drake {environment['drake']}, "
        f"{environment['cpu_count']} CPUs, {environment['platform']}"
    )
    return "\n".join(lines)


def _header_lines(report: dict) -> list[str]:
    """What was timed, and the table's heading."""
    scenario = report["scenario"]
    return [
        f"Benchmark of {scenario['name']}: {number(scenario['duration'], ' s')} simulated, sensor "
        f"{scenario['sensor']}, {scenario['integration_scheme']} accuracy "
        f"{number(scenario['accuracy'])}, max step {number(scenario['max_step_size'], ' s')}, "
        f"{report['repeat']} timed run(s) after a warm-up",
        "",
        f"{'':34}{'closed loop':>22}{'floor (bare arm)':>22}",
    ]


def _table_lines(loop: dict, floor: dict) -> list[str]:
    """The closed loop and the floor side by side: times, steps, evaluations."""
    lines = []

    def row(label: str, closed: str, bare: str = "") -> None:
        lines.append(f"{label:34}{closed:>22}{bare:>22}")

    row(
        "AdvanceTo wall time, median",
        seconds(loop["wall_time"]["median"]),
        seconds(floor["wall_time"]["median"]),
    )
    row(
        "  min / max",
        f"{seconds(loop['wall_time']['min'])} / {seconds(loop['wall_time']['max'])}",
        f"{seconds(floor['wall_time']['min'])} / {seconds(floor['wall_time']['max'])}",
    )
    row(
        "AdvanceTo CPU time, median",
        seconds(loop["cpu_time"]["median"]),
        seconds(floor["cpu_time"]["median"]),
    )
    row(
        "real-time factor",
        number(loop["real_time_factor"]),
        number(floor["real_time_factor"]),
    )
    row("integrator steps", number(loop["integrator_steps"]), number(floor["integrator_steps"]))
    row(
        "derivative evaluations",
        number(loop["derivative_evaluations"]),
        number(floor["derivative_evaluations"]),
    )
    row("  per step", number(loop["derivative_evaluations_per_step"]))
    row(
        "wall time per step",
        seconds(1e-6 * loop["wall_time_per_step_us"]),
        seconds(1e-6 * floor["wall_time_per_step_us"]),
    )
    floor_per_evaluation = floor["wall_time_per_derivative_evaluation_us"]
    row(
        "wall time per derivative eval.",
        seconds(1e-6 * loop["wall_time_per_derivative_evaluation_us"]),
        seconds(1e-6 * floor_per_evaluation) if floor_per_evaluation is not None else seconds(None),
    )
    row("build time (excluded)", seconds(loop["build_time"]))
    return lines


def _ratio_lines(report: dict) -> list[str]:
    """The closed loop over the floor, the integrator's work, one evaluation alone, and
    a warning if the runs took different steps."""
    loop, floor = report["closed_loop"], report["floor"]
    integrator = loop["integrator"]
    lines = [
        "",
        f"closed loop / floor: {number(report['ratio_to_floor'])} x in wall time, "
        f"{number(report['per_evaluation_ratio_to_floor'])} x per derivative evaluation "
        f"(floor drift {number(floor['max_joint_drift'], ' rad', digits=1)})",
        f"  in CPU time: {number(report['cpu_ratio_to_floor'])} x, "
        f"{number(report['cpu_per_evaluation_ratio_to_floor'])} x per derivative evaluation",
        f"integrator: {number(integrator.get('num_newton_raphson_iterations'))} Newton "
        f"iterations, {number(integrator.get('num_jacobian_evaluations'))} Jacobians "
        f"({number(integrator.get('num_derivative_evaluations_for_jacobian'))} derivative "
        f"evaluations), {number(integrator.get('num_iteration_matrix_factorizations'))} "
        f"factorizations, step shrinkages "
        f"{number(integrator.get('num_step_shrinkages_from_error_control'))} (error control) + "
        f"{number(integrator.get('num_step_shrinkages_from_substep_failures'))} "
        f"(substep failures), smallest step "
        f"{seconds(integrator.get('smallest_adapted_step_size_taken'))}",
    ]
    one = report.get("one_evaluation")
    if one is not None:
        lines.append(
            f"one derivative evaluation alone (CPU time, least of {one['rounds']} rounds):"
            f" closed loop {seconds(1e-6 * one['closed_loop_us'])}, floor "
            f"{seconds(1e-6 * one['floor_us'])}, {number(one['ratio'])} x"
        )
    if not loop["deterministic"]:
        lines.append("warning: the runs did not take the same steps (non-deterministic loop)")
    return lines


def _python_lines(python: dict) -> list[str]:
    """The profiling run's Python callbacks: totals, then one row per callback."""
    fraction = python["fraction_of_wall_time"]
    lines = [
        "",
        f"Python callbacks (separate profiling run, {seconds(python['profiled_wall_time'])}): "
        f"{number(python['callback_calls'])} calls, "
        f"{number(python['callbacks_per_derivative_evaluation'])} per derivative evaluation; "
        f"{seconds(python['time_in_callbacks'])} inside them"
        + (
            f" = {number(100 * fraction, ' %', digits=2)} of the run"
            if fraction is not None
            else ""
        ),
        f"  {'callback':46}{'calls':>10}{'per eval':>10}{'time':>10}{'mean':>10}",
    ]
    for entry in python["callbacks"]:
        lines.append(
            f"  {entry['name']:46}{number(entry['calls']):>10}"
            f"{number(entry['per_derivative_evaluation']):>10}"
            f"{seconds(entry['time']):>10}{seconds(1e-6 * entry['mean_us']):>10}"
        )
    return lines


def _logging_lines(report: dict) -> list[str]:
    """The timed median against the run with the other logging setting."""
    timed = report["closed_loop"]["wall_time"]
    lines = [
        "",
        f"logging (one run each; the timed runs ranged {seconds(timed['min'])} to "
        f"{seconds(timed['max'])}):",
    ]
    for entry in report["logging"]:
        relative = entry.get("relative_to_timed")
        lines.append(
            f"  {entry['logging']:14}{seconds(entry['wall_time']):>10}"
            f"{number(entry['integrator_steps']):>10} steps"
            + (f"  ({_signed_percent(relative - 1)} vs timed median)" if relative else "")
        )
    return lines


def _memory_lines(report: dict) -> list[str]:
    """The process's peak memory and the warm-up's force check."""
    memory, loop = report["memory"], report["closed_loop"]
    return [
        "",
        f"memory: peak RSS {number(memory['peak_rss_mb'], ' MB')} (process), Python allocations "
        f"peak {number(memory['python_peak_mb'], ' MB')} (tracemalloc, warm-up run)",
        f"force check (warm-up): peak {number(loop['peak_force'])} N, contact losses "
        f"{number(loop['contact_losses'])}",
    ]
