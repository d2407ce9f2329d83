"""The result writer never deletes what it did not write: the result marker, --force on a
folder that holds the user's files, a folder that changes during the run, permissions."""

import json
import subprocess
import sys
import textwrap

import pytest

from admittance.diagrams.app.bench_report import check_bench_file
from admittance.diagrams.app.cli import main
from admittance.diagrams.results.folder import (
    MARKER,
    REPLAY_MARK,
    OutputExistsError,
    atomic_output_dir,
    check_replay_file,
    marker_entries,
)

SIMULATE = ["simulate", "-q", "--set", "duration=0.2"]
SWEEP = ["sweep", "-q", "--set", "duration=0.2", "--grid", "wall.stiffness=2e4", "--workers", "1"]
NOTE = "the user's own notes\n"


def _one_line(capsys, *texts):
    """One line on stderr holding `texts`; nothing on stdout (refused before any run)."""
    captured = capsys.readouterr()
    error = captured.err.strip()
    assert error.count("\n") == 0 and "Traceback" not in error, error
    assert captured.out == ""
    for text in texts:
        assert text in error, error
    return error


def _user_folder(path):
    path.mkdir()
    (path / "notes.txt").write_text(NOTE)
    return path


def test_force_onto_a_folder_the_tool_did_not_write_is_refused(tmp_path, capsys):
    out = _user_folder(tmp_path / "documents")
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 2
    _one_line(capsys, f"--out {out}: holds files this tool did not write (notes.txt)")
    assert (out / "notes.txt").read_text() == NOTE
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["documents"]  # nothing staged


def test_force_replaces_an_earlier_result_and_refuses_one_the_user_added_to(tmp_path, capsys):
    out = tmp_path / "run"
    assert main([*SIMULATE, "--out", str(out)]) == 0
    first = json.loads((out / MARKER).read_text())
    assert first["tool"] == "admittance" and first["version"]
    assert first["command"] == f"admittance simulate -q --set duration=0.2 --out {out}"
    assert set(first["entries"]) == {p.name for p in out.iterdir()} - {MARKER}
    assert "metrics.json" in first["entries"] and MARKER not in first["entries"]
    capsys.readouterr()
    # Without --force an earlier result is kept; with it, replaced.
    assert main([*SIMULATE, "--out", str(out)]) == 2
    _one_line(capsys, f"--out {out}: holds an earlier result; pass --force")
    (out / "metrics.json").write_text("{}")
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 0
    assert json.loads((out / "metrics.json").read_text())["failed"] is False
    assert marker_entries(out) == {p.name for p in out.iterdir()} - {MARKER}
    capsys.readouterr()
    # A file the user put into the result: the folder is no longer the tool's alone.
    (out / "notes.txt").write_text(NOTE)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 2
    _one_line(capsys, "holds files this tool did not write (notes.txt); choose another folder")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_a_marker_that_is_not_the_tools_does_not_make_a_folder_replaceable(tmp_path, capsys):
    out = _user_folder(tmp_path / "documents")
    (out / MARKER).write_text('{"tool": "other", "entries": ["notes.txt"]}')
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 2
    _one_line(capsys, f"did not write ({MARKER}, notes.txt)")
    (out / MARKER).write_text('{"tool": "admittance", "entries": ["../notes.txt", "."]}')
    assert main([*SWEEP, "--out", str(out), "--force"]) == 2
    _one_line(capsys, "did not write (notes.txt)")
    (out / MARKER).write_text("not json")
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 2
    _one_line(capsys, "did not write")
    assert (out / "notes.txt").read_text() == NOTE


def test_an_empty_folder_is_used(tmp_path, capsys):
    out = tmp_path / "empty"
    out.mkdir()
    assert main([*SIMULATE, "--out", str(out)]) == 0
    assert "metrics.json" in marker_entries(out)


