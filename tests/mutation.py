"""Mutation testing of the laws with cosmic-ray, one module at a time (docs/evidence/testing.md).

    python tests/mutation.py optimal_admittance      # mutate, test, report (resumable)
    python tests/mutation.py --report all            # the scores of the sessions run so far

The targets, the operators left out and the equivalent mutants (each with its reason) are in
tests/mutation.toml under [cosmic-ray]. cosmic-ray reads one target per config file, so
this script writes one config file per target into .mutation/ (git-ignored), with the
target's module and test command, and keeps the session database there: an interrupted run
goes on where it stopped. cosmic-ray rewrites the module on disk for each mutant and puts it
back afterwards: run it on a copy of the repository (or leave the tree alone meanwhile).

The score is killed / (mutants - equivalent), over the mutants that ran (the filtered
operators are skipped, not counted). A mutant listed as equivalent that is killed, or that
no longer matches its source line, is reported so the list stays true.
"""

from __future__ import annotations

import argparse
import ast
import os
import sqlite3
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
WORKDIR = ROOT / ".mutation"


def _settings() -> dict:
    with open(ROOT / "tests" / "mutation.toml", "rb") as stream:
        return tomllib.load(stream)["cosmic-ray"]


def _toml_value(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def _write_config(name: str, settings: dict) -> Path:
    """cosmic-ray's config for one target: its module and its unit tests."""
    target = settings["targets"][name]
    tests = " ".join(target["tests"])
    command = f"{sys.executable} -m pytest -x -q -p no:cacheprovider -p no:hypothesispytest {tests}"
    excluded = settings["exclude-operators"]
    lines = [
        "[cosmic-ray]",
        f"module-path = {_toml_value(target['module-path'])}",
        f"timeout = {_toml_value(float(settings['timeout']))}",
        "excluded-modules = []",
        f"test-command = {_toml_value(command)}",
        "",
        "[cosmic-ray.distributor]",
        'name = "local"',
        "",
        "[cosmic-ray.filters.operators-filter]",
        f"exclude-operators = {_toml_value(excluded)}",
        "",
    ]
    path = WORKDIR / f"{name}.toml"
    path.write_text("\n".join(lines))
    return path


def _run(*command: str) -> None:
    subprocess.run(command, cwd=ROOT, check=True)


def _tool(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def _forget_survivors(session: Path) -> int:
    """Drops the results of the mutants that survived, so that exec runs them again."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    with use_db(str(session), WorkDB.Mode.open) as db:
        survivors = [
            job for job, result in db.results if result.test_outcome == TestOutcome.SURVIVED
        ]
    connection = sqlite3.connect(session)
    with connection:
        connection.executemany(
            "DELETE FROM work_results WHERE job_id = ?", [(job,) for job in survivors]
        )
    connection.close()
    return len(survivors)


def run(name: str, settings: dict, *, reset: bool, retest: bool) -> float:
    """Runs (or resumes) the session of one target; returns the seconds it took."""
    WORKDIR.mkdir(exist_ok=True)
    config = _write_config(name, settings)
    session = WORKDIR / f"{name}.sqlite"
    if reset and session.exists():
        session.unlink()
    start = time.monotonic()
    if not session.exists():
        _run(_tool("cosmic-ray"), "init", str(config), str(session))
        _run(_tool("cr-filter-operators"), str(session), str(config))
    elif retest:
        print(f"{name}: running the {_forget_survivors(session)} survivors again")
    _run(_tool("cosmic-ray"), "exec", str(config), str(session))
    return time.monotonic() - start


def _template_lines(module: Path) -> range:
    """The lines of the module's TemplateSystem function (the nested system class)."""
    tree = ast.parse(module.read_text())
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and any(
            "TemplateSystem" in ast.unparse(decorator) for decorator in node.decorator_list
        ):
            return range(node.lineno, node.end_lineno + 1)
    return range(0)


def _mutated_line(diff: str | None) -> str:
    """The mutant's source line (stripped), from cosmic-ray's diff."""
    for row in (diff or "").splitlines():
        if row.startswith("+") and not row.startswith("+++"):
            return row[1:].strip()
    return ""


def report(name: str, settings: dict) -> dict:
    """Counts of one target's session; prints the survivors that are not known equivalent."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome

    target = settings["targets"][name]
    module = ROOT / target["module-path"]
    source = module.read_text().splitlines()
    equivalent: dict[tuple, list[dict]] = {}
    for entry in target.get("equivalent", []):
        equivalent.setdefault((entry["operator"], entry["line"], entry["column"]), []).append(entry)
    inside = _template_lines(module)
    counts = dict(mutants=0, killed=0, survived=0, equivalent=0, pending=0, in_template=0)
    survivors, stale = [], []
    matched = set()
    with use_db(str(WORKDIR / f"{name}.sqlite"), WorkDB.Mode.open) as db:
        results = dict(db.results)
        for item in db.work_items:
            result = results.get(item.job_id)
            if result is not None and result.worker_outcome == WorkerOutcome.SKIPPED:
                continue  # a filtered operator
            (mutation,) = item.mutations
            line, column = mutation.start_pos
            counts["mutants"] += 1
            counts["in_template"] += line in inside
            if result is None:
                counts["pending"] += 1
                continue
            key = (mutation.operator_name, line, column)
            killed = result.test_outcome in (TestOutcome.KILLED, TestOutcome.INCOMPETENT) or (
                result.worker_outcome in (WorkerOutcome.EXCEPTION, WorkerOutcome.ABNORMAL)
            )
            mutant = _mutated_line(result.diff)
            entry = next(
                (
                    e
                    for e in equivalent.get(key, [])
                    if "mutant" not in e or e["mutant"].strip() == mutant
                ),
                None,
            )
            if entry is not None:
                matched.add((*key, entry.get("mutant")))
                if entry["source"].strip() != source[line - 1].strip():
                    stale.append(f"{name}:{line}: the listed source no longer matches")
                if killed:
                    stale.append(f"{name}:{line}:{column} {key[0]} is listed but killed")
                counts["equivalent"] += 1
                continue
            if killed:
                counts["killed"] += 1
            else:
                counts["survived"] += 1
                survivors.append((line, column, mutation.operator_name, result.diff))
    for key, entries in equivalent.items():
        for entry in entries:
            if (*key, entry.get("mutant")) not in matched:
                stale.append(f"{name}: listed equivalent {key} is no mutant of this session")
    for line, column, operator, diff in sorted(survivors):
        print(f"--- survived {name}:{line}:{column} {operator}")
        print("\n".join(row for row in (diff or "").splitlines() if row[:1] in "+-"))
    for message in stale:
        print("STALE", message)
    scored = counts["mutants"] - counts["equivalent"] - counts["pending"]
    counts["score"] = counts["killed"] / scored if scored else float("nan")
    return counts


def main(argv: list[str] | None = None) -> int:
    settings = _settings()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("targets", nargs="+", help=f"all, or of {sorted(settings['targets'])}")
    parser.add_argument("--report", action="store_true", help="report only, run nothing")
    parser.add_argument(
        "--equivalents", action="store_true", help="print the equivalent mutants as a table"
    )
    parser.add_argument("--reset", action="store_true", help="start the sessions anew")
    parser.add_argument(
        "--retest", action="store_true", help="run the surviving mutants again (after new tests)"
    )
    arguments = parser.parse_args(argv)
    names = sorted(settings["targets"]) if arguments.targets == ["all"] else arguments.targets
    for name in names:
        if name not in settings["targets"]:
            parser.error(f"unknown target {name!r}; one of {sorted(settings['targets'])}")
    os.chdir(ROOT)
    if arguments.equivalents:
        print("| module:line | mutation | why it is equivalent |")
        print("| --- | --- | --- |")
        for name in names:
            for entry in settings["targets"][name].get("equivalent", []):
                operator = entry["operator"].removeprefix("core/")
                change = f"`{entry['mutant']}`" if "mutant" in entry else operator
                print(f"| {name}:{entry['line']} | {change} | {entry['reason']} |")
        return 0
    totals = dict(mutants=0, killed=0, survived=0, equivalent=0, pending=0)
    rows = []
    for name in names:
        seconds = None
        if not arguments.report:
            seconds = run(name, settings, reset=arguments.reset, retest=arguments.retest)
        counts = report(name, settings)
        for key in totals:
            totals[key] += counts[key]
        rows.append((name, counts, seconds))
    print()
    print("| module | mutants | in the template | equivalent | killed | survived | score |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, counts, seconds in rows:
        took = "" if seconds is None else f" ({seconds / 60:.0f} min)"
        print(
            f"| {name}{took} | {counts['mutants']} | {counts['in_template']} | "
            f"{counts['equivalent']} | {counts['killed']} | {counts['survived']} | "
            f"{100 * counts['score']:.1f} % |"
        )
    scored = totals["mutants"] - totals["equivalent"] - totals["pending"]
    if scored:
        print(
            f"\nall: {totals['killed']} killed of {scored} non-equivalent mutants: "
            f"{100 * totals['killed'] / scored:.1f} % ({totals['pending']} pending)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
