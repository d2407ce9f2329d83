"""Results are never half-written: atomic folders, no silent overwrite, kills."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from admittance.diagrams.app.cli import main
from admittance.diagrams.results.folder import (
    INCOMPLETE_MARK,
    OutputExistsError,
    atomic_output_dir,
    write_marker,
)


def _previous_result(folder):
    """An earlier result of the tool: its file and the marker that lists it."""
    folder.mkdir()
    (folder / "metrics.json").write_text('{"previous": true}\n')
    write_marker(folder, ["metrics.json"])


def test_existing_result_is_not_overwritten_without_force(tmp_path, capsys):
    out = tmp_path / "run"
    _previous_result(out)
    args = ["simulate", "--set", "duration=0.2", "--set", "sensor.kind=ideal", "--out", str(out)]
    assert main(args) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "--force" in error and str(out) in error
    assert json.loads((out / "metrics.json").read_text()) == {"previous": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing staged
    # Asked to, it replaces the folder as a whole.
    assert main([*args, "--force"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert "previous" not in metrics and metrics["failed"] is False
    assert not (out / INCOMPLETE_MARK).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_error_inside_the_block_leaves_the_previous_result(tmp_path):
    out = tmp_path / "run"
    _previous_result(out)
    with pytest.raises(RuntimeError, match="disk full"):
        with atomic_output_dir(out) as staging:
            (staging / "metrics.json").write_text("{}")
            raise RuntimeError("disk full")
    assert json.loads((out / "metrics.json").read_text()) == {"previous": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    with pytest.raises(OutputExistsError, match="--force"):
        with atomic_output_dir(out, overwrite=False):
            pass


def test_a_killed_writer_leaves_the_previous_result_and_a_marked_staging_folder(tmp_path):
    """SIGKILL in the middle of writing: `run/` is untouched; the staging folder says it is
    incomplete; the next write into the same place removes it."""
    out = tmp_path / "run"
    _previous_result(out)
    script = textwrap.dedent(
        f"""
        import os, signal
        from admittance.diagrams.results.folder import atomic_output_dir
        with atomic_output_dir({str(out)!r}) as staging:
            (staging / "timeseries.csv").write_text("time,x\\n0,0.2\\n")
            os.kill(os.getpid(), signal.SIGKILL)
        """
    )
    process = subprocess.run([sys.executable, "-c", script], check=False)
    assert process.returncode == -signal.SIGKILL
    assert json.loads((out / "metrics.json").read_text()) == {"previous": True}
    staged = [p for p in tmp_path.iterdir() if p.name != "run"]
    assert len(staged) == 1 and staged[0].name.startswith(".run.incomplete.")
    assert (staged[0] / INCOMPLETE_MARK).is_file()
    # The next run cleans the dead process's staging folder up and writes its result.
    with atomic_output_dir(out) as staging:
        (staging / "metrics.json").write_text('{"next": true}\n')
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert json.loads((out / "metrics.json").read_text()) == {"next": True}


# The command line, with the simulator's monitor wrapped to write a marker file once the
# simulated time passes 0.5 s: the signal that the run is under way.
_MARKED_MAIN = textwrap.dedent(
    """
    import pathlib, sys
    from pydrake.systems.analysis import Simulator
    from admittance.diagrams.app.cli import main

    marker = pathlib.Path(sys.argv[1])
    set_monitor = Simulator.set_monitor

    def marked_set_monitor(simulator, monitor):
        def marked(root_context):
            if root_context.get_time() > 0.5 and not marker.exists():
                marker.write_text(str(root_context.get_time()))
            return monitor(root_context)

        return set_monitor(simulator, marked)

    Simulator.set_monitor = marked_set_monitor
    sys.exit(main(sys.argv[2:]))
    """
)


def test_a_killed_simulation_writes_nothing(tmp_path):
    """Killed mid-simulation (before any write), the command leaves no result folder."""
    out = tmp_path / "results" / "run"
    marker = tmp_path / "simulating"
    command = [sys.executable, "-c", _MARKED_MAIN, str(marker), "simulate", "paper_moving_wall"]
    command += ["--set", "duration=300", "--out", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        # 0.5 s of the FlexiForce loop is under way; the other 299.5 s take minutes.
        deadline = time.monotonic() + 120.0
        while not marker.exists():
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline, "the simulation did not start in 120 s"
            time.sleep(0.01)
    finally:
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL  # killed, not finished
    assert float(marker.read_text()) > 0.5
    assert not (tmp_path / "results").exists()
