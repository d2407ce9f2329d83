"""Ctrl-C at any moment: one line, exit status 130, no traceback, nothing half-written.

Each command runs in a process group of its own; SIGINT goes to the whole group, as a
terminal's Ctrl-C does (worker processes included). The moment is chosen by what the
program does, never by a sleep: Drake's library mapped into the process (start-up, while
pydrake loads), or a progress line on stderr (a stage under way).
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

COMMAND = [sys.executable, "-m", "admittance.diagrams.app.cli"]
# A stage of a run takes seconds; this only bounds a test whose trigger never comes.
DEADLINE = 180.0
# Two short grasps (about 1.5 s each), one per controller, on two workers.
GRASP_COMPARE = [
    "grasp-compare",
    *("--set", "duration=1.2", "--size-errors", "0", "--stiffness-errors", "1"),
    *("--workers", "2"),
]


def _start(arguments: list[str], cwd: Path) -> subprocess.Popen:
    environment = dict(os.environ, MPLBACKEND="Agg")
    return subprocess.Popen(
        [*COMMAND, *arguments],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a shell's job
        env=environment,
    )


def _stderr_lines(process: subprocess.Popen) -> queue.Queue:
    lines: queue.Queue = queue.Queue()

    def read() -> None:
        for line in process.stderr:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    return lines


def _drake_loading(pid: int) -> bool:
    try:
        return "libdrake" in Path(f"/proc/{pid}/maps").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return False


def _worker_loading_drake(process: subprocess.Popen) -> bool:
    """A worker process (multiprocessing's spawn) of the command is loading Drake."""
    try:
        children = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
    except FileNotFoundError:
        return False
    for child in children:
        try:
            command = Path(f"/proc/{child}/cmdline").read_bytes()
        except FileNotFoundError:
            continue
        if b"spawn_main" in command and _drake_loading(int(child)):
            return True
    return False


def _interrupt(arguments: list[str], cwd: Path, trigger: str):
    """Runs the command, sends SIGINT to its group at `trigger`; returns the process (its
    pid is the group's), the stderr lines before the signal and the stderr after it."""
    process = _start(arguments, cwd)
    lines = _stderr_lines(process)
    before: list[str] = []
    deadline = time.monotonic() + DEADLINE
    try:
        if trigger in ("start-up", "worker start-up"):
            loading = _drake_loading if trigger == "start-up" else _worker_loading_drake
            while not loading(process.pid if trigger == "start-up" else process):
                assert process.poll() is None, f"the command ended before its {trigger}"
                assert time.monotonic() < deadline, f"no {trigger}"
                time.sleep(0.001)
        else:
            while True:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
                assert line is not None, f"the command ended before {trigger!r}: {before}"
                before.append(line.rstrip("\n"))
                if trigger in line:
                    break
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=DEADLINE)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    after = []
    while (line := lines.get(timeout=10)) is not None:
        after.append(line)
    return process, before, "".join(after)


def _group_members(group: int) -> list[str]:
    """The command lines of the live processes of process group `group`."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            command = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (FileNotFoundError, ProcessLookupError):
            continue
        if int(fields[2]) == group and fields[0] != "Z":  # fields: state, ppid, pgrp
            members.append(command)
    return members


def _group_ends(group: int) -> list[str]:
    """Waits until no process of the group is left (multiprocessing's resource tracker
    leaves when it reads the end of its pipe from the exited parent); returns what is left
    after DEADLINE."""
    deadline = time.monotonic() + DEADLINE
    while (left := _group_members(group)) and time.monotonic() < deadline:
        time.sleep(0.01)
    return left


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize(
    "arguments, trigger",
    [
        # While pydrake loads (its C++ initialization must not see the KeyboardInterrupt).
        (["simulate", "--set", "duration=30"], "start-up"),
        # While the loop is simulated (30 s of the paper's run take several seconds).
        (["simulate", "--set", "duration=30"], "simulating"),
        # While the figures are drawn into the staging folder.
        (["simulate", "--set", "duration=0.5"], "writing"),
        # While a worker process loads Drake (it must not print a traceback of its own).
        (["compare", "--set", "duration=1.5", "--workers", "2"], "worker start-up"),
        # While the worker processes run the controllers (after the first one finished).
        (["compare", "--set", "duration=1.5", "--workers", "2"], "[1/5]"),
        # grasp-compare on the same runner: while its workers load Drake, and while they run
        # its points (after the first finished).
        (GRASP_COMPARE, "worker start-up"),
        (GRASP_COMPARE, "[1/2]"),
        # Between the stages of the stability analysis.
        (["stability", "--quick", "--no-trajectory"], "stability map 1 of 4"),
    ],
    ids=[
        "start-up",
        "simulating",
        "writing",
        "compare-worker-start-up",
        "compare-workers",
        "grasp-compare-worker-start-up",
        "grasp-compare-workers",
        "stability-maps",
    ],
)
def test_ctrl_c_exits_130_with_one_line_and_nothing_half_written(tmp_path, arguments, trigger):
    out = tmp_path / "results" / "run"
    process, before, after = _interrupt([*arguments, "--out", str(out)], tmp_path, trigger)
    assert process.returncode == 130, after
    assert "Traceback" not in after and "initialization failed" not in after
    command = arguments[0]
    *progress, message = after.strip().splitlines() or [""]
    assert all(line.startswith(f"admittance {command}: ") for line in before + progress), after
    if out.exists():  # the signal came after the folder was moved into place
        assert message == f"admittance: interrupted after writing {out}/"
        assert not (out / "INCOMPLETE").exists()
    else:
        assert message == "admittance: interrupted; no result was written"
    # Nothing staged is left next to the result, and no worker is left running.
    assert not out.parent.exists() or [p.name for p in out.parent.iterdir()] in ([], ["run"])
    assert _group_ends(process.pid) == []


def test_a_ctrl_c_that_an_extension_turns_into_its_own_error_still_exits_130(monkeypatch, capsys):
    """numpy checks for signals while it builds an array for a pybind11 call: a Ctrl-C
    there reaches the command line as that call's TypeError ("incompatible function
    arguments"), not as KeyboardInterrupt. It is still an interruption: 130, one line."""
    from admittance.diagrams.app import cli

    def handler(args, progress):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # the signal's handler runs here
        except KeyboardInterrupt:
            raise TypeError("SetFromVector(): incompatible function arguments") from None

    monkeypatch.setitem(cli.HANDLERS, "simulate", handler)
    try:
        assert cli.main(["simulate", "paper_stiffness_step"]) == 130
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    assert capsys.readouterr().err.strip() == "admittance: interrupted; no result was written"
