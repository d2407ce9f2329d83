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

from admittance.diagrams.app.interrupts import sigint_held_back

EXIT_RUN_FAILED = 1
EXIT_INPUT_ERROR = 2
EXIT_INTERRUPTED = 130
DEFAULT_SCENARIO = "paper_stiffness_step"
# The built-in scenarios (the YAML files of admittance.diagrams.scenarios), listed without
# importing the scenario module (and Drake) for --help.
_SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"
# The most timed runs `bench --repeat` takes (each one is a whole simulation).
MAX_REPEAT = 100

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
    "pydrake.math",
    "pydrake.multibody.math",
    "pydrake.multibody.parsing",
    "pydrake.multibody.plant",
    "pydrake.multibody.tree",
    "pydrake.symbolic",
    "pydrake.systems.analysis",
    "pydrake.systems.framework",
    "pydrake.systems.primitives",
    "pydrake.systems.scalar_conversion",
    "pydrake.trajectories",
)

EXIT_STATUS = """\
exit status:
  0    done
  1    the run failed (a simulation diverged, a worker process died); one line on stderr
  2    bad input (a scenario key or value, a flag, a file, an --out folder); one line on
       stderr, nothing written (but a result kept beside an --out folder that changed, named)
  130  interrupted (Ctrl-C or SIGTERM); one line on stderr, nothing half-written
"""


FORCE_HELP = "replace an earlier result of this tool in --out, never a folder with other files"
SIMULATE_FORCE_HELP = FORCE_HELP + " (and an earlier --meshcat-html replay)"


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in one line with status 2."""

    def error(self, message: str) -> None:  # noqa: D102
        self.exit(EXIT_INPUT_ERROR, f"{self.prog}: error: {message}\n")


def _builtin_names() -> list[str]:
    return sorted(path.stem for path in _SCENARIO_DIR.glob("*.yaml"))


def _add_common_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        help=f"built-in name ({', '.join(_builtin_names())}) or a YAML path "
        f"(default: {DEFAULT_SCENARIO})",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key, e.g. --set wall.stiffness=2e4 (repeatable)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")


def _error(message: str) -> None:
    print(f"admittance: error: {message}", file=sys.stderr)


def _arm_scenario(args: argparse.Namespace):
    """The arm scenario of `args`; a grasp scenario is refused with one line."""
    from admittance.diagrams.grasp_scenario import GraspScenario
    from admittance.diagrams.scenario import ScenarioError, load_scenario

    scenario = load_scenario(args.scenario, args.overrides)
    if isinstance(scenario, GraspScenario):
        raise ScenarioError(
            f"scenario: '{args.scenario}' is a grasp scenario (kind: grasp); `admittance "
            f"{args.command}` runs arm scenarios only (grasps: simulate, diagram, grasp-compare)"
        )
    return scenario


# --- the subcommands ----------------------------------------------------------------------


def _cmd_simulate(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.result_folder import (
        check_output_dir,
        check_replay_file,
        check_writable,
        write_marked_replay,
    )
    from admittance.diagrams.grasp_scenario import GraspScenario
    from admittance.diagrams.scenario import load_scenario
    from admittance.diagrams.simulation import SimulationDivergedError

    scenario = load_scenario(args.scenario, args.overrides)
    # The run, its result folder, summary and replay, by the scenario's kind.
    if isinstance(scenario, GraspScenario):
        from admittance.diagrams.app.grasp_results import grasp_summary as summary
        from admittance.diagrams.app.grasp_results import write_grasp_results as write_results
        from admittance.diagrams.grasp_replay import write_grasp_meshcat_replay as replay
        from admittance.diagrams.grasp_simulation import run_grasp as run
    else:
        from admittance.diagrams.app.simulate import summary, write_results
        from admittance.diagrams.simulation import run_scenario as run
        from admittance.diagrams.visualization import write_meshcat_replay as replay
    out = Path(args.out) if args.out else Path("results") / scenario.name
    check_output_dir(out, overwrite=args.force)
    if args.meshcat_html:
        check_writable(args.meshcat_html, "--meshcat-html")
        check_replay_file(args.meshcat_html, args.force)
    try:
        result = run(scenario, progress=progress.simulation(scenario.name, scenario.duration))
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
        write_marked_replay(replay, result, Path(args.meshcat_html), args.force, out)
        print(f"wrote {args.meshcat_html} (Meshcat replay)")
    return 0


def _cmd_diagram(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.result_folder import check_writable
    from admittance.diagrams.closed_loop import BuildClosedLoop
    from admittance.diagrams.grasp import BuildGrasp
    from admittance.diagrams.grasp_scenario import GraspScenario
    from admittance.diagrams.scenario import ScenarioError, load_scenario
    from admittance.diagrams.visualization import write_diagram_picture

    scenario = load_scenario(args.scenario, args.overrides)
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".svg", ".png", ".dot"):
        raise ScenarioError(f"--out {args.out}: unsupported picture format; use .svg, .png or .dot")
    check_writable(args.out)
    grasp = isinstance(scenario, GraspScenario)
    loop = BuildGrasp(scenario) if grasp else BuildClosedLoop(scenario)
    print(f"wrote {write_diagram_picture(loop.diagram, args.out)}")
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
    from admittance.diagrams.closed_loop import CheckScenarioStarts
    from admittance.diagrams.scenario import ScenarioError

    if not 1 <= args.repeat <= MAX_REPEAT:
        raise ScenarioError(
            f"--repeat {args.repeat}: must be an integer in [1, {MAX_REPEAT}] (each is a "
            "whole simulation)"
        )
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
    from admittance.diagrams.scenario import CONTROLLER_KINDS, ScenarioError

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
    from admittance.diagrams.force_controllers import baseline_gains

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
    from admittance.diagrams.scenario import ScenarioError

    try:
        return [float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise ScenarioError(f"{flag} {text!r}: expected a comma list of numbers") from None


def _cmd_grasp_compare(args: argparse.Namespace, progress) -> int:
    from admittance.diagrams.app.grasp_compare import compare_grasps, format_grasp_table
    from admittance.diagrams.app.result_folder import check_output_dir, result_folder
    from admittance.diagrams.grasp_scenario import GRASP_CONTROLLER_KINDS, GraspScenario
    from admittance.diagrams.scenario import ScenarioError, load_scenario

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
    from admittance.diagrams.closed_loop import CheckScenarioStarts

    scenario = _arm_scenario(args)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_stability"
    axes = MapAxes.quick() if args.quick else MapAxes()
    check_output_dir(out, overwrite=args.force)
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


# --- the parser ---------------------------------------------------------------------------


def _version() -> str:
    """The installed distribution's version (one source: pyproject.toml)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("optimal-admittance")
    except PackageNotFoundError:  # pragma: no cover (running from an uninstalled tree)
        return "unknown"


