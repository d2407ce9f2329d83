"""The `admittance` command line: the files it writes and its one-line errors."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest

from admittance.diagrams.app.cli import main
from admittance.diagrams.results.folder import MARKER, marker_entries

REQUIRED_COLUMNS = ["time", "x", "y", "theta", "xr", "force", "force_measured", "force_reference"]
REQUIRED_METRICS = [
    "peak_force",
    "steady_state_force_error",
    "rms_force_error",
    "first_contact_time",
    "wall_time",
    "real_time_factor",
]


def test_simulate_writes_timeseries_metrics_and_figures(tmp_path, capsys):
    out = tmp_path / "run"
    status = main(["simulate", "paper_moving_wall", "--set", "duration=1.0", "--out", str(out)])
    assert status == 0
    names = {p.name for p in out.iterdir()}
    assert {"timeseries.csv", "metrics.json", "scenario.yaml"} <= names
    assert {"fig5_errors.png", "fig6_reference.png", "fig7_force.png"} <= names
    assert marker_entries(out) == names - {MARKER}  # the result marker lists every file
    with open(out / "timeseries.csv") as file:
        rows = list(csv.DictReader(file))
    assert set(REQUIRED_COLUMNS) <= set(rows[0])
    assert float(rows[-1]["time"]) == pytest.approx(1.0)
    assert float(rows[-1]["force"]) > 0  # pressing the wall
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(REQUIRED_METRICS) <= set(metrics)
    assert metrics["peak_force"] == pytest.approx(max(float(r["force"]) for r in rows))
    assert "peak force" in capsys.readouterr().out
    # No staging folders are left next to the result.
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


@pytest.mark.parametrize(
    "arguments, key",
    [
        (["simulate", "--set", "wall.stiffnes=1e4"], "wall.stiffnes"),
        (["simulate", "--set", "admittance.gamma=-1"], "admittance.gamma"),
        (["simulate", "no_such_scenario"], "scenario"),
        (["simulate", "--set", "sensor.kind=piezo"], "sensor.kind"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, arguments, key):
    out = tmp_path / "run"
    completed = subprocess.run(
        [sys.executable, "-m", "admittance.diagrams.app.cli", *arguments, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 2
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in completed.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bench_refuses_an_unreadable_before_file_with_one_line(tmp_path):
    # Checked before anything runs: exit status 2, one line naming the file.
    missing = tmp_path / "before.json"
    completed = subprocess.run(
        [sys.executable, "-m", "admittance.diagrams.app.cli", "bench", "--before", str(missing)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 2
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and "--before" in lines[0] and "before.json" in lines[0]
    assert "Traceback" not in completed.stderr and completed.stdout == ""


def test_simulate_into_a_pipe_that_closes_after_one_line_exits_0_quietly(tmp_path):
    # `admittance simulate | head -1`: the reader goes away after the first line, while the
    # summary is still being printed (unbuffered, as PYTHONUNBUFFERED=1 makes it). That is
    # not a failure of the run: exit status 0, no traceback, the results written.
    out = tmp_path / "run"
    command = [sys.executable, "-u", "-m", "admittance.diagrams.app.cli", "simulate"]
    command += ["paper_moving_wall", "--set", "duration=0.3", "--quiet", "--out", str(out)]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as process:
        first = process.stdout.readline()
        process.stdout.close()  # as `head -1` does after its line
        status = process.wait(timeout=120)
        errors = process.stderr.read()
    assert first.startswith("scenario paper_moving_wall")
    assert status == 0, errors
    assert "Traceback" not in errors and "Error" not in errors
    assert (out / "metrics.json").is_file()
