"""What a hostile new user gives the command line ends in one line and status 2.

Each class of bad input found by trying: a malformed file that a scenario names (a broken
or non-URDF arm, a directory), a scenario file that is empty, a list, not UTF-8 or gives a
key twice; an integer beyond what Drake or the machine takes; a rate or speed that no arm
can follow (the integrator would crawl after it); a list entry with a field left out; an
output place that cannot be written. Each ends before anything runs, with one line on
stderr naming the key or flag, and nothing written.
"""

from __future__ import annotations

import os

import pytest

from admittance.diagrams.app.cli import main
from admittance.urdf import PLANAR_ARM_URDF

URDF = PLANAR_ARM_URDF.read_text()


def _without(text: str, start: str, end: str) -> str:
    """`text` without the first block from `start` to the end of `end` after it."""
    first = text.index(start)
    return text[:first] + text[text.index(end, first) + len(end) :]


# name -> (file contents, what the message says)
SCENARIO_FILES = {
    "empty": (b"# only a comment\n", "holds no scenario keys"),
    "a list": (b"- duration\n- 2\n", "must hold a mapping of scenario keys, got a list"),
    "a scalar": (b"42\n", "must hold a mapping of scenario keys, got a number"),
    "not UTF-8": (b"duration: 2\nname: caf\xe9\n", "is not UTF-8 text (byte 0xe9 at offset 21)"),
    "a key twice": (b"duration: 2\nseed: 1\nduration: 3\n", "line 3: key 'duration' is given"),
    "an alias": (b"wall:\n  position: &x 0.2\ntrajectory:\n  frequency: *x\n", "aliases"),
}