def test_a_folder_that_changes_during_the_run_is_left_as_it_is(tmp_path):
    """The user puts a file into the folder while the result is being written: it is not
    replaced; the new result is kept beside it, and the error says where."""
    out = tmp_path / "run"
    with atomic_output_dir(out) as staging:  # an earlier result
        (staging / "metrics.json").write_text('{"earlier": true}')
    with pytest.raises(OutputExistsError) as raised:
        with atomic_output_dir(out, overwrite=True) as staging:
            (staging / "metrics.json").write_text('{"new": true}')
            (out / "notes.txt").write_text(NOTE)
    message = str(raised.value)
    assert "changed during the run" in message and "(notes.txt)" in message
    assert json.loads((out / "metrics.json").read_text()) == {"earlier": True}
    assert (out / "notes.txt").read_text() == NOTE
    (kept,) = [p for p in tmp_path.iterdir() if p.name != "run"]
    assert kept.name.startswith("run.new-") and f"the new result is in {kept}/" in message
    assert json.loads((kept / "metrics.json").read_text()) == {"new": True}
    assert marker_entries(kept) == {"metrics.json"}
    # A folder made during the run where there was none is not replaced either.
    fresh = tmp_path / "fresh"
    with pytest.raises(OutputExistsError, match="changed during the run"):
        with atomic_output_dir(fresh) as staging:
            (staging / "metrics.json").write_text("{}")
            _user_folder(fresh)
    assert [p.name for p in fresh.iterdir()] == ["notes.txt"]


