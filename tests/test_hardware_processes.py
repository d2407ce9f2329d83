"""The station and the controller as two processes over udpm multicast, inside a network
namespace that the test makes itself (``unshare -rn``: loopback up, multicast routed to it),
so that no packet leaves the machine; skipped where namespaces are not allowed.

The timing tests assert no absolute time: the figures go to docs/evidence/hardware.md.
"""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from admittance.diagrams.app.cli import main

URL = "udpm://239.255.76.67:7667?ttl=0"
ADMITTANCE = str(Path(sys.executable).with_name("admittance"))


def _namespaces_allowed() -> str | None:
    """None if this machine lets the test make a network namespace, else why not."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare or ip is not installed"
    probe = subprocess.run(
        ["unshare", "-rn", "sh", "-c", "ip link set lo up && ip route add 224.0.0.0/4 dev lo"],
        capture_output=True,
        text=True,
    )
    if probe.returncode != 0:
        return f"network namespaces are not allowed here ({probe.stderr.strip()[:80]})"
    return None


NAMESPACE_REFUSAL = _namespaces_allowed()
needs_namespace = pytest.mark.skipif(NAMESPACE_REFUSAL is not None, reason=NAMESPACE_REFUSAL or "")


def run_pair(
    tmp_path: Path,
    control: list[str],
    station: list[str],
    after: str = "",
    admittance: str = ADMITTANCE,
) -> dict:
    """Runs `admittance control` then, once it waits for status, `admittance station`, both
    in one fresh network namespace; `after` is shell run while the station runs (CONTROL
    is the controller's pid); `admittance` is the console script to run. Returns the exit
    statuses and the stderr texts."""
    control_cmd = " ".join(
        shlex.quote(str(a))
        for a in [admittance, "control", "--lcm", URL, "--out", tmp_path / "control", *control]
    )
    station_cmd = " ".join(
        shlex.quote(str(a))
        for a in [admittance, "station", "--lcm", URL, "--out", tmp_path / "station", *station]
    )
    script = f"""
ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 97
{control_cmd} > {tmp_path}/control.out 2> {tmp_path}/control.err &
CONTROL=$!
for i in $(seq 600); do
  grep -q "waiting for status" {tmp_path}/control.err 2>/dev/null && break; sleep 0.1
done
{station_cmd} > {tmp_path}/station.out 2> {tmp_path}/station.err &
STATION=$!
{after}
wait $STATION; echo "station $?" > {tmp_path}/status
wait $CONTROL; echo "control $?" >> {tmp_path}/status
"""
    subprocess.run(["unshare", "-rn", "sh", "-c", script], check=True, timeout=600)
    codes = dict(line.split() for line in (tmp_path / "status").read_text().splitlines())
    return {
        "station": int(codes["station"]),
        "control": int(codes["control"]),
        "control_err": (tmp_path / "control.err").read_text(),
        "station_err": (tmp_path / "station.err").read_text(),
    }


def _metrics(tmp_path: Path) -> dict:
    return json.loads((tmp_path / "station" / "metrics.json").read_text())


def test_a_url_that_could_leave_the_machine_or_a_bad_key_is_refused_in_one_line(tmp_path, capsys):
    status = main(["control", "--lcm", "udpm://239.255.76.67:7667", "--out", str(tmp_path / "c")])
    error = capsys.readouterr().err.strip()
    assert status == 2 and "ttl" in error and "\n" not in error
    assert not (tmp_path / "c").exists()
    for bad, key in (("gama=1", "gama"), ("mode=velocity", "mode"), ("rate=-5", "rate")):
        status = main(["station", "--lcm", "memq://", "--set", bad, "--out", str(tmp_path / "s")])
        error = capsys.readouterr().err.strip()
        assert status == 2 and error.startswith(f"admittance: error: {key}: ") and "\n" not in error
    assert not (tmp_path / "s").exists()


# A responder answers one lcmt_panda_status with an lcmt_panda_command of the same utime;
# a prober publishes a status every 10 ms until that answer comes back.
_RESPONDER = """
import sys
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm
lcm = DrakeLcm(sys.argv[1])
answered = []
def answer(data):
    command = lcmt_panda_command()
    command.utime = lcmt_panda_status.decode(data).utime
    lcm.Publish("PANDA_COMMAND", command.encode())
    answered.append(command.utime)
lcm.Subscribe("PANDA_STATUS", answer)
while not answered:
    lcm.HandleSubscriptions(100)
"""
_PROBER = """
import sys, time
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm
lcm = DrakeLcm(sys.argv[1])
got = []
lcm.Subscribe("PANDA_COMMAND", lambda data: got.append(lcmt_panda_command.decode(data).utime))
status = lcmt_panda_status()
status.utime = 123456
start = time.monotonic()
while not got and time.monotonic() - start < 30:
    lcm.Publish("PANDA_STATUS", status.encode())
    lcm.HandleSubscriptions(10)
print(got[0] if got else "none")
"""


@needs_namespace
def test_a_status_and_its_command_cross_between_two_processes_in_the_namespace():
    script = (
        "ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 97\n"
        f"{shlex.quote(sys.executable)} -c {shlex.quote(_RESPONDER)} {shlex.quote(URL)} &\n"
        f"{shlex.quote(sys.executable)} -c {shlex.quote(_PROBER)} {shlex.quote(URL)}\n"
        "wait\n"
    )
    done = subprocess.run(
        ["unshare", "-rn", "sh", "-c", script], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["123456"]


@needs_namespace
@pytest.mark.slow
def test_two_processes_talk_and_the_controller_exits_when_the_station_is_gone(tmp_path):
    """A short station (0.3 s): every status is answered in time (no command loss at the
    station); then the station stops and the controller exits with one line, status 1."""
    result = run_pair(
        tmp_path,
        ["--set", "duration=10", "--set", "station_timeout=0.5"],
        ["--set", "duration=0.3"],
    )
    assert result["station"] == 0
    assert result["control"] == 1
    last = result["control_err"].strip().splitlines()[-1]
    assert last.startswith("admittance: error: no status from the station on PANDA_STATUS")
    metrics = _metrics(tmp_path)
    assert metrics["command_loss_time"] is None
    timing = json.loads((tmp_path / "control" / "timing.json").read_text())
    assert set(timing["latency"]) == {"p50", "p99", "max"} == set(timing["period_jitter"])
    assert timing["cycles"] >= 290 and isinstance(timing["missed_deadlines"], int)
    assert "hold command: station gone" in (tmp_path / "control" / "events.log").read_text()


@needs_namespace
@pytest.mark.slow
def test_two_processes_press_the_table_within_5_percent_of_fr(tmp_path):
    result = run_pair(tmp_path, ["--set", "duration=4"], ["--set", "duration=4"])
    assert result["station"] == 0 and result["control"] == 0, result
    metrics = _metrics(tmp_path)
    assert metrics["command_loss_time"] is None
    assert abs(metrics["steady_state_force"] - 10.0) < 0.5
    assert metrics["settling_time"] is not None


@needs_namespace
@pytest.mark.slow
def test_the_controller_killed_mid_press_leaves_the_arm_held_under_2_fr(tmp_path):
    """SIGKILL once the controller's clock reaches 2 s (in contact since 0.92 s, the force
    near 9.6 N at the end of its ramp): the station holds the arm from its watchdog's
    timeout on, and the force after the loss stays under 2 Fr."""
    result = run_pair(
        tmp_path,
        ["--set", "duration=6"],
        ["--set", "duration=6", "-q"],
        after=f"while ! grep -q 't = 2.0 s' {tmp_path}/control.err; do sleep 0.02; done; "
        "kill -KILL $CONTROL",
    )
    assert result["station"] == 0 and result["control"] == 128 + 9  # killed
    metrics = _metrics(tmp_path)
    loss = metrics["command_loss_time"]
    assert loss is not None and loss > 1.0
    data = np.loadtxt(tmp_path / "station" / "timeseries.csv", delimiter=",", skiprows=1)
    at_loss = data[np.searchsorted(data[:, 0], loss), 1]
    assert at_loss > 5.0  # mid-press
    assert metrics["peak_force_after_command_loss"] < 2 * 10.0
    hold = [e for e in metrics["watchdog_events"] if e["event"].startswith("hold: newest")]
    assert hold and hold[-1]["time"] == pytest.approx(loss, abs=2e-3)


def test_sigterm_makes_the_controller_send_its_last_safe_command_and_exit_0(tmp_path):
    """memq:// keeps it in the one process: no namespace needed."""
    import signal
    import time

    out = tmp_path / "control"
    process = subprocess.Popen(
        [ADMITTANCE, "control", "--lcm", "memq://", "--out", str(out)],
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in process.stderr:
        if "waiting for status" in line:
            break
    time.sleep(0.2)
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0
    assert "hold command: stop requested" in (out / "events.log").read_text()
    assert json.loads((out / "timing.json").read_text())["cycles"] == 0