# name -> (URDF text, the key the message names, what it says)
URDF_FILES = {
    "truncated": (URDF[: len(URDF) // 2], "arm.urdf", "is not a URDF that Drake reads"),
    "not a robot": ("<html><body>arm</body></html>\n", "arm.urdf", "does not contain a robot"),
    "unactuated": (
        _without(
            _without(
                _without(URDF, '<transmission name="joint1', "</transmission>"),
                '<transmission name="joint2',
                "</transmission>",
            ),
            '<transmission name="joint3',
            "</transmission>",
        ),
        "arm.urdf",
        "got 3 joint velocities and 0 actuators",
    ),
    "floating": (
        _without(URDF, '<joint name="base_weld"', "</joint>"),
        "arm.urdf",
        "got 9 joint velocities and 3 actuators",
    ),
    "no fingertip": (
        _without(URDF, '<frame name="fingertip"', "/>"),
        "arm.fingertip_frame",
        "no frame named 'fingertip'",
    ),
}


def _one_line(capsys, key: str, text: str) -> None:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"admittance: error: {key}") and text in lines[0], lines[0]
    assert "Traceback" not in captured.err and captured.out == ""


@pytest.mark.parametrize("name", SCENARIO_FILES)
def test_a_scenario_file_that_is_not_a_mapping_of_keys(tmp_path, capsys, name):
    contents, text = SCENARIO_FILES[name]
    (tmp_path / "mine.yaml").write_bytes(contents)
    out = tmp_path / "run"
    assert main(["simulate", str(tmp_path / "mine.yaml"), "--out", str(out)]) == 2
    _one_line(capsys, "scenario: ", text)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.yaml"]


@pytest.mark.parametrize("name", URDF_FILES)
def test_a_urdf_file_the_loop_cannot_use(tmp_path, capsys, name):
    urdf, key, text = URDF_FILES[name]
    (tmp_path / "arm.urdf").write_text(urdf)
    (tmp_path / "mine.yaml").write_text("duration: 0.2\narm:\n  urdf: arm.urdf\n")
    out = tmp_path / "run"
    assert main(["simulate", str(tmp_path / "mine.yaml"), "--out", str(out)]) == 2
    _one_line(capsys, key, text)
    assert not out.exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file whatever its permissions")
def test_an_unreadable_urdf(tmp_path, capsys):
    (tmp_path / "arm.urdf").write_text(URDF)
    (tmp_path / "arm.urdf").chmod(0)
    out = tmp_path / "run"
    arguments = ["simulate", "--set", f"arm.urdf={tmp_path / 'arm.urdf'}", "--out", str(out)]
    assert main(arguments) == 2
    _one_line(capsys, "arm.urdf", "cannot be read: Permission denied")


@pytest.mark.parametrize(
    "arguments, key, text",
    [
        # Drake's RandomGenerator keeps 32 bits: 2**32 would silently repeat seed 0, and a
        # seed past 2**64 was a TypeError from inside Drake.
        (["simulate", "--set", "seed=4294967296"], "seed", "in [0, 4294967295]"),
        (["simulate", "--set", f"seed={2**64}"], "seed", "in [0, 4294967295]"),
        (["simulate", "--set", "duration=1" + "0" * 400], "duration", "got inf"),
        (["compare", "--workers", "0"], "--workers 0", "must be an integer in [1, "),
        (["compare", "--workers", str(10**20)], "--workers", "must be an integer in [1, "),
        (["bench", "--repeat", "1000000000"], "--repeat", "in [1, 100]"),
        (["sweep", "--random", "seed=randint:0:9", "--samples", str(10**12)], "--samples", ""),
        (
            ["sweep", "--grid", "wall.stiffness=linspace:1e4:2e4:1000000000000"],
            "--grid",
            "N must be an integer in [1, 100000]",
        ),
        (
            ["sweep"]
            + ["--grid", "wall.stiffness=linspace:1e4:2e4:1000"]
            + ["--grid", "wall.position=linspace:0.19:0.2:1000"],
            "sweep: ",
            "= 1000000 points; at most 100000",
        ),
    ],
    ids=[
        "seed-2**32",
        "seed-2**64",
        "huge-integer",
        "workers-0",
        "workers-huge",
        "repeat",
        "samples",
        "grid-size",
        "sweep-size",
    ],
)
def test_an_integer_beyond_what_is_taken(tmp_path, capsys, arguments, key, text):
    out = tmp_path / "run"
    command, *rest = arguments
    extra = ["--json", str(out)] if command == "bench" else ["--out", str(out)]
    assert main([command, "paper_moving_wall", *rest, *extra]) == 2
    _one_line(capsys, key, text)
    assert not out.exists()


@pytest.mark.parametrize(
    "override, key, text",
    [
        # 20 Hz on the paper's 25 mm: 3 m/s at the fingertip; the integrator took minutes.
        ("trajectory.frequency=20", "trajectory.frequency", "beyond the URDF's velocity limits"),
        ("wall.velocity=-0.6", "wall.velocity", "beyond the URDF's velocity limits"),
        ("simulator.target_realtime_rate=1e-6", "simulator.target_realtime_rate", "0 (as fast"),
        ("simulator.max_step_size=1e-12", "simulator.max_step_size", ">= 1e-6 s"),
        ("simulator.accuracy=1e-300", "simulator.accuracy", "in [1e-8, 0.1]"),
        ("admittance.period=1e-12", "admittance.period", "or >= 1e-5 s"),
        ("logging.period=1e-12", "logging.period", "0 (every step) or in [1e-5, 0.1] s"),
    ],
)
def test_a_rate_or_speed_that_no_arm_can_follow(tmp_path, capsys, override, key, text):
    out = tmp_path / "run"
    arguments = ["simulate", "--set", "duration=0.5", "--set", override, "--out", str(out)]
    assert main(arguments) == 2
    _one_line(capsys, key, text)
    assert not out.exists()


@pytest.mark.parametrize(
    "override, key",
    [
        ("faults=[{kind: sensor_nan}]", "faults[0].start: missing"),
        ("faults=[{kind: sensor_nan, start: 0.2}]", "faults[0].end: missing"),
        ("faults=[{kind: wall_retract, start: 0.2, end: 0.3}]", "faults[0].value: missing"),
        ("faults=[{start: 0.2, end: 0.3, value: 1}]", "faults[0].kind: missing"),
        ("wall.stiffness_steps=[{time: 0.2}]", "wall.stiffness_steps[0].stiffness: missing"),
        ("wall.stiffness_steps=[{stiffness: 1e5}]", "wall.stiffness_steps[0].time: missing"),
    ],
)
def test_a_list_entry_with_a_field_left_out(tmp_path, capsys, override, key):
    out = tmp_path / "run"
    assert main(["simulate", "--set", override, "--out", str(out)]) == 2
    _one_line(capsys, key, "needs")
    assert not out.exists()


@pytest.mark.parametrize(
    "arguments, key, text",
    [
        (["simulate", "--set", "name=../elsewhere"], "name", "a file name"),
        (["simulate", "--out", "."], "--out .", "is the current folder"),
        (["simulate", "--out", "note.txt/run"], "--out note.txt/run", "is not a folder"),
        (["simulate", "--meshcat-html", "note.txt/replay.html"], "--meshcat-html", "not a folder"),
        (["bench", "--json", "note.txt/bench.json"], "--json", "is not a folder"),
        (["diagram", "--out", "note.txt/loop.svg"], "--out", "is not a folder"),
    ],
)
def test_an_output_place_that_cannot_be_written(
    tmp_path, capsys, monkeypatch, arguments, key, text
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "note.txt").write_text("a file, not a folder\n")
    command, *rest = arguments
    force = ["--force"] if command == "simulate" else []
    assert main([command, "--set", "duration=0.2", *rest, *force]) == 2
    _one_line(capsys, key, text)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["note.txt"]
