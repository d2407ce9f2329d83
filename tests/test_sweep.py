"""`admittance sweep`: specs, the table, resume after a kill, Dask.

Every sweep here is a few short runs (1.5-2 s of paper_moving_wall, 2-4 points).
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time

import pytest

from admittance.diagrams.app.cli import main
from admittance.diagrams.app.sweep import (
    GRID_FORMS,
    RANDOM_FORMS,
    SweepError,
    define_sweep,
    parse_grid,
    parse_random,
    read_points,
    run_point,
    summarize,
    table_text,
)
from admittance.diagrams.results.folder import MARKER, marker_entries

FORCE_REFERENCE = 5.0  # paper_moving_wall's Fr, N
SHORT = ["paper_moving_wall", "--set", "duration=1.5"]


def _table(out):
    with open(out / "table.csv") as file:
        return list(csv.DictReader(file))


def _lines(out):
    return (out / "points.jsonl").read_text().splitlines(keepends=True)


def _numeric(row: dict) -> dict:
    """The numeric cells of a table.csv row (None for an empty cell)."""
    skip = ("point_id", "failed", "failure")
    return {k: float(v) if v != "" else None for k, v in row.items() if k not in skip}


def _same_metrics(a: dict, b: dict) -> bool:
    """Rows of two runs of the same point agree (times excepted; None = no value)."""
    keys = (set(a) | set(b)) - {"wall_time", "point_time"}
    for key in keys:
        if a.get(key) is None or b.get(key) is None:
            if a.get(key) is not b.get(key):
                return False
        elif a[key] != pytest.approx(b[key], rel=1e-9, abs=1e-12):
            return False
    return True


def _start_sweep(arguments: list[str]) -> subprocess.Popen:
    # Ctrl-C's default handler even if this test runs where SIGINT is ignored (a
    # background job without job control passes SIG_IGN on to its children).
    command = (
        "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from admittance.diagrams.app.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    return subprocess.Popen(
        [sys.executable, "-c", command, *arguments],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _messages(stderr: str) -> list[str]:
    """The lines of stderr that are not progress lines (``admittance sweep: ...``)."""
    return [line for line in stderr.splitlines() if not line.startswith("admittance sweep: ")]


def _wait_for_a_point(process: subprocess.Popen, points) -> None:
    """Returns once points.jsonl holds one whole line: a finished point (a line is written
    whole, then its newline; a file that is merely not empty may hold a torn line)."""
    deadline = time.monotonic() + 120
    while not (points.exists() and b"\n" in points.read_bytes()):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "no point finished in 120 s"
        time.sleep(0.01)


# --- specs --------------------------------------------------------------------------------


def test_grid_specs():
    axis = parse_grid("wall.stiffness=1e4,5e4,1e5")
    assert axis.key == "wall.stiffness" and axis.values == (1e4, 5e4, 1e5) and not axis.log
    axis = parse_grid("wall.position=linspace:0.145:0.155:3")
    assert axis.values == pytest.approx((0.145, 0.150, 0.155)) and not axis.log
    axis = parse_grid("wall.stiffness=logspace:1e3:1e6:4")  # A and B in real units
    assert axis.values == pytest.approx((1e3, 1e4, 1e5, 1e6)) and axis.log
    axis = parse_grid("sensor.kind=ideal,flexiforce")
    assert axis.values == ("ideal", "flexiforce")
    axis = parse_grid("arm.initial_position=[0.14, -0.25, 1.57],[0.15, -0.25, 1.57]")
    assert axis.values == ([0.14, -0.25, 1.57], [0.15, -0.25, 1.57])
    assert parse_grid("wall.stiffness=1e3,1e5").log  # a list over two decades plots in log


def test_random_specs_and_reproducible_draws():
    assert parse_random("wall.stiffness=loguniform:1e3:1e6").log
    assert parse_random("sensor.kind=choice:ideal,flexiforce").parameters == ("ideal", "flexiforce")
    arguments = dict(
        random=[
            "wall.stiffness=loguniform:1e3:1e6",
            "wall.position=uniform:0.145:0.155",
            "force_reference=normal:5:0.5",
            "seed=randint:0:9",
            "sensor.kind=choice:ideal,flexiforce",
        ],
        samples=50,
        seed=7,
    )
    first = define_sweep("paper_moving_wall", ["duration=1"], **arguments)
    again = define_sweep("paper_moving_wall", ["duration=1"], **arguments)
    assert [p.values for p in first.points] == [p.values for p in again.points]
    assert [p.point_id for p in first.points] == [p.point_id for p in again.points]
    assert len({p.point_id for p in first.points}) == 50
    values = [p.values for p in first.points]
    assert all(1e3 <= v["wall.stiffness"] <= 1e6 for v in values)
    assert all(0.145 <= v["wall.position"] <= 0.155 for v in values)
    assert all(isinstance(v["seed"], int) and 0 <= v["seed"] <= 9 for v in values)
    assert {v["sensor.kind"] for v in values} == {"ideal", "flexiforce"}
    # Log-uniform: about as many draws in each decade.
    decades = [int(math.log10(v["wall.stiffness"])) for v in values]
    assert all(8 <= decades.count(d) <= 28 for d in (3, 4, 5))
    other = define_sweep("paper_moving_wall", ["duration=1"], **{**arguments, "seed": 8})
    assert [p.values for p in other.points] != [p.values for p in first.points]


def test_grid_times_samples_share_the_draws():
    definition = define_sweep(
        "paper_moving_wall",
        grid=["wall.stiffness=1e4,1e5"],
        random=["wall.position=uniform:0.145:0.155"],
        samples=3,
        seed=1,
    )
    points = definition.points
    assert [p.index for p in points] == list(range(6))
    assert [p.values["wall.stiffness"] for p in points] == [1e4] * 3 + [1e5] * 3
    positions = [p.values["wall.position"] for p in points]
    assert positions[:3] == positions[3:]  # common random numbers across grid points
    assert len({p.point_id for p in points}) == 6


@pytest.mark.parametrize(
    "flag, text, problem",
    [
        ("--grid", "wall.stiffness", "expected KEY=SPEC"),
        ("--grid", "wall.stiffness=", "expected KEY=SPEC"),
        ("--grid", "wall.stiffness=logspace:0:1e5:3", "A > 0"),
        ("--grid", "wall.stiffness=linspace:1e4:1e5", "A:B:N"),
        ("--grid", "wall.stiffness=linspace:1e4:1e5:2.5", "integer"),
        ("--grid", "wall.stiffness=uniform:1e4:1e5", "unknown form"),
        ("--grid", "wall.stiffness=1e4,,1e5", "empty value"),
        ("--grid", "wall.stiffness=1e4,1e4", "twice"),
        ("--random", "wall.stiffness=gauss:1:2", "unknown distribution"),
        ("--random", "wall.stiffness=uniform:2e4:1e4", "A < B"),
        ("--random", "wall.stiffness=loguniform:0:1e4", "A > 0"),
        ("--random", "wall.stiffness=normal:1e4:0", "STD > 0"),
        ("--random", "wall.stiffness=uniform:abc:1e4", "not a number"),
        ("--random", "seed=randint:0.5:3", "integers"),
        ("--random", "wall.stiffness=uniform:1e4", "A:B"),
    ],
)
def test_bad_specs_name_the_flag_and_the_allowed_forms(flag, text, problem):
    parse = parse_grid if flag == "--grid" else parse_random
    with pytest.raises(SweepError) as raised:
        parse(text)
    message = str(raised.value)
    assert message.startswith(f"{flag} {text!r}:") and problem in message
    assert (GRID_FORMS if flag == "--grid" else RANDOM_FORMS) in message
    assert "\n" not in message


@pytest.mark.parametrize(
    "arguments, expected",
    [
        (["--grid", "wall.stifness=1e4,2e4"], "did you mean 'wall.stiffness'"),
        (["--grid", "wall.stiffness=2e4,-1"], "wall.stiffness: must be in (0"),
        (["--random", "seed=uniform:0:9", "--samples", "2"], "seed: expected an integer"),
        (["--random", "wall.stiffness=uniform:1e4:2e4"], "--samples: required"),
        (["--grid", "wall.stiffness=2e4", "--grid", "wall.stiffness=3e4"], "already swept"),
        (["--grid", "wall.stiffness=uniform:1e4:2e4"], "--grid 'wall.stiffness=uniform"),
        (["--set", "wall.stiffness=abc", "--grid", "wall.position=0.15"], "expected a number"),
        (["--grid", "wall.position=0.15", "--workers", "0"], "--workers 0"),
        (["--grid", "wall.position=0.15", "--scheduler", "tcp://x:1"], "--engine dask"),
        ([], "at least one --grid"),
    ],
)
def test_bad_input_exits_2_with_one_line_before_anything_runs(
    tmp_path, capsys, arguments, expected
):
    out = tmp_path / "sweep"
    assert main(["sweep", *SHORT, *arguments, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], captured.err
    assert captured.out == "" and not out.exists()


def test_point_out_of_the_valid_range_names_the_point(tmp_path, capsys):
    # Fr = 60 N is valid alone, but not with max_push 1 cm and Kp 1200: a cross-key check.
    out = tmp_path / "sweep"
    arguments = ["sweep", *SHORT, "--grid", "force_reference=5,60", "--out", str(out)]
    assert main(arguments) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "force_reference=60" in error and not out.exists()


def test_missing_dask_is_one_line_that_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    out = tmp_path / "sweep"
    arguments = ["sweep", *SHORT, "--grid", "wall.stiffness=2e4", "--engine", "dask"]
    assert main([*arguments, "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "pip install -e .[dask]" in error and not out.exists()


# --- points, table, summary ---------------------------------------------------------------


def test_a_failing_point_is_a_row_not_an_exception():
    task = {
        "index": 0,
        "point_id": "unreachable",
        "values": {"arm.initial_position": [0.9, -0.25, 1.5708]},
        "scenario": "paper_moving_wall",
        "overrides": {"duration": 0.5, "arm.initial_position": [0.9, -0.25, 1.5708]},
    }
    row = run_point(task)
    assert row["failed"] is True and "arm.initial_position" in row["failure"]
    assert row["metrics"]["point_time"] > 0 and "peak_force" not in row["metrics"]
    json.dumps(row, allow_nan=False)  # a points.jsonl line


def test_table_and_summary_show_failures_and_degraded_points():
    definition = define_sweep("paper_moving_wall", grid=["wall.stiffness=1e4,2e4,3e4"])
    ids = [p.point_id for p in definition.points]
    base = {"force_reference": 5.0, "contact_losses": 0, "point_time": 1.0}
    rows = [
        {
            "index": 2,
            "point_id": ids[2],
            "values": {"wall.stiffness": 3e4},
            "failed": True,
            "failure": "simulation diverged: at t = 1 s",
            "metrics": {"point_time": 0.5},
        },
        {
            "index": 0,
            "point_id": ids[0],
            "values": {"wall.stiffness": 1e4},
            "failed": False,
            "failure": None,
            "metrics": {**base, "peak_force": 20.0, "steady_state_force_error": 0.01},
        },
        {
            "index": 1,
            "point_id": ids[1],
            "values": {"wall.stiffness": 2e4},
            "failed": False,
            "failure": None,
            "metrics": {**base, "peak_force": 90.0, "steady_state_force_error": 0.4},
        },
    ]
    table = list(csv.DictReader(table_text(definition.keys, rows).splitlines()))
    assert [r["index"] for r in table] == ["0", "1", "2"]
    assert table[2]["failed"] == "true" and "diverged" in table[2]["failure"]
    assert table[2]["peak_force"] == "" and table[1]["wall.stiffness"] == "20000.0"
    text = summarize(definition, rows)
    assert "3 points, 3 finished, 1 failed" in text
    assert "tracking degrades (steady-state force error > 5 % of Fr, or failed) at 2 of 3" in text
    assert "#1 (wall.stiffness=2e+04): 0.4 N" in text  # the worst steady-state error
    assert "the worst peak force:\n    #1 (wall.stiffness=2e+04): 90 N" in text
    assert "#2 (wall.stiffness=3e+04): simulation diverged" in text


def test_read_points_ignores_a_torn_last_line(tmp_path):
    path = tmp_path / "points.jsonl"
    good = json.dumps({"index": 0, "point_id": "a", "values": {}}) + "\n"
    torn = json.dumps({"index": 1, "point_id": "b", "values": {}})[:20]
    path.write_text(good + "not json\n" + good.replace('"a"', '"c"') + torn)
    rows, bad = read_points(path)
    assert sorted(rows) == ["a", "c"] and bad == 2


# --- sweeps through the command line ------------------------------------------------------


def test_grid_sweep_writes_the_table_points_and_plots(tmp_path, capsys):
    """Ke from 2e4 to 1e5 N/m against the receding wall: the paper's controller tracks Fr
    within 5 % at every stiffness (steady state), and the first-contact peak grows with Ke."""
    out = tmp_path / "sweep"
    arguments = ["sweep", "paper_moving_wall", "--set", "duration=2"]
    arguments += ["--grid", "wall.stiffness=logspace:2e4:1e5:4", "--workers", "2"]
    assert main([*arguments, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "4 points, 4 finished, 0 failed" in printed and "at 0 of 4 points" in printed
    names = {p.name for p in out.iterdir()}
    assert {"sweep.json", "points.jsonl", "table.csv", "summary.txt"} <= names
    plot = out / "summary_wall.stiffness.png"
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [n for n in names if n.endswith(".tmp")]
    assert marker_entries(out) == names - {MARKER}  # the result marker lists every file
    assert (out / "summary.txt").read_text() in printed
    assert len(_lines(out)) == 4
    rows = _table(out)
    assert [int(r["index"]) for r in rows] == [0, 1, 2, 3]
    stiffness = [float(r["wall.stiffness"]) for r in rows]
    assert stiffness == pytest.approx([2e4, 2e4 * 5 ** (1 / 3), 2e4 * 5 ** (2 / 3), 1e5])
    for row in rows:
        assert row["failed"] == "false" and row["failure"] == ""
        for name in ("peak_force", "steady_state_force_error", "rms_force_error", "wall_time"):
            assert math.isfinite(float(row[name]))
        assert row["contact_losses"] == "0" and float(row["settling_first_contact_0"]) < 1.0
        assert float(row["steady_state_force_error"]) < 0.05 * FORCE_REFERENCE
    peaks = [float(r["peak_force"]) for r in rows]
    assert peaks == sorted(peaks) and peaks[-1] > peaks[0] + 5  # a stiffer wall hits harder
    definition = json.loads((out / "sweep.json").read_text())["definition"]
    assert definition["points"] == 4 and definition["grid"][0]["key"] == "wall.stiffness"


def test_resume_recomputes_only_the_missing_points(tmp_path, capsys):
    out = tmp_path / "sweep"
    arguments = ["sweep", *SHORT, "--grid", "wall.stiffness=1e4,3e4,1e5", "--out", str(out)]
    assert main(arguments) == 0
    capsys.readouterr()
    lines = _lines(out)
    first_rows = {json.loads(line)["index"]: json.loads(line) for line in lines}
    # Lose one finished point and tear another (a kill in the middle of its write).
    kept, lost, torn = lines
    (out / "points.jsonl").write_text(kept + torn[: len(torn) // 2])
    assert main(arguments) == 0
    progress = capsys.readouterr().err  # progress lines go to stderr
    assert "ignored 1 unreadable line" in progress
    assert "skipped 1 finished points of 3; 2 to run" in progress
    resumed = _lines(out)
    assert len(resumed) == 3 and resumed[0] == kept  # the finished point was not recomputed
    for line in resumed[1:]:
        row = json.loads(line)
        assert _same_metrics(row["metrics"], first_rows[row["index"]]["metrics"])
    assert [int(r["index"]) for r in _table(out)] == [0, 1, 2]
    # Nothing left to run: the table is rebuilt from the record alone.
    assert main(arguments) == 0
    assert "skipped 3 finished points of 3; 0 to run" in capsys.readouterr().err
    assert _lines(out) == resumed


def test_another_sweep_in_the_same_folder_needs_force(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", *SHORT, "--grid", "wall.stiffness=2e4", "--out", str(out)]) == 0
    capsys.readouterr()
    other = ["sweep", *SHORT, "--grid", "wall.stiffness=3e4", "--out", str(out)]
    assert main(other) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "--force" in error and "grid" in error
    assert json.loads(_lines(out)[0])["values"] == {"wall.stiffness": 2e4}
    assert main([*other, "--force"]) == 0
    assert "resuming" not in capsys.readouterr().err
    assert [json.loads(line)["values"] for line in _lines(out)] == [{"wall.stiffness": 3e4}]
    # A folder that is not a sweep's is not written into.
    stranger = tmp_path / "results"
    stranger.mkdir()
    (stranger / "metrics.json").write_text("{}")
    assert main(["sweep", *SHORT, "--grid", "wall.stiffness=2e4", "--out", str(stranger)]) == 2
    assert "holds files this tool did not write (metrics.json)" in capsys.readouterr().err
    assert sorted(p.name for p in stranger.iterdir()) == ["metrics.json"]


@pytest.mark.parametrize("how", ["SIGINT", "SIGKILL"])
def test_a_killed_sweep_resumes_without_recomputing_finished_points(tmp_path, capsys, how):
    """Start a sweep in another process; stop it after its first finished point (Ctrl-C, or
    SIGKILL of the whole process group); the same command again only runs the rest."""
    out = tmp_path / "sweep"
    arguments = ["sweep", *SHORT, "--grid", "wall.stiffness=1e4,2e4,5e4,1e5", "--workers", "1"]
    arguments += ["--out", str(out)]
    process = _start_sweep(arguments)
    _wait_for_a_point(process, out / "points.jsonl")
    if how == "SIGINT":
        process.send_signal(signal.SIGINT)
    else:
        os.killpg(process.pid, signal.SIGKILL)
    _, stderr = process.communicate(timeout=60)
    if how == "SIGINT":
        assert process.returncode == 130
        (message,) = _messages(stderr)
        assert "run the same command again to resume" in message and "Traceback" not in stderr
    else:
        assert process.returncode == -signal.SIGKILL
    before = _lines(out)
    finished = [line for line in before if line.endswith("\n")]
    # At least the point waited for; not all four: the kill follows the first line within
    # one 10 ms poll, and each further point is a 1.5 s simulation (over 1 s of wall time).
    assert 1 <= len(finished) < 4
    assert main(arguments) == 0
    assert f"skipped {len(finished)} finished points of 4" in capsys.readouterr().err
    after = _lines(out)
    assert after[: len(finished)] == finished and len(after) == 4
    assert sorted(json.loads(line)["index"] for line in after) == [0, 1, 2, 3]
    assert [int(r["index"]) for r in _table(out)] == [0, 1, 2, 3]


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
def test_a_dead_worker_stops_the_sweep_with_one_line_and_keeps_the_points(tmp_path, capsys):
    out = tmp_path / "sweep"
    arguments = ["sweep", *SHORT, "--grid", "wall.stiffness=1e4,2e4,5e4,1e5", "--workers", "1"]
    arguments += ["--out", str(out)]
    process = _start_sweep(arguments)
    _wait_for_a_point(process, out / "points.jsonl")
    children = open(f"/proc/{process.pid}/task/{process.pid}/children").read().split()
    workers = [
        int(child)
        for child in children
        if "spawn_main" in (cmdline := open(f"/proc/{child}/cmdline").read())
        and "resource_tracker" not in cmdline
    ]
    assert len(workers) == 1
    os.kill(workers[0], signal.SIGKILL)  # as the kernel's out-of-memory killer would
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1
    lines = _messages(stderr)
    assert len(lines) == 1 and "worker process died" in lines[0] and "resume" in lines[0]
    finished = _lines(out)
    assert main(arguments) == 0
    assert f"skipped {len(finished)} finished points of 4" in capsys.readouterr().err
    assert _lines(out)[: len(finished)] == finished and len(_lines(out)) == 4


def test_dask_engine_gives_the_local_table(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    grid = ["--grid", "wall.stiffness=2e4,1e5"]
    local = tmp_path / "local"
    assert main(["sweep", *SHORT, *grid, "--out", str(local)]) == 0
    # An existing scheduler (here an in-process LocalCluster, one worker thread).
    on_cluster = tmp_path / "dask"
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        arguments = ["--engine", "dask", "--scheduler", cluster.scheduler_address]
        assert main(["sweep", *SHORT, *grid, *arguments, "--out", str(on_cluster)]) == 0
    # No scheduler: the sweep starts its own LocalCluster of --workers processes.
    own_cluster = tmp_path / "dask_local"
    arguments = ["--engine", "dask", "--workers", "1"]
    assert main(["sweep", *SHORT, *grid, *arguments, "--out", str(own_cluster)]) == 0
    assert "2 points, 2 finished, 0 failed" in capsys.readouterr().out
    expected = _table(local)
    for folder in (on_cluster, own_cluster):
        rows = _table(folder)
        assert [r["point_id"] for r in rows] == [r["point_id"] for r in expected]
        for row, reference in zip(rows, expected, strict=True):
            assert row["failed"] == reference["failed"] == "false"
            assert _same_metrics(_numeric(row), _numeric(reference))
