"""The `admittance` command line (see README.md, "Commands").

    admittance simulate  [SCENARIO] [--set KEY=VALUE ...] [--out DIR] [--force]
    admittance stability [SCENARIO] [--set KEY=VALUE ...] [--out DIR] [--force] [--quick]
    admittance diagram   [SCENARIO] [--set KEY=VALUE ...] --out FILE
    admittance compare   [SCENARIO] [--set KEY=VALUE ...] [--controllers K,...] [--out DIR]
    admittance bench     [SCENARIO] [--set KEY=VALUE ...] [--repeat N] [--json FILE]
                         [--before FILE]
    admittance sweep     [SCENARIO] [--set KEY=VALUE ...] [--grid KEY=SPEC ...]
                         [--random KEY=DIST ...] [--samples N] [--seed S] [--workers N]
                         [--engine local|dask] [--scheduler ADDRESS] --out DIR [--force]

Errors in the input print one line naming the key and exit with status 2; a run that fails
(a diverging simulation) prints one line and exits with status 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from admittance.diagrams.app.result_folder import (
    OutputExistsError,
    atomic_write_text,
    check_output_dir,
)
from admittance.diagrams.scenario import ScenarioError, builtin_scenario_names, load_scenario

DEFAULT_SCENARIO = "paper_stiffness_step"
EXIT_INPUT_ERROR = 2
EXIT_RUN_FAILED = 1


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in one line with status 2."""

    def error(self, message: str) -> None:  # noqa: D102
        self.exit(EXIT_INPUT_ERROR, f"{self.prog}: error: {message}\n")


def _add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        help=f"built-in name ({', '.join(builtin_scenario_names())}) or a YAML path "
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


def _cmd_simulate(args: argparse.Namespace) -> int:
    from admittance.diagrams.app.simulate import summary, write_results
    from admittance.diagrams.simulation import SimulationDivergedError, run_scenario

    scenario = load_scenario(args.scenario, args.overrides)
    out = Path(args.out) if args.out else Path("results") / scenario.name
    check_output_dir(out, overwrite=args.force)
    try:
        result = run_scenario(scenario)
    except SimulationDivergedError as diverged:
        # Keep what was logged, marked failed (metrics.json: "failed": true).
        write_results(diverged.result, out, overwrite=args.force)
        print(f"admittance: error: {diverged} (partial, failed result in {out}/)", file=sys.stderr)
        return EXIT_RUN_FAILED
    write_results(result, out, overwrite=args.force)
    print(summary(result))
    print(f"wrote {out}/: timeseries.csv, metrics.json, scenario.yaml, fig5-7 PNG")
    if args.meshcat_html:
        from admittance.diagrams.visualization import write_meshcat_replay

        print(f"wrote {write_meshcat_replay(result, args.meshcat_html)} (Meshcat replay)")
    return 0


def _cmd_diagram(args: argparse.Namespace) -> int:
    from admittance.diagrams.closed_loop import BuildClosedLoop
    from admittance.diagrams.visualization import write_diagram_picture

    scenario = load_scenario(args.scenario, args.overrides)
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".svg", ".png", ".dot"):
        raise ScenarioError(f"--out {args.out}: unsupported picture format; use .svg, .png or .dot")
    loop = BuildClosedLoop(scenario)
    print(f"wrote {write_diagram_picture(loop.diagram, args.out)}")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    import json

    from admittance.diagrams.app.bench import (
        format_benchmark,
        load_benchmark_report,
        run_benchmark,
    )

    scenario = load_scenario(args.scenario, args.overrides)
    if args.repeat < 1:
        raise ScenarioError(f"--repeat {args.repeat}: must be an integer >= 1")
    before = None
    if args.before:
        try:
            before = load_benchmark_report(args.before, scenario)
        except ValueError as error:
            raise ScenarioError(str(error)) from None
    report = run_benchmark(scenario, repeat=args.repeat)
    print(format_benchmark(report, before))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps(report, indent=2) + "\n")
        print(f"wrote {path}")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from admittance.diagrams.app.compare import compare_controllers, format_table, write_comparison
    from admittance.diagrams.force_controllers import baseline_gains
    from admittance.diagrams.scenario import CONTROLLER_KINDS

    kinds = [k.strip() for k in args.controllers.split(",")] if args.controllers else None
    for kind in kinds or []:
        if kind not in CONTROLLER_KINDS:
            raise ScenarioError(
                f"--controllers: {kind!r} is not a controller; allowed: "
                + ", ".join(CONTROLLER_KINDS)
            )
    scenario = load_scenario(args.scenario, args.overrides)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_compare"
    check_output_dir(out, overwrite=args.force)
    scenario, runs = compare_controllers(
        args.scenario, args.overrides, kinds or CONTROLLER_KINDS, workers=args.workers
    )
    gains = ", ".join(f"{k} {v:.3g}" for k, v in baseline_gains(scenario).items())
    print(f"{scenario.name}: Fr = {scenario.force_reference:g} N; baseline gains ({gains})")
    print(format_table(runs), end="")
    write_comparison(scenario, runs, out, overwrite=args.force)
    print(f"wrote {out}/: table.txt, table.csv, metrics.json, force.png")
    return 0