def _subcommand(commands, name: str, help: str) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        name,
        help=help,
        description=help[0].upper() + help[1:] + ".",
        epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_common_arguments(parser)
    return parser


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="admittance",
        description="Optimal admittance control of a 3-DOF planar arm against a compliant "
        "wall (Drake).",
        epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"admittance {_version()}")
    parser.add_argument(
        "-q", "--quiet", dest="quiet_all", action="store_true", help="no progress lines on stderr"
    )
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    simulate = _subcommand(commands, "simulate", "run one scenario headless, write results")
    simulate.add_argument("--out", help="output folder (default: results/<scenario name>)")
    simulate.add_argument("--force", action="store_true", help=SIMULATE_FORCE_HELP)
    simulate.add_argument(
        "--meshcat-html",
        metavar="FILE",
        help="also write a self-contained Meshcat replay (see --force)",
    )
    simulate.set_defaults(handler=_cmd_simulate)

    diagram = _subcommand(
        commands, "diagram", "draw the closed loop's block diagram (Graphviz: .svg, .png or .dot)"
    )
    diagram.add_argument("--out", required=True, help="output file: .svg, .png or .dot")
    diagram.set_defaults(handler=_cmd_diagram)

    stability = _subcommand(
        commands,
        "stability",
        "linearize the loop at its contact equilibrium: eigenvalues, Lyapunov certificate, "
        "eq. 13, critical Gamma and stability maps",
    )
    stability.add_argument("--out", help="output folder (default: results/<scenario>_stability)")
    stability.add_argument("--force", action="store_true", help=FORCE_HELP)
    stability.add_argument("--quick", action="store_true", help="coarse map grids")
    stability.add_argument(
        "--no-trajectory", action="store_true", help="skip V(t) along a simulated run"
    )
    stability.set_defaults(handler=_cmd_stability)

    compare = _subcommand(
        commands,
        "compare",
        "run every force controller (the paper's and the baselines) on one scenario: a table "
        "and overlaid force plots",
    )
    compare.add_argument(
        "--controllers", metavar="K,...", help="a comma list of controller.kind values (all)"
    )
    compare.add_argument("--workers", type=int, help="parallel runs (default: the cores)")
    compare.add_argument("--out", help="output folder (default: results/<scenario>_compare)")
    compare.add_argument("--force", action="store_true", help=FORCE_HELP)
    compare.set_defaults(handler=_cmd_compare)

    grasp_compare = _subcommand(
        commands,
        "grasp-compare",
        "a grasp with position-only fingers against the paper's law, over brick size and "
        "contact stiffness errors: held, crushed or lost",
    )
    grasp_compare.set_defaults(scenario="grasp_hold")
    grasp_compare.add_argument(
        "--size-errors",
        default="-0.002,0,0.002",
        metavar="M,...",
        help="brick.size_error values, m (default -0.002,0,0.002)",
    )
    grasp_compare.add_argument(
        "--stiffness-errors",
        default="0.1,1,10",
        metavar="R,...",
        help="brick.stiffness_error values (default 0.1,1,10)",
    )
    grasp_compare.add_argument(
        "--controllers", metavar="K,...", help="pid_only,optimal_admittance (default both)"
    )
    grasp_compare.add_argument("--workers", type=int, help="parallel runs (default: the cores)")
    grasp_compare.add_argument("--out", help="output folder (default: results/<scenario>_compare)")
    grasp_compare.add_argument("--force", action="store_true", help=FORCE_HELP)
    grasp_compare.set_defaults(handler=_cmd_grasp_compare)

    bench = _subcommand(
        commands,
        "bench",
        "time a scenario (median of --repeat runs after a warm-up) against the bare plant's "
        "floor; where the time goes",
    )
    bench.add_argument(
        "--repeat", type=int, default=3, help=f"timed runs, 1 to {MAX_REPEAT} (default 3)"
    )
    bench.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    bench.add_argument(
        "--before",
        metavar="FILE",
        help="the --json report of an earlier run of the same scenario (e.g. on the code "
        "before a change), printed beside this one with its per-callback profile",
    )
    bench.set_defaults(handler=_cmd_bench)

    sweep = _subcommand(
        commands,
        "sweep",
        "run a grid or Monte Carlo over scenario keys in parallel: one table, summary plots; "
        "an interrupted sweep resumes where it stopped",
    )
    sweep.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="KEY=SPEC",
        help="sweep a key over 1e4,5e4,1e5 or linspace:A:B:N or logspace:A:B:N (repeatable: "
        "the Cartesian product)",
    )
    sweep.add_argument(
        "--random",
        action="append",
        default=[],
        metavar="KEY=DIST",
        help="draw a key from uniform:A:B, loguniform:A:B, normal:MEAN:STD, randint:A:B or "
        "choice:a,b,c (repeatable; needs --samples)",
    )
    sweep.add_argument(
        "--samples", type=int, metavar="N", help="Monte Carlo samples (per grid point)"
    )
    sweep.add_argument(
        "--seed", type=int, default=0, metavar="S", help="seed of the draws (default 0)"
    )
    sweep.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="parallel processes (default: all cores, os.cpu_count())",
    )
    sweep.add_argument(
        "--engine",
        choices=("local", "dask"),
        default="local",
        help="local process pool (default) or a dask.distributed cluster (pip install -e .[dask])",
    )
    sweep.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="with --engine dask: the scheduler to use (default: start a LocalCluster)",
    )
    sweep.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="sweep folder: points.jsonl (the resumable record), table.csv, summary.txt, PNG",
    )
    sweep.add_argument(
        "--force", action="store_true", help="start over in a folder of another sweep (or result)"
    )
    sweep.set_defaults(handler=_cmd_sweep)
    return parser


