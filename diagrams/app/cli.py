"""The `admittance` command line (see README.md, "Commands").

    admittance simulate  [SCENARIO] [--set KEY=VALUE ...] [--out DIR] [--force]
    admittance stability [SCENARIO] [--set KEY=VALUE ...] [--out DIR] [--force] [--quick]
    admittance diagram   [SCENARIO] [--set KEY=VALUE ...] --out FILE
    admittance compare   [SCENARIO] [--set KEY=VALUE ...] [--controllers K,...] [--out DIR]
    admittance grasp-compare [SCENARIO] [--set KEY=VALUE ...] [--size-errors M,...]
                         [--stiffness-errors R,...] [--controllers K,...] [--out DIR]
    admittance bench     [SCENARIO] [--set KEY=VALUE ...] [--repeat N] [--json FILE]
                         [--before FILE]
    admittance sweep     [SCENARIO] [--set KEY=VALUE ...] [--grid KEY=SPEC ...]
                         [--random KEY=DIST ...] [--samples N] [--seed S] [--workers N]
                         [--engine local|dask] [--scheduler ADDRESS] --out DIR [--force]

Results and summaries go to stdout, progress to stderr (``--quiet`` silences it). Errors
in the input print one line naming the key and exit with status 2; a run that fails (a
diverging simulation) prints one line and exits with status 1; Ctrl-C at any moment exits
with status 130 after one line.

This module imports only the standard library at the top: Drake, numpy and matplotlib are
imported inside :func:`main`, so that a Ctrl-C while they load is handled like any other.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

from admittance.diagrams.app.interrupts import record_sigint, sigint_held_back, sigint_received
from admittance.diagrams.app.parser import (
    EXIT_INPUT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_RUN_FAILED,
    MAX_REPEAT,
    build_parser,
)

# The extension modules of Drake that the project imports (tests/test_layout.py checks the
# list against the code). They load with Ctrl-C held back: their C++ initialization would
# turn a KeyboardInterrupt into "ImportError: initialization failed".
DRAKE_MODULES = (
    "pydrake.autodiffutils",
    "pydrake.common",
    "pydrake.common.cpp_param",
    "pydrake.common.value",
    "pydrake.common.yaml",
    "pydrake.geometry",
    "pydrake.lcm",
    "pydrake.manipulation",
    "pydrake.math",
    "pydrake.multibody.math",
    "pydrake.multibody.parsing",
    "pydrake.multibody.plant",
    "pydrake.multibody.tree",
    "pydrake.symbolic",
    "pydrake.systems.analysis",
    "pydrake.systems.controllers",
    "pydrake.systems.framework",
    "pydrake.systems.lcm",
    "pydrake.systems.primitives",
    "pydrake.systems.scalar_conversion",
    "pydrake.trajectories",
)


def _error(message: str) -> None:
    print(f"admittance: error: {message}", file=sys.stderr)


def _arm_scenario(args: argparse.Namespace):
    """The arm scenario of `args`; a grasp or spatial scenario is refused with one line."""
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.planar_gripper import GraspScenario
    from admittance.diagrams.scenario.schema import ScenarioError

    scenario = load_scenario(args.scenario, args.overrides)
    _refuse_spatial(scenario, args)
    if isinstance(scenario, GraspScenario):
        raise ScenarioError(
            f"scenario: '{args.scenario}' is a grasp scenario (kind: grasp); `admittance "
            f"{args.command}` runs arm scenarios only (grasps: simulate, diagram, stability, "
            "grasp-compare)"
        )
    return scenario


def _spatial_scenario(args: argparse.Namespace):
    """The spatial-arm scenario of `args`, or None for any other kind."""
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.spatial_arm import SpatialScenario

    scenario = load_scenario(args.scenario, args.overrides)
    return scenario if isinstance(scenario, SpatialScenario) else None


def _refuse_spatial(scenario, args: argparse.Namespace) -> None:
    """One line for a spatial-arm scenario given to a command that does not run one."""
    from admittance.diagrams.scenario.schema import ScenarioError
    from admittance.diagrams.scenario.spatial_arm import SpatialScenario

    if isinstance(scenario, SpatialScenario):
        raise ScenarioError(
            f"scenario: '{args.scenario}' is a spatial-arm scenario (kind: spatial); "
            f"`admittance {args.command}` does not run one yet (spatial arms: simulate, "
            "bench, stability)"
        )


# --- the subcommands ----------------------------------------------------------------------


def _cmd_simulate(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.result_folder import (
        check_output_dir,
        check_replay_file,
        check_writable,
        write_marked_replay,
    )
    from admittance.diagrams.app.simulate import summary, write_results
    from admittance.diagrams.run.engine import SimulationDivergedError
    from admittance.diagrams.run.simulation import simulate
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.views.figures import write_replay

    scenario = load_scenario(args.scenario, args.overrides)
    out = Path(args.out) if args.out else Path("results") / scenario.name
    check_output_dir(out, overwrite=args.force)
    if args.meshcat_html:
        check_writable(args.meshcat_html, "--meshcat-html")
        check_replay_file(args.meshcat_html, args.force)
    try:
        result = simulate(scenario, progress=progress.simulation(scenario.name, scenario.duration))
    except SimulationDivergedError as diverged:
        # Keep what was logged, marked failed (metrics.json: "failed": true).
        progress(f"writing the partial result to {out}/")
        write_results(diverged.result, out, overwrite=args.force)
        _error(f"{diverged} (partial, failed result in {out}/)")
        return EXIT_RUN_FAILED
    progress(f"writing {out}/")
    folder = write_results(result, out, overwrite=args.force)
    print(summary(result))
    print(folder.describe(out))
    if args.meshcat_html:
        progress(f"writing the Meshcat replay {args.meshcat_html}")
        write_marked_replay(write_replay, result, Path(args.meshcat_html), args.force, out)
        print(f"wrote {args.meshcat_html} (Meshcat replay)")
    return 0


def _cmd_diagram(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.result_folder import check_writable
    from admittance.diagrams.loop.build import BuildLoop
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.schema import ScenarioError
    from admittance.diagrams.views.picture import write_diagram_picture

    scenario = load_scenario(args.scenario, args.overrides)
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".svg", ".png", ".dot"):
        raise ScenarioError(f"--out {args.out}: unsupported picture format; use .svg, .png or .dot")
    check_writable(args.out)
    print(f"wrote {write_diagram_picture(BuildLoop(scenario).diagram, args.out)}")
    return 0


def _cmd_bench(args: argparse.Namespace, progress) -> int:
    import json

    from admittance.diagrams.app.bench import run_benchmark
    from admittance.diagrams.app.bench_report import (
        check_bench_file,
        format_benchmark,
        load_benchmark_report,
    )
    from admittance.diagrams.app.result_folder import atomic_write_text, check_writable
    from admittance.diagrams.loop.planar_arm import CheckScenarioStarts
    from admittance.diagrams.scenario.schema import ScenarioError

    if not 1 <= args.repeat <= MAX_REPEAT:
        raise ScenarioError(
            f"--repeat {args.repeat}: must be an integer in [1, {MAX_REPEAT}] (each is a "
            "whole simulation)"
        )
    spatial = _spatial_scenario(args)
    if spatial is not None:
        from admittance.diagrams.app.spatial_bench import spatial_bench_command

        return spatial_bench_command(spatial, args, progress)
    scenario = _arm_scenario(args)
    before = None
    if args.before:
        try:
            before = load_benchmark_report(args.before, scenario)
        except ValueError as error:
            raise ScenarioError(str(error)) from None
    if args.json:
        check_writable(args.json, "--json")
        check_bench_file(args.json)
    CheckScenarioStarts(scenario)
    report = run_benchmark(scenario, repeat=args.repeat, progress=progress)
    print(format_benchmark(report, before))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        check_bench_file(path)  # again: it may have changed during the runs
        atomic_write_text(path, json.dumps(report, indent=2) + "\n")
        print(f"wrote {path}")
    return 0


def _controller_kinds(text: str | None) -> list[str]:
    """The --controllers list, checked: known kinds, each once."""
    from admittance.diagrams.scenario.planar_arm import CONTROLLER_KINDS
    from admittance.diagrams.scenario.schema import ScenarioError

    if text is None:
        return list(CONTROLLER_KINDS)
    kinds = [kind.strip() for kind in text.split(",")]
    for index, kind in enumerate(kinds):
        if kind not in CONTROLLER_KINDS:
            raise ScenarioError(
                f"--controllers: {kind!r} is not a controller; allowed: "
                + ", ".join(CONTROLLER_KINDS)
            )
        if kind in kinds[:index]:
            raise ScenarioError(f"--controllers: {kind!r} is listed twice")
    return kinds


def _cmd_compare(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.compare import (
        compare_controllers,
        format_table,
        write_comparison,
    )
    from admittance.diagrams.app.formatting import number
    from admittance.diagrams.app.result_folder import check_output_dir
    from admittance.diagrams.robots.planar_arm import baseline_gains

    kinds = _controller_kinds(args.controllers)
    scenario = _arm_scenario(args)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_compare"
    check_output_dir(out, overwrite=args.force)
    scenario, runs = compare_controllers(
        args.scenario, args.overrides, kinds, workers=args.workers, progress=progress
    )
    gains = ", ".join(f"{k} {number(v)}" for k, v in baseline_gains(scenario).items())
    print(
        f"{scenario.name}: Fr = {number(scenario.force_reference, ' N')}; baseline gains ({gains})"
    )
    print(format_table(runs), end="")
    progress(f"writing {out}/")
    folder = write_comparison(scenario, runs, out, overwrite=args.force)
    print(folder.describe(out))
    return 0


def _number_list(flag: str, text: str) -> list[float]:
    from admittance.diagrams.scenario.schema import ScenarioError

    try:
        return [float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise ScenarioError(f"{flag} {text!r}: expected a comma list of numbers") from None


def _cmd_grasp_compare(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.grasp_compare import compare_grasps, format_grasp_table
    from admittance.diagrams.app.result_folder import check_output_dir, result_folder
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.planar_gripper import GRASP_CONTROLLER_KINDS, GraspScenario
    from admittance.diagrams.scenario.schema import ScenarioError

    scenario = load_scenario(args.scenario, args.overrides)
    if not isinstance(scenario, GraspScenario):
        raise ScenarioError(f"scenario: '{args.scenario}' is not a grasp scenario (kind: grasp)")
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_compare"
    check_output_dir(out, overwrite=args.force)
    controllers = (
        [k.strip() for k in args.controllers.split(",")]
        if args.controllers
        else list(GRASP_CONTROLLER_KINDS)
    )
    rows = compare_grasps(
        args.scenario,
        args.overrides,
        size_errors=_number_list("--size-errors", args.size_errors),
        stiffness_errors=_number_list("--stiffness-errors", args.stiffness_errors),
        controllers=controllers,
        workers=args.workers,
        progress=progress,
    )
    table = format_grasp_table(rows)
    print(table, end="")
    progress(f"writing {out}/")
    with result_folder(out, overwrite=args.force) as folder:
        folder.write_text("table.md", table)
        folder.write_json("rows.json", rows)
    print(folder.describe(out))
    return 0


def _cmd_stability(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.result_folder import check_output_dir
    from admittance.diagrams.app.stability_report import (
        MapAxes,
        analyse,
        format_report,
        write_report,
    )
    from admittance.diagrams.loop.planar_arm import CheckScenarioStarts
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.planar_gripper import GraspScenario
    from admittance.diagrams.scenario.spatial_arm import SpatialScenario

    scenario = load_scenario(args.scenario, args.overrides)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_stability"
    check_output_dir(out, overwrite=args.force)
    if isinstance(scenario, SpatialScenario):
        from admittance.diagrams.app.spatial_stability_report import spatial_stability_command

        return spatial_stability_command(scenario, out, args, progress)
    if isinstance(scenario, GraspScenario):
        from admittance.diagrams.app.grasp_stability_report import grasp_stability_command

        return grasp_stability_command(scenario, out, args, progress)
    axes = MapAxes.quick() if args.quick else MapAxes()
    CheckScenarioStarts(scenario)
    report = analyse(scenario, axes=axes, with_trajectory=not args.no_trajectory, progress=progress)
    progress(f"writing {out}/")
    folder = write_report(report, out, overwrite=args.force)
    print(format_report(report.summary), end="")
    print(folder.describe(out))
    return 0


def _cmd_sweep(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.formatting import seconds
    from admittance.diagrams.app.sweep import WorkerDiedError, define_sweep, run_sweep

    _arm_scenario(args)
    definition = define_sweep(
        args.scenario,
        args.overrides,
        grid=args.grid,
        random=args.random,
        samples=args.samples,
        seed=args.seed,
    )
    points = Path(args.out) / "points.jsonl"
    try:
        outcome = run_sweep(
            definition,
            args.out,
            workers=args.workers,
            engine=args.engine,
            scheduler=args.scheduler,
            force=args.force,
            progress=progress,
        )
    except KeyboardInterrupt:
        if points.is_file() and points.stat().st_size > 0:
            kept = f"the finished points are kept in {points}: run the same command again to resume"
        else:
            kept = "no point had finished"
        print(f"admittance: interrupted; {kept}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except WorkerDiedError as error:
        _error(str(error))
        return EXIT_RUN_FAILED
    print(outcome.summary, end="")
    names = ", ".join(path.name for path in outcome.files)
    print(
        f"ran {outcome.ran} points in {seconds(outcome.elapsed)} ({outcome.skipped} skipped); "
        f"wrote {outcome.out_dir}/: {names}"
    )
    return 0


def _cmd_station(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.hardware import station_command

    return station_command(args, progress)


def _cmd_control(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.hardware import control_command

    return control_command(args, progress)


# --- the parser ---------------------------------------------------------------------------


# Each subcommand's function, by its name on the command line.
HANDLERS = {
    "simulate": _cmd_simulate,
    "diagram": _cmd_diagram,
    "stability": _cmd_stability,
    "compare": _cmd_compare,
    "grasp-compare": _cmd_grasp_compare,
    "bench": _cmd_bench,
    "sweep": _cmd_sweep,
    "station": _cmd_station,
    "control": _cmd_control,
}


def _interrupted() -> int:
    """The one line of a Ctrl-C: which result folders were completed before it, if any."""
    completed = []
    module = sys.modules.get("admittance.diagrams.app.result_folder")
    if module is not None:
        completed = [f"{folder}/" for folder in module.completed_folders]
    if completed:
        print(f"admittance: interrupted after writing {', '.join(completed)}", file=sys.stderr)
    else:
        print("admittance: interrupted; no result was written", file=sys.stderr)
    return EXIT_INTERRUPTED


def _load_libraries() -> None:
    """Drake, numpy and matplotlib (headless: figures go to files), Ctrl-C held back."""
    with sigint_held_back():
        for name in DRAKE_MODULES:
            importlib.import_module(name)
        import matplotlib

        matplotlib.use("Agg")
        importlib.import_module("matplotlib.pyplot")


def _run(args: argparse.Namespace, argv: list[str]) -> int:
    _load_libraries()
    from admittance.diagrams.app.progress import Progress
    from admittance.diagrams.app.result_folder import (
        OutputExistsError,
        OutputPathError,
        command_line,
        completed_folders,
    )
    from admittance.diagrams.app.sweep.runner import WorkerDiedError
    from admittance.diagrams.scenario.schema import ScenarioError
    from admittance.diagrams.views.picture import DiagramPictureError

    completed_folders.clear()
    command_line[:] = ["admittance", *argv]  # recorded in the result folders' markers
    progress = Progress(args.command, quiet=args.quiet or args.quiet_all)
    try:
        status = args.handler(args, progress)
        sys.stdout.flush()  # a reader gone away shows here, inside the handling below
        return status
    except (ScenarioError, OutputExistsError, OutputPathError, DiagramPictureError) as error:
        _error(str(error))
        return EXIT_INPUT_ERROR
    except WorkerDiedError as error:  # compare, grasp-compare (sweep says what it kept)
        _error(str(error))
        return EXIT_RUN_FAILED
    except BrokenPipeError:  # the reader of stdout went away: main() ends quietly
        raise
    except OSError as error:  # the system refused a write that was possible at the start
        where = f"{error.filename}: " if error.filename else ""
        _error(f"{where}{error.strerror or error}")
        return EXIT_RUN_FAILED


def main(argv: list[str] | None = None) -> int:
    """Runs the command line; returns the exit status (0, 1, 2 or 130)."""
    record_sigint()
    try:
        args = build_parser(HANDLERS).parse_args(argv)
        return _run(args, sys.argv[1:] if argv is None else list(argv))
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:  # the reader went away (e.g. `| head`): not an error of the run
        # Python's own flush at exit would fail again on the closed pipe: point the
        # descriptor at /dev/null (the recipe of Python's signal documentation).
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except Exception:
        if sigint_received():  # a Ctrl-C that an extension's call turned into its own error
            return _interrupted()
        raise


if __name__ == "__main__":
    sys.exit(main())
