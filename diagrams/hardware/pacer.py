"""A status pacer: the robot's messages at exactly the robot's rate, from a fixed posture,
without a simulation, to time the controller at 1 kHz on a machine whose simulated station
cannot keep real time.

Every period, on absolute deadlines of the monotonic clock (sleep to just before, then
spin), it publishes an ``lcmt_panda_status`` (the home posture, at rest, ``utime`` the
pacer's own clock) and an ``lcmt_force_torque`` (a constant press), and it records when the
command answering each status arrives: the round trip status -> command as the robot sees
it, transport included. The controller's work per cycle is the same whatever the posture.
"""

from __future__ import annotations

import time

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command

from admittance.diagrams.hardware.messages import CHANNELS, status_at_rest
from admittance.diagrams.hardware.timing import quantiles

__all__ = ["StatusPacer"]

# The time before a deadline at which the pacer stops sleeping and spins, s.
SPIN = 2e-4


class StatusPacer:
    """Publishes status and wrench at `rate` Hz for `duration` s; measures the answers."""

    def __init__(self, lcm, *, rate: float, positions, force: float = 10.0) -> None:
        self._lcm = lcm
        self.period = 1.0 / rate
        # The robot at rest at `positions` (its record's home posture).
        self._status = status_at_rest(0, np.array(positions, dtype=float))
        self._wrench = lcmt_force_torque()
        self._wrench.fz = -force  # the tool points into the table: the table pushes along -z
        self._sent: dict[int, float] = {}
        self._round_trips: list[float] = []
        self._send_lateness: list[float] = []
        lcm.Subscribe(CHANNELS.command, self._on_command)

    def _on_command(self, data: bytes) -> None:
        now = time.monotonic()
        utime = lcmt_panda_command.decode(data).utime
        sent = self._sent.pop(utime, None)
        if sent is not None:
            self._round_trips.append(now - sent)

    def run(self, duration: float, stop=lambda: False) -> dict:
        """Paces for `duration` s; returns the figures (seconds)."""
        start = time.monotonic()
        steps = int(round(duration / self.period))
        for k in range(steps):
            if stop():
                break
            deadline = start + k * self.period
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                if remaining > SPIN:
                    self._lcm.HandleSubscriptions(0)
                    time.sleep(min(remaining - SPIN, 2e-4))
            now = time.monotonic()
            self._send_lateness.append(now - deadline)
            utime = int(round(k * self.period * 1e6))
            self._status.utime = utime
            self._wrench.timestamp = utime
            self._sent[utime] = now
            self._lcm.Publish(CHANNELS.wrench, self._wrench.encode())
            self._lcm.Publish(CHANNELS.status, self._status.encode())
            self._lcm.HandleSubscriptions(0)
        end = time.monotonic() + 0.05
        while time.monotonic() < end:
            self._lcm.HandleSubscriptions(1)
        return self.summary(time.monotonic() - start)

    def summary(self, wall: float) -> dict:
        trips = np.asarray(self._round_trips)
        late = np.asarray(self._send_lateness)
        sent = len(self._send_lateness)

        return {
            "period": self.period,
            "statuses": sent,
            "answered": int(trips.size),
            "unanswered": sent - int(trips.size),
            "answered_within_period": int(np.count_nonzero(trips <= self.period)),
            "round_trip": quantiles(trips),
            "send_lateness": quantiles(late),
            "wall_time": wall,
        }