def test_a_file_put_into_the_folder_during_a_run_keeps_both(tmp_path, capsys, monkeypatch):
    """The command line: the folder, checked before the run, gets the user's file while
    the simulation runs; the run's result is kept beside it, and the line says where."""
    import admittance.diagrams.run.simulation as simulation  # the run the command calls

    out = tmp_path / "run"
    assert main([*SIMULATE, "--out", str(out)]) == 0
    simulate = simulation.simulate

    def run_while_the_user_writes(scenario, **options):
        (out / "notes.txt").write_text(NOTE)
        return simulate(scenario, **options)

    monkeypatch.setattr(simulation, "simulate", run_while_the_user_writes)
    capsys.readouterr()
    assert main([*SIMULATE, "--out", str(out), "--force"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "Traceback" not in error
    (kept,) = [p for p in tmp_path.iterdir() if p.name != "run"]
    assert error == (
        f"admittance: error: --out {out}: changed during the run and now holds files this "
        f"tool did not write (notes.txt); left as it is, the new result is in {kept}/"
    )
    assert (out / "notes.txt").read_text() == NOTE and "metrics.json" in marker_entries(out)
    assert marker_entries(kept) == {p.name for p in kept.iterdir()} - {MARKER}
    assert json.loads((kept / "metrics.json").read_text())["failed"] is False


# A subprocess with the given umask runs the command line.
_WITH_UMASK = textwrap.dedent(
    """
    import os, sys
    os.umask(int(sys.argv[1], 8))
    from admittance.diagrams.app.cli import main
    sys.exit(main(sys.argv[2:]))
    """
)


@pytest.mark.parametrize("umask, folder, file", [("022", 0o755, 0o644), ("077", 0o700, 0o600)])
def test_result_permissions_follow_the_umask(tmp_path, umask, folder, file):
    out = tmp_path / "run"
    command = [sys.executable, "-c", _WITH_UMASK, umask, "-q", *SIMULATE, "--out", str(out)]
    subprocess.run(command, check=True, capture_output=True)
    assert out.stat().st_mode & 0o777 == folder
    files = list(out.iterdir())
    assert MARKER in [p.name for p in files] and len(files) == 7
    assert {p.name: p.stat().st_mode & 0o777 for p in files} == {p.name: file for p in files}


def test_sweep_refuses_a_folder_the_tool_did_not_write(tmp_path, capsys):
    out = _user_folder(tmp_path / "documents")
    for force in ([], ["--force"]):
        assert main([*SWEEP, "--out", str(out), *force]) == 2
        _one_line(capsys, f"--out {out}: holds files this tool did not write (notes.txt)")
        assert [p.name for p in out.iterdir()] == ["notes.txt"]  # not even a lock file
        assert (out / "notes.txt").read_text() == NOTE


def test_sweep_resumes_only_its_own_folder_and_force_replaces_another_result(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main([*SWEEP, "--out", str(out)]) == 0
    assert marker_entries(out) == {p.name for p in out.iterdir()} - {MARKER}
    capsys.readouterr()
    # The user's file in the sweep's folder: no resume, no start over.
    (out / "notes.txt").write_text(NOTE)
    for force in ([], ["--force"]):
        assert main([*SWEEP, "--out", str(out), *force]) == 2
        _one_line(capsys, "did not write (notes.txt)")
    assert (out / "notes.txt").read_text() == NOTE
    # A result folder of `simulate` becomes a sweep's with --force (its files go).
    run = tmp_path / "run"
    assert main([*SIMULATE, "--out", str(run)]) == 0
    capsys.readouterr()
    assert main([*SWEEP, "--out", str(run)]) == 2
    _one_line(capsys, "not a sweep (no sweep.json); pass --force")
    assert main([*SWEEP, "--out", str(run), "--force"]) == 0
    names = {p.name for p in run.iterdir()}
    assert "metrics.json" not in names and "sweep.json" in names
    assert marker_entries(run) == names - {MARKER}


def test_single_files_replace_only_what_the_tool_wrote(tmp_path, capsys):
    """--meshcat-html FILE and bench --json FILE: a file of the user's is refused before
    the run; the tool's own earlier file is replaced (the replay with --force)."""
    mine = tmp_path / "mine.html"
    mine.write_text(NOTE)
    assert main([*SIMULATE, "--out", str(tmp_path / "run"), "--meshcat-html", str(mine)]) == 2
    _one_line(capsys, f"--meshcat-html {mine}: exists and is not a Meshcat replay this tool")
    assert main(["bench", "-q", "--set", "duration=0.2", "--repeat", "1", "--json", str(mine)]) == 2
    _one_line(capsys, f"--json {mine}: exists and is not a bench report this tool wrote")
    assert mine.read_text() == NOTE
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.html"]
    replay = tmp_path / "replay.html"
    replay.write_text(f"<html></html>\n{REPLAY_MARK}\n")
    check_replay_file(replay, force=True)
    with pytest.raises(OutputExistsError, match="this tool wrote\\); pass --force"):
        check_replay_file(replay, force=False)
    report = tmp_path / "bench.json"
    report.write_text(
        json.dumps(
            {
                "scenario": {"name": "x"},
                "closed_loop": {},
                "python": {"callbacks": {}},
                "ratio_to_floor": 5,
            }
        )
    )
    check_bench_file(report)


def test_sweep_checks_its_folder_again_once_locked(tmp_path, capsys, monkeypatch):
    """The folder gets the user's file between the first check and the lock: refused
    there, and the lock file the sweep made is taken away again."""
    import admittance.diagrams.app.sweep.run as sweep_run

    out = _user_folder(tmp_path / "documents")
    monkeypatch.setattr(sweep_run, "check_folder", lambda out_dir, force: None)
    assert main([*SWEEP, "--out", str(out), "--force"]) == 2
    _one_line(capsys, f"--out {out}: holds files this tool did not write (notes.txt)")
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_the_replay_is_marked_and_replaced_only_with_force(tmp_path, capsys):
    replay = tmp_path / "replay.html"
    arguments = [*SIMULATE, "--meshcat-html", str(replay)]
    assert main([*arguments, "--out", str(tmp_path / "one")]) == 0
    assert replay.read_text().rstrip().endswith(REPLAY_MARK)
    capsys.readouterr()
    assert main([*arguments, "--out", str(tmp_path / "two")]) == 2
    _one_line(capsys, f"--meshcat-html {replay}: exists (a Meshcat replay this tool wrote); pass")
    assert main([*arguments, "--out", str(tmp_path / "two"), "--force"]) == 0
    assert replay.read_text().count(REPLAY_MARK) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one", "replay.html", "two"]
