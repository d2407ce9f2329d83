"""The `admittance` command line (see docs/reference/commands.md).

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

from admittance.diagrams.app.parser import (
    EXIT_INPUT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_RUN_FAILED,
    MAX_REPEAT,
    build_parser,
)
from admittance.diagrams.results.interrupts import record_sigint, sigint_held_back, sigint_received

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


def _refusal(source, robot, command: str) -> str:
    """The one line for a scenario whose robot does not take `command`: which robots'
    scenarios the command runs, and which commands this robot's take."""
    from admittance.diagrams.robots.kinds import every_robot

    takers = [other.noun for other in every_robot() if other.supports(command)]
    article = "an" if robot.noun[0] in "aeiou" else "a"
    return (
        f"scenario: '{source}' is {article} {robot.noun} scenario (kind: {robot.kind}); "
        f"`admittance {command}` runs {' and '.join(takers) or 'no'} scenarios only "
        f"({robot.plural}: {', '.join(robot.commands)})"
    )


def _scenario(args: argparse.Namespace):
    """The scenario of `args` and its robot's record; a robot whose record does not take
    the command is refused with one line."""
    from admittance.diagrams.robots.kinds import robot_of
    from admittance.diagrams.scenario.files import load_scenario
    from admittance.diagrams.scenario.schema import ScenarioError

    scenario = load_scenario(args.scenario, args.overrides)
    robot = robot_of(scenario)
    if not robot.supports(args.command):
        raise ScenarioError(_refusal(args.scenario, robot, args.command))
    return scenario, robot


# --- the subcommands ----------------------------------------------------------------------


def _cmd_simulate(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.simulate import summary, write_results
    from admittance.diagrams.results.folder import (
        check_output_dir,
        check_replay_file,
        check_writable,
        write_marked_replay,
    )
    from admittance.diagrams.run.engine import SimulationDivergedError
    from admittance.diagrams.run.simulation import simulate
    from admittance.diagrams.views.figures import write_replay

    scenario, _ = _scenario(args)
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
    from admittance.diagrams.results.folder import check_writable
    from admittance.diagrams.scenario.schema import ScenarioError
    from admittance.diagrams.views.picture import write_diagram_picture

    scenario, robot = _scenario(args)
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".svg", ".png", ".dot"):
        raise ScenarioError(f"--out {args.out}: unsupported picture format; use .svg, .png or .dot")
    check_writable(args.out)
    print(f"wrote {write_diagram_picture(robot.build(scenario).diagram, args.out)}")
    return 0


def _before_report(args: argparse.Namespace, scenario, robot) -> dict | None:
    """The earlier report of --before, or None; one line where the robot cannot compare."""
    from admittance.diagrams.robots.kinds import every_robot
    from admittance.diagrams.scenario.schema import ScenarioError

    if not args.before:
        return None
    if robot.bench.load_before is None:
        comparable = [r.noun for r in every_robot() if r.bench and r.bench.load_before]
        raise ScenarioError(
            f"--before {args.before}: compares {' and '.join(comparable)} benchmarks only "
            f"(a {robot.noun} report has other keys)"
        )
    try:
        return robot.bench.load_before(args.before, scenario)
    except ValueError as error:
        raise ScenarioError(str(error)) from None


def _cmd_bench(args: argparse.Namespace, progress) -> int:
    import json

    from admittance.diagrams.app.bench_report import check_bench_file
    from admittance.diagrams.results.folder import atomic_write_text, check_writable
    from admittance.diagrams.scenario.schema import ScenarioError

    if not 1 <= args.repeat <= MAX_REPEAT:
        raise ScenarioError(
            f"--repeat {args.repeat}: must be an integer in [1, {MAX_REPEAT}] (each is a "
            "whole simulation)"
        )
    scenario, robot = _scenario(args)
    before = _before_report(args, scenario, robot)
    if args.json:
        check_writable(args.json, "--json")
        check_bench_file(args.json)
    robot.check_start(scenario)
    report = robot.bench.run(scenario, repeat=args.repeat, progress=progress)
    print(robot.bench.format(report, before))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        check_bench_file(path)  # again: it may have changed during the runs
        atomic_write_text(path, json.dumps(report, indent=2) + "\n")
        print(f"wrote {path}")
    return 0


def _number_list(flag: str, text: str) -> list[float]:
    from admittance.diagrams.scenario.schema import ScenarioError

    try:
        return [float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise ScenarioError(f"{flag} {text!r}: expected a comma list of numbers") from None


def _compare_options(args: argparse.Namespace) -> dict:
    """The options of `args` that its comparison command takes besides the common ones."""
    options = {"controllers": args.controllers}
    if args.command == "grasp-compare":
        options["size_errors"] = _number_list("--size-errors", args.size_errors)
        options["stiffness_errors"] = _number_list("--stiffness-errors", args.stiffness_errors)
    return options


def _cmd_compare(args: argparse.Namespace, progress) -> int:
    """`compare` and `grasp-compare`: the robot's comparison, written to its folder."""
    from admittance.diagrams.results.folder import check_output_dir

    scenario, robot = _scenario(args)
    options = _compare_options(args)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_compare"
    check_output_dir(out, overwrite=args.force)
    text, folder = robot.compare(
        args.scenario,
        args.overrides,
        out,
        **options,
        workers=args.workers,
        overwrite=args.force,
        progress=progress,
    )
    print(text, end="")
    print(folder.describe(out))
    return 0


def _cmd_stability(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.results.folder import check_output_dir
    from admittance.diagrams.robots.record import StabilityOptions

    scenario, robot = _scenario(args)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_stability"
    check_output_dir(out, overwrite=args.force)
    robot.check_start(scenario)
    options = StabilityOptions(quick=args.quick, trajectory=not args.no_trajectory)
    text, folder = robot.stability(scenario, out, options, args.force, progress)
    print(text, end="")
    print(folder.describe(out))
    return 0


def _cmd_sweep(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.sweep import WorkerDiedError, define_sweep, run_sweep
    from admittance.diagrams.views.formatting import seconds

    _scenario(args)
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
    "grasp-compare": _cmd_compare,
    "bench": _cmd_bench,
    "sweep": _cmd_sweep,
    "station": _cmd_station,
    "control": _cmd_control,
}


def _interrupted() -> int:
    """The one line of a Ctrl-C: which result folders were completed before it, if any."""
    completed = []
    module = sys.modules.get("admittance.diagrams.results.folder")
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
    from admittance.diagrams.results.folder import (
        OutputExistsError,
        OutputPathError,
        command_line,
        completed_folders,
    )
    from admittance.diagrams.run.parallel import WorkerDiedError
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
