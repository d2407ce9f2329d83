"""The `admittance` command line's parser: its subcommands, their options, the exit status.

Standard library only, so that ``--help`` answers without loading Drake. The commands
themselves are :mod:`admittance.diagrams.app.cli`'s, passed in as handlers.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from pathlib import Path

__all__ = [
    "DEFAULT_SCENARIO",
    "EXIT_INPUT_ERROR",
    "EXIT_INTERRUPTED",
    "EXIT_RUN_FAILED",
    "MAX_REPEAT",
    "build_parser",
]

EXIT_RUN_FAILED = 1
EXIT_INPUT_ERROR = 2
EXIT_INTERRUPTED = 130
DEFAULT_SCENARIO = "paper_stiffness_step"
# The built-in scenarios (the YAML files of admittance.diagrams.scenarios), listed without
# importing the scenario module (and Drake) for --help.
_SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"
# The most timed runs `bench --repeat` takes (each one is a whole simulation).
MAX_REPEAT = 100

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


def _add_common_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    parser.add_argument(
        "scenario",
        nargs="?",
        default=default,
        help=f"built-in name ({', '.join(_builtin_names())}) or a YAML path "
        f"(default: {default})",
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


def _version() -> str:
    """The installed distribution's version (one source: pyproject.toml)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("optimal-admittance")
    except PackageNotFoundError:  # pragma: no cover (running from an uninstalled tree)
        return "unknown"


def _subcommand(
    commands, name: str, help: str, default: str = DEFAULT_SCENARIO
) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        name,
        help=help,
        description=help[0].upper() + help[1:] + ".",
        epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_common_arguments(parser, default)
    return parser


def build_parser(handlers: Mapping[str, Callable]) -> argparse.ArgumentParser:
    """The command line's parser; each subcommand's `handler` is handlers[its name]."""
    parser = _Parser(
        prog="admittance",
        description="Optimal admittance control on Drake: the paper's planar arm against its "
        "compliant wall, Drake's planar gripper, spatial arms (Panda, UR5) on a table, and the "
        "split into a station and a controller over LCM.",
        epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"admittance {_version()}")
    parser.add_argument(
        "-q", "--quiet", dest="quiet_all", action="store_true", help="no progress lines on stderr"
    )
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    # In the order of `admittance --help`.
    _add_simulate(commands, handlers)
    _add_diagram(commands, handlers)
    _add_stability(commands, handlers)
    _add_compare(commands, handlers)
    _add_grasp_compare(commands, handlers)
    _add_bench(commands, handlers)
    _add_sweep(commands, handlers)
    _add_hardware_commands(commands, handlers)
    return parser


def _add_simulate(commands, handlers: Mapping[str, Callable]) -> None:
    """`simulate`: one scenario headless, its result folder (and a Meshcat replay)."""
    simulate = _subcommand(commands, "simulate", "run one scenario headless, write results")
    simulate.add_argument("--out", help="output folder (default: results/<scenario name>)")
    simulate.add_argument("--force", action="store_true", help=SIMULATE_FORCE_HELP)
    simulate.add_argument(
        "--meshcat-html",
        metavar="FILE",
        help="also write a self-contained Meshcat replay (see --force)",
    )
    simulate.set_defaults(handler=handlers["simulate"])


def _add_diagram(commands, handlers: Mapping[str, Callable]) -> None:
    """`diagram`: the closed loop's block diagram."""
    diagram = _subcommand(
        commands, "diagram", "draw the closed loop's block diagram (Graphviz: .svg, .png or .dot)"
    )
    diagram.add_argument("--out", required=True, help="output file: .svg, .png or .dot")
    diagram.set_defaults(handler=handlers["diagram"])


def _add_stability(commands, handlers: Mapping[str, Callable]) -> None:
    """`stability`: the linearized loop's report."""
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
    stability.set_defaults(handler=handlers["stability"])


def _add_compare(commands, handlers: Mapping[str, Callable]) -> None:
    """`compare`: every force controller on one scenario."""
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
    compare.set_defaults(handler=handlers["compare"])


def _add_grasp_compare(commands, handlers: Mapping[str, Callable]) -> None:
    """`grasp-compare`: position-only fingers against the paper's law, over model errors."""
    grasp_compare = _subcommand(
        commands,
        "grasp-compare",
        "a grasp with position-only fingers against the paper's law, over brick size and "
        "contact stiffness errors: held, crushed or lost",
        "grasp_hold",
    )
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
    grasp_compare.set_defaults(handler=handlers["grasp-compare"])


def _add_bench(commands, handlers: Mapping[str, Callable]) -> None:
    """`bench`: a scenario timed against the bare plant's floor."""
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
    bench.set_defaults(handler=handlers["bench"])


def _add_sweep(commands, handlers: Mapping[str, Callable]) -> None:
    """`sweep`: a grid or Monte Carlo over scenario keys, its points and where they run."""
    sweep = _subcommand(
        commands,
        "sweep",
        "run a grid or Monte Carlo over scenario keys in parallel: one table, summary plots; "
        "an interrupted sweep resumes where it stopped",
    )
    _add_sweep_points(sweep)
    _add_sweep_engine(sweep)
    sweep.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="sweep folder: points.jsonl (the resumable record), table.csv, summary.txt, PNG",
    )
    sweep.add_argument(
        "--force", action="store_true", help="start over in a folder of another sweep (or result)"
    )
    sweep.set_defaults(handler=handlers["sweep"])


def _add_sweep_points(sweep: argparse.ArgumentParser) -> None:
    """The sweep's points: --grid, --random, --samples, --seed."""
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


def _add_sweep_engine(sweep: argparse.ArgumentParser) -> None:
    """Where the sweep's points run: --workers, --engine, --scheduler."""
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


LCM_HELP = "LCM URL: memq:// (one process) or udpm://GROUP:PORT?ttl=0 (packets stay on this host)"


def _add_hardware_commands(commands, handlers: Mapping[str, Callable]) -> None:
    """`station` and `control`: the robot (simulated) and the controller as two processes
    that speak Drake's LCM driver messages (docs/evidence/hardware.md)."""
    for name, help, default in (
        (
            "station",
            "simulate the Panda in real time as the robot would be: publish its status and "
            "wrist wrench on LCM, apply the commands it receives, hold the arm when they stop",
            "results/<scenario>_station",
        ),
        (
            "control",
            "run the admittance controller alone at the robot's rate, reading only LCM "
            "status and wrench messages and publishing commands; timing.json and events.log",
            "results/<scenario>_control",
        ),
    ):
        command = _subcommand(commands, name, help, "panda_surface_press")
        command.add_argument("--lcm", required=True, metavar="URL", help=LCM_HELP)
        command.add_argument("--out", help=f"output folder (default: {default})")
        command.add_argument("--force", action="store_true", help=FORCE_HELP)
        command.set_defaults(handler=handlers[name])
    station = commands.choices["station"]
    station.add_argument(
        "--pacer",
        action="store_true",
        help="no simulation: publish the status and wrench at the robot's rate from a fixed "
        "posture and time the controller's answers (pacer.json)",
    )