def _cmd_stability(args: argparse.Namespace) -> int:
    from admittance.diagrams.app.stability_report import (
        MapAxes,
        analyse,
        format_report,
        write_report,
    )

    scenario = load_scenario(args.scenario, args.overrides)
    out = Path(args.out) if args.out else Path("results") / f"{scenario.name}_stability"
    axes = MapAxes.quick() if args.quick else MapAxes()
    check_output_dir(out, overwrite=args.force)
    report = analyse(scenario, axes=axes, with_trajectory=not args.no_trajectory)
    write_report(report, out, overwrite=args.force)
    print(format_report(report.summary), end="")
    print(f"wrote {out}/: report.json, report.txt, eigenvalues, maps and V(t) as PNG")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from admittance.diagrams.app.sweep import SweepWorkerError, define_sweep, run_sweep

    definition = define_sweep(
        args.scenario,
        args.overrides,
        grid=args.grid,
        random=args.random,
        samples=args.samples,
        seed=args.seed,
    )
    try:
        outcome = run_sweep(
            definition,
            args.out,
            workers=args.workers,
            engine=args.engine,
            scheduler=args.scheduler,
            force=args.force,
        )
    except KeyboardInterrupt:
        print(
            f"admittance: interrupted; the finished points are kept in {args.out}/points.jsonl: "
            f"run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    except SweepWorkerError as error:
        print(f"admittance: error: {error}", file=sys.stderr)
        return EXIT_RUN_FAILED
    print(outcome.summary, end="")
    print(
        f"ran {outcome.ran} points in {outcome.elapsed:.1f} s ({outcome.skipped} skipped); "
        f"wrote {outcome.out_dir}/: points.jsonl, table.csv, summary.txt, "
        f"{len(outcome.files) - 3} summary plot(s)"
    )
    return 0


def _version() -> str:
    """The installed distribution's version (one source: pyproject.toml)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("optimal-admittance")
    except PackageNotFoundError:  # pragma: no cover (running from an uninstalled tree)
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="admittance",
        description="Optimal admittance control of a 3-DOF planar arm against a compliant "
        "wall (Drake).",
    )
    parser.add_argument("--version", action="version", version=f"admittance {_version()}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    simulate = commands.add_parser("simulate", help="run one scenario headless, write results")
    _add_scenario_arguments(simulate)
    simulate.add_argument("--out", help="output folder (default: results/<scenario name>)")
    simulate.add_argument("--force", action="store_true", help="replace an existing --out folder")
    simulate.add_argument(
        "--meshcat-html", metavar="FILE", help="also write a self-contained Meshcat replay"
    )
    simulate.set_defaults(handler=_cmd_simulate)

    diagram = commands.add_parser(
        "diagram", help="draw the closed loop's block diagram (Graphviz: .svg, .png or .dot)"
    )
    _add_scenario_arguments(diagram)
    diagram.add_argument("--out", required=True, help="output file: .svg, .png or .dot")
    diagram.set_defaults(handler=_cmd_diagram)

    stability = commands.add_parser(
        "stability",
        help="linearize the loop at its contact equilibrium: eigenvalues, Lyapunov "
        "certificate, eq. 13, critical Gamma and stability maps",
    )
    _add_scenario_arguments(stability)
    stability.add_argument("--out", help="output folder (default: results/<scenario>_stability)")
    stability.add_argument("--force", action="store_true", help="replace an existing --out folder")
    stability.add_argument("--quick", action="store_true", help="coarse map grids")
    stability.add_argument(
        "--no-trajectory", action="store_true", help="skip V(t) along a simulated run"
    )
    stability.set_defaults(handler=_cmd_stability)

    compare = commands.add_parser(
        "compare",
        help="run every force controller (the paper's and the baselines) on one scenario: "
        "a table and overlaid force plots",
    )
    _add_scenario_arguments(compare)
    compare.add_argument(
        "--controllers", metavar="K,...", help="a comma list of controller.kind values (all)"
    )
    compare.add_argument("--workers", type=int, help="parallel runs (default: the cores)")
    compare.add_argument("--out", help="output folder (default: results/<scenario>_compare)")
    compare.add_argument("--force", action="store_true", help="replace an existing --out folder")
    compare.set_defaults(handler=_cmd_compare)

    bench = commands.add_parser(
        "bench",
        help="time a scenario (median of --repeat runs after a warm-up) against the bare "
        "plant's floor; where the time goes",
    )
    _add_scenario_arguments(bench)
    bench.add_argument("--repeat", type=int, default=3, help="timed runs (default 3)")
    bench.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    bench.add_argument(
        "--before",
        metavar="FILE",
        help="the --json report of an earlier run of the same scenario (e.g. on the code "
        "before a change), printed beside this one with its per-callback profile",
    )
    bench.set_defaults(handler=_cmd_bench)

    sweep = commands.add_parser(
        "sweep",
        help="run a grid or Monte Carlo over scenario keys in parallel: one table, summary "
        "plots; an interrupted sweep resumes where it stopped",
    )
    _add_scenario_arguments(sweep)
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
        "--force", action="store_true", help="start over in a folder that holds another sweep"
    )
    sweep.set_defaults(handler=_cmd_sweep)
    return parser


def main(argv: list[str] | None = None) -> int:
    import matplotlib

    matplotlib.use("Agg")  # headless: figures go to files
    from admittance.diagrams.visualization import DiagramPictureError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except (ScenarioError, OutputExistsError, DiagramPictureError) as error:
        print(f"admittance: error: {error}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except BrokenPipeError:  # the reader went away (e.g. `| head`): not an error of the run
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (so the exit flush stays quiet)
        return 0
    except KeyboardInterrupt:
        print("admittance: interrupted; no result was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