# --- main ---------------------------------------------------------------------------------


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
    from admittance.diagrams.scenario import ScenarioError
    from admittance.diagrams.visualization import DiagramPictureError

    completed_folders.clear()
    command_line[:] = ["admittance", *argv]  # recorded in the result folders' markers
    progress = Progress(args.command, quiet=args.quiet or args.quiet_all)
    try:
        return args.handler(args, progress)
    except (ScenarioError, OutputExistsError, OutputPathError, DiagramPictureError) as error:
        _error(str(error))
        return EXIT_INPUT_ERROR
    except WorkerDiedError as error:  # compare, grasp-compare (sweep says what it kept)
        _error(str(error))
        return EXIT_RUN_FAILED
    except OSError as error:  # the system refused a write that was possible at the start
        where = f"{error.filename}: " if error.filename else ""
        _error(f"{where}{error.strerror or error}")
        return EXIT_RUN_FAILED


def main(argv: list[str] | None = None) -> int:
    """Runs the command line; returns the exit status (0, 1, 2 or 130)."""
    try:
        args = build_parser().parse_args(argv)
        return _run(args, sys.argv[1:] if argv is None else list(argv))
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:  # the reader went away (e.g. `| head`): not an error of the run
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (so the exit flush stays quiet)
        return 0


if __name__ == "__main__":
    sys.exit(main())
