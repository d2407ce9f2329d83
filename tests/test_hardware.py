"""The hardware split over real LCM in one process (memq://): the messages, the
controller's law and watchdogs, the station's command watchdog, the clock from utime."""

from __future__ import annotations

import math

import numpy as np
import pytest
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm

from admittance.diagrams.hardware.config import load_hardware_config
from admittance.diagrams.hardware.control_law import AdmittanceLaw
from admittance.diagrams.hardware.controller import AdmittanceController
from admittance.diagrams.hardware.messages import (
    CHANNELS,
    check_lcm_url,
    decode_parameters,
    encode_parameters,
    status_at_rest,
)
from admittance.diagrams.hardware.panda import PANDA_HOME
from admittance.diagrams.hardware.station import run_station, station_metrics

PERIOD = 1e-3


class FakeClock:
    """A wall clock the test advances by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _status(utime: int, q=PANDA_HOME) -> bytes:
    return status_at_rest(utime, q).encode()


def _wrench(timestamp: int, fz: float) -> bytes:
    message = lcmt_force_torque()
    message.timestamp = timestamp
    # The hand points down at PANDA_HOME: the sensor's z is the world's -z.
    message.fz = -fz
    return message.encode()


class Commands:
    """Every command published on the memq instance."""

    def __init__(self, lcm) -> None:
        self.received: list[lcmt_panda_command] = []
        lcm.Subscribe(
            CHANNELS.command, lambda data: self.received.append(lcmt_panda_command.decode(data))
        )


def _controller(overrides=(), clock=None):
    lcm = DrakeLcm("memq://")
    config = load_hardware_config("panda_surface_press", list(overrides))
    controller = AdmittanceController(config, lcm, clock=clock or FakeClock())
    return lcm, config, controller, Commands(lcm)


def _cycle(lcm, utime: int, force: float | None, wrench_time: int | None = None) -> None:
    if force is not None:
        lcm.Publish(CHANNELS.wrench, _wrench(utime if wrench_time is None else wrench_time, force))
    lcm.Publish(CHANNELS.status, _status(utime))
    while lcm.HandleSubscriptions(0):  # the status, then the command it answers
        pass


def _answer_statuses(lcm, until: int | None = None) -> None:
    """A stand-in controller: zero torque in answer to every status up to `until` us."""

    def answer(data):
        status = lcmt_panda_status.decode(data)
        if until is not None and status.utime > until:
            return
        command = lcmt_panda_command()
        command.utime = status.utime
        command.num_joint_torque = 7
        command.joint_torque = [0.0] * 7
        command.control_mode_expected = 4
        lcm.Publish(CHANNELS.command, command.encode())

    lcm.Subscribe(CHANNELS.status, answer)


# --- messages -----------------------------------------------------------------------------


def test_parameters_round_trip_and_refuse_bad_values_in_one_line():
    assert decode_parameters(encode_parameters(force_reference=5, gamma=1e-6)) == {
        "force_reference": 5.0,
        "gamma": 1e-6,
    }
    for bad in (b"{}", b"[1]", b'{"gama": 1}', b'{"alpha": -1}', b'{"gamma": "x"}', b"\xff"):
        with pytest.raises(ValueError, match="^parameters: ") as error:
            decode_parameters(bad)
        assert "\n" not in str(error.value)


def test_only_urls_that_keep_packets_on_the_host_are_accepted():
    assert check_lcm_url("memq://") == "memq://"
    assert check_lcm_url("udpm://239.255.76.67:7667?ttl=0")
    for url in ("udpm://239.255.76.67:7667", "udpm://239.255.76.67:7667?ttl=1", ""):
        with pytest.raises(ValueError, match="ttl"):
            check_lcm_url(url)


def test_station_status_and_command_round_trip_through_drakes_sender_and_receiver():
    """The station's status decodes in Python with the plant's positions and its time; a
    Python command reaches the plant through PandaCommandReceiver (the watchdog releases the
    hold at the first fresh command)."""
    lcm = DrakeLcm("memq://")
    statuses = []
    lcm.Subscribe(CHANNELS.status, lambda data: statuses.append(lcmt_panda_status.decode(data)))

    _answer_statuses(lcm)
    config = load_hardware_config(None, ["duration=0.01", "realtime_rate=0", "command_wait=0"])
    run = run_station(config, lcm)
    assert [s.utime for s in statuses[:3]] == [0, 1000, 2000]
    np.testing.assert_allclose(statuses[0].joint_position, PANDA_HOME, atol=1e-12)
    assert run.events[0][1] == "commanded: fresh command"
    assert run.hold[-1] == 0.0


def test_position_mode_tracks_the_commanded_joint_positions():
    """mode: position: the station's joint PD, gravity compensated, brings the arm at rest
    to the commanded positions (no steady-state error: gravity is cancelled, nothing else
    loads the free arm); joint 1 moved by 0.05 rad, read back from the status."""
    lcm = DrakeLcm("memq://")
    target = PANDA_HOME + np.array([0.05, 0, 0, 0, 0, 0, 0])
    statuses = []

    def answer(data):
        status = lcmt_panda_status.decode(data)
        statuses.append(status)
        command = lcmt_panda_command()
        command.utime = status.utime
        command.num_joint_position = 7
        command.joint_position = list(target)
        command.control_mode_expected = 1  # PandaControlMode.kPosition
        lcm.Publish(CHANNELS.command, command.encode())

    lcm.Subscribe(CHANNELS.status, answer)
    config = load_hardware_config(
        None, ["duration=0.6", "realtime_rate=0", "command_wait=0", "mode=position"]
    )
    run = run_station(config, lcm)
    assert run.hold[-1] == 0.0
    np.testing.assert_allclose(statuses[-1].joint_position, target, atol=1e-3)
    assert abs(statuses[len(statuses) // 10].joint_position[0] - PANDA_HOME[0]) > 1e-3


# --- the law ------------------------------------------------------------------------------


def _law(**changes):
    values = dict(
        force_reference=10.0,
        gamma=3e-6,
        alpha=0.02,
        stiffness=1000.0,
        max_force=20.0,
        force_bound_gain=4.0,
        max_push=0.08,
    )
    values.update(changes)
    return AdmittanceLaw(**values)


def test_law_increment_by_hand_and_bumpless_changes():
    law = _law()
    # First sample: E = 10 - 4 = 6 N, no previous error: Xr = Gamma K dt E = 1.8e-5 m.
    assert law.update(4.0, 1e-3) == pytest.approx(3e-6 * 1000 * 1e-3 * 6)
    before = law.offset
    law.set_parameters(gamma=6e-6, alpha=0.05)
    assert law.offset == before  # the integral continues
    # Next sample, E = 10 - 5 = 5 N: + 6e-6 * 1000 (1e-3 * 5 + 0.05 (5 - 6)).
    assert law.update(5.0, 1e-3) - before == pytest.approx(6e-3 * (5e-3 - 0.05))
    # A step of Fr by -5 N moves Xr by Gamma K alpha dFr at once (plus dt E), as eq. 10.
    before = law.offset
    law.set_parameters(force_reference=5.0)
    assert law.update(5.0, 1e-3) - before == pytest.approx(6e-3 * (0.0 + 0.05 * -5.0))
    # Above the guard (Fr + Fmax) / 2 = 12.5 N the penalty mu (F - Fg) adds: E_b = 5 - 15 - 4 * 7.5.
    law = _law(force_reference=5.0)
    assert law.bounded_error(20.0) == pytest.approx(-15.0 - 4.0 * 7.5)


def test_parameter_message_changes_the_running_law_without_a_jump():
    lcm, config, controller, _ = _controller()
    for k in range(5):
        _cycle(lcm, 1000 * k, 4.0)
    before = controller.law.offset
    lcm.Publish(CHANNELS.parameters, encode_parameters(gamma=1e-6, alpha=0.0))
    lcm.HandleSubscriptions(0)
    assert controller.law.offset == before and controller.law.gamma == 1e-6
    _cycle(lcm, 5000, 4.0)
    # One sample at the new gains: Gamma K dt E = 1e-6 * 1000 * 1e-3 * 6.
    assert controller.law.offset - before == pytest.approx(6e-6)
    assert "parameters: alpha=0, gamma=1e-06" in controller.events[-1].what
    lcm.Publish(CHANNELS.parameters, b'{"max_force": 1}')  # below Fr: refused
    lcm.HandleSubscriptions(0)
    assert controller.law.max_force == config.max_force
    assert controller.events[-1].what.startswith("parameters rejected")


# --- the controller's watchdogs -----------------------------------------------------------


def test_no_status_for_n_periods_sends_the_hold_command_with_its_time():
    clock = FakeClock()
    lcm, config, controller, commands = _controller(["status_timeout_periods=3"], clock)
    for k in range(4):
        _cycle(lcm, 1000 * k, 0.0)
        clock.now += PERIOD
    torque = list(commands.received[-1].joint_torque)
    count = len(commands.received)
    clock.now += 2.9 * PERIOD - PERIOD  # 2.9 periods since the last status
    controller.poll(0.0)
    lcm.HandleSubscriptions(0)
    assert len(commands.received) == count
    clock.now += 0.2 * PERIOD  # 3.1 periods
    controller.poll(0.0)
    lcm.HandleSubscriptions(0)
    hold = commands.received[-1]
    assert len(commands.received) == count + 1
    assert hold.utime == 3000 and list(hold.joint_torque) == torque
    assert controller.events[-1].what.startswith("hold: no status for 3.1 periods")
    assert controller.events[-1].time == pytest.approx(0.003)
    _cycle(lcm, 4000, 0.0)
    assert controller.events[-1].what == "resume: status received"


def test_the_station_gone_raises_one_line():
    from admittance.diagrams.hardware.controller import StationGoneError

    clock = FakeClock()
    lcm, config, controller, _ = _controller([], clock)
    _cycle(lcm, 0, 0.0)
    clock.now += config.station_timeout + 0.01
    with pytest.raises(StationGoneError, match="no status from the station on PANDA_STATUS"):
        controller.check_watchdogs()


@pytest.mark.parametrize("fault", ["nan", "stale"])
def test_a_non_finite_or_stale_wrench_holds_the_law(fault):
    lcm, config, controller, commands = _controller()
    for k in range(3):
        _cycle(lcm, 1000 * k, 4.0)
    held = controller.law.offset
    for k in range(3, 6):
        if fault == "nan":
            _cycle(lcm, 1000 * k, math.nan)
        else:  # the last wrench is from utime 2000: stale beyond wrench_timeout
            _cycle(lcm, 1000 * k + int(config.wrench_timeout * 1e6), None)
        assert controller.law.offset == held
    assert len(commands.received) == 6
    what = "non-finite wrench" if fault == "nan" else "stale wrench"
    assert [e.what for e in controller.events if e.what.startswith("hold:")] == [
        f"hold: {what}; the law holds its offset"
        if fault == "nan"
        else next(e.what for e in controller.events if "stale" in e.what)
    ]
    assert what in controller.events[-1].what
    # A valid wrench resumes the law from its held offset, no jump: the alpha difference
    # restarts, so one step Gamma K dt E with dt the status clock's step (5 ms here for both:
    # the last status came at 5 ms, or at 15 ms for the stale case).
    last = controller.time
    _cycle(lcm, int(last * 1e6) + 5000, 4.0)
    assert controller.law.offset - held == pytest.approx(3e-6 * 1000 * 5e-3 * 6, rel=1e-9)


# --- the station's watchdog ---------------------------------------------------------------


def test_station_holds_the_arm_when_commands_stop_and_logs_when():
    """Commands answer every status until 50 ms, then stop: the station holds from the
    first step at which the newest command is older than the timeout (20 ms)."""
    lcm = DrakeLcm("memq://")

    _answer_statuses(lcm, until=50_000)
    config = load_hardware_config(None, ["duration=0.1", "realtime_rate=0", "command_wait=0"])
    run = run_station(config, lcm)
    metrics = station_metrics(run, config)
    # The last command answers the status at 50 ms and is latched at 51 ms; the hold comes
    # once more than 20 ms have passed since then: at 72 ms (the watchdog's 1 ms sampling).
    assert metrics["command_loss_time"] == pytest.approx(0.072, abs=1.5e-3)
    assert run.events[-1][1].startswith("hold: newest command 0.02")
    assert run.hold[-1] == 1.0


# --- station and controller together, one process -----------------------------------------


def _press(overrides):
    lcm = DrakeLcm("memq://")
    config = load_hardware_config("panda_surface_press", ["command_wait=0", *overrides])
    controller = AdmittanceController(config, lcm)
    run = run_station(config, lcm)
    return config, controller, run


def test_the_controller_keeps_its_clock_from_the_status_utime():
    """A station paced at 0.2 of real time and one as fast as it can give the controller the
    same answer at each status time: the approach Xr(t) = Gamma K Fr t (no contact yet, E =
    Fr constant), by hand."""
    answers = []
    for rate in (0.0, 0.2):
        config, controller, run = _press(["duration=0.05", f"realtime_rate={rate}"])
        answers.append((np.array(controller.trace.times), np.array(controller.trace.offset)))
        if rate > 0:
            assert run.real_time_rate == pytest.approx(rate, rel=0.2)
    np.testing.assert_array_equal(answers[0][0], answers[1][0])
    np.testing.assert_array_equal(answers[0][1], answers[1][1])
    times, offsets = answers[0]
    expected = config.gamma * config.translational_stiffness * config.force_reference * times
    np.testing.assert_allclose(offsets[1:], expected[1:], rtol=1e-9)


@pytest.mark.slow
def test_the_press_settles_within_5_percent_in_one_process():
    config, controller, run = _press(["duration=4", "realtime_rate=0"])
    metrics = station_metrics(run, config)
    assert metrics["command_loss_time"] is None
    assert metrics["settling_time"] is not None and metrics["settling_time"] < 3.5
    assert abs(metrics["steady_state_force"] - config.force_reference) < 0.05 * 10


class MutedLcm:
    """The controller's view of a memq instance whose outgoing messages can be cut (the
    controller process gone, as by SIGKILL) or that sends a parameter change at a time."""

    def __init__(self, lcm) -> None:
        self.lcm = lcm
        self.muted = False

    def Subscribe(self, channel, handler):  # noqa: N802 (DrakeLcm's interface)
        return self.lcm.Subscribe(channel, handler)

    def Publish(self, channel, data):  # noqa: N802
        if not self.muted:
            self.lcm.Publish(channel, data)

    def HandleSubscriptions(self, timeout):  # noqa: N802
        return self.lcm.HandleSubscriptions(timeout)


def _press_with(overrides, at_time, action):
    """The press in one process; `action(controller, muted_lcm)` runs once at the first
    status at or after `at_time` s."""
    lcm = DrakeLcm("memq://")
    muted = MutedLcm(lcm)
    config = load_hardware_config("panda_surface_press", ["command_wait=0", *overrides])
    controller = AdmittanceController(config, muted)
    done = []

    def watch(data):
        if not done and lcmt_panda_status.decode(data).utime >= at_time * 1e6:
            done.append(True)
            action(controller, muted, lcm)

    lcm.Subscribe(CHANNELS.status, watch)
    run = run_station(config, lcm)
    return config, controller, run


@pytest.mark.slow
def test_commands_lost_mid_press_the_station_holds_and_the_force_stays_put():
    """The controller falls silent at 2 s (in contact since 0.7 s, 9.7 N): the station holds
    from its timeout (20 ms after the last command) and the force stays under 2 Fr; with
    the latched torques as the brake's load it stays within 0.5 N of its value."""

    def silence(controller, muted, lcm):
        muted.muted = True

    config, _, run = _press_with(["duration=2.6", "realtime_rate=0"], 2.0, silence)
    metrics = station_metrics(run, config)
    loss = metrics["command_loss_time"]
    assert loss == pytest.approx(2.0 + 0.001 + config.command_timeout, abs=2.5e-3)
    assert metrics["peak_force_after_command_loss"] < 2 * config.force_reference
    at_loss = run.force[np.searchsorted(run.times, loss)]
    after = run.force[run.times >= loss]
    assert np.max(np.abs(after - at_loss)) < 0.5


@pytest.mark.slow
def test_fr_from_10_to_5_n_while_running_follows_without_overshoot_beyond_10_percent():
    def lower(controller, muted, lcm):
        lcm.Publish(CHANNELS.parameters, encode_parameters(force_reference=5.0))

    config, controller, run = _press_with(["duration=5", "realtime_rate=0"], 2.5, lower)
    assert any("force_reference=5" in e.what for e in controller.events)
    after = run.force[run.times >= 2.5]
    assert np.min(after) > 5.0 - 0.1 * 5.0  # no overshoot below 4.5 N
    assert after[-1] == pytest.approx(5.0, abs=0.25)
