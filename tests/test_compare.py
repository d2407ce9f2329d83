"""`admittance compare`: every controller on the paper's scenarios; the paper's law keeps
the force at Fr where the PID alone and eq. 6 with a 1 mm wall error do not."""

from __future__ import annotations

import csv

import pytest

from admittance.diagrams.app.cli import main
from admittance.diagrams.results.folder import MARKER, marker_entries


def _table(path):
    with (path / "table.csv").open() as handle:
        return {row["controller"]: row for row in csv.DictReader(handle)}


@pytest.mark.parametrize(
    "scenario, overrides, unsafe",
    [
        # The plan is 5 cm behind the wall: the PID alone presses ~56 N; eq. 6 from a wall
        # estimate 1 mm too deep leaves the receding wall.
        ("paper_moving_wall", [], {"pid_only": "excessive force"}),
        # 20 s: 5 s past the stiffness step. Eq. 6 pushes toward Fr + Ke * 1 mm; the PID alone
        # on Xd = the wall surface presses nothing.
        ("paper_stiffness_step", ["duration=20"], {"fixed_reference": "excessive force"}),
    ],
)
def test_compare_tables_every_controller(tmp_path, capsys, scenario, overrides, unsafe):
    out = tmp_path / "compare"
    sets = [item for key in overrides for item in ("--set", key)]
    assert main(["compare", scenario, *sets, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    table = _table(out)
    assert set(table) == {
        "optimal_admittance",
        "pid_only",
        "fixed_reference",
        "classical_admittance",
        "adaptive_impedance",
    }
    for kind in table:
        assert kind in printed
    optimal = table["optimal_admittance"]
    assert optimal["verdict"] == "tracks Fr"
    assert float(optimal["steady_error"]) < 0.05 * 5.0
    for kind, verdict in unsafe.items():
        assert table[kind]["verdict"] == verdict
    for kind in ("pid_only", "fixed_reference"):
        assert table[kind]["verdict"] != "tracks Fr"
    assert (out / "force.png").stat().st_size > 10_000
    assert (out / "table.txt").read_text().count("\n") >= 6
    assert marker_entries(out) == {p.name for p in out.iterdir()} - {MARKER}


def test_compare_rejects_an_unknown_controller(tmp_path, capsys):
    out = tmp_path / "compare"
    code = main(["compare", "--controllers", "optimal_admittance,pd", "--out", str(out)])
    assert code == 2
    assert "--controllers: 'pd' is not a controller" in capsys.readouterr().err
    assert not out.exists()


def test_a_failed_run_is_a_row_with_its_reason():
    from admittance.diagrams.robots.planar_arm.compare import ControllerRun, format_table, table_row

    failed = {"failed": True, "failure": "the integrator failed at t = 1.2 s: step too small"}
    ok = {"peak_force": 5.2, "final_mean_force": 5.01, "events": []}
    runs = [
        ControllerRun("classical_admittance", table_row("classical_admittance", failed, 5.0)),
        ControllerRun("optimal_admittance", table_row("optimal_admittance", ok, 5.0)),
    ]
    assert runs[0].row["verdict"] == "failed"
    assert runs[1].row["verdict"] == "tracks Fr"
    text = format_table(runs)
    assert "classical_admittance: the integrator failed at t = 1.2 s" in text
