"""The station's side of the robot's interface: what the Panda's controller box does with
the commands it receives (torque or joint positions, gravity compensated, with a command
watchdog), and the wrist sensor's wrench as the message a force/torque driver publishes.

The Panda's torque interface adds the arm's gravity torques to the commanded torques (a
user's controller sends only what is on top of them); its position interface tracks the
commanded joint positions with the box's own joint controller. When commands stop, the
robot's controller stops the arm (Franka's "communication constraints violation" reflex,
which then closes the brakes). The station stands in for that with a hold: from the
moment the newest command is older than ``command_timeout``, its joint PD holds the joint
positions latched at that moment, gravity compensated, until a fresh command arrives. The
hold keeps the torques it latched as a feed-forward, as a brake keeps the joints' loads: a
held arm neither pushes harder nor springs back, and the force it leaves on a surface is
the one it had at the loss.
"""

from __future__ import annotations

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command
from pydrake.common.value import Value
from pydrake.systems.framework import BasicVector, LeafSystem

__all__ = ["CommandWatchdog", "WrenchMessage", "WristWrenchSensor", "joint_gains"]

NUM_JOINTS = 7


class CommandWatchdog(LeafSystem):
    """The Panda's command interface with its watchdog (the class docstring above).

    Every period: a command whose ``utime`` differs from the last one seen is fresh; with
    the freshest command at most ``command_timeout`` old, the actuation is

        torque mode:    u = tau_commanded + g(q)
        position mode:  u = Kp (q_commanded - q) - Kd v + g(q)

    and otherwise the arm is held, u = tau_hold + Kp (q_hold - q) - Kd v + g(q), with
    q_hold and tau_hold (the commanded torque on top of gravity) latched when the hold
    began: a brake, which locks the joints where they are with the torques that balanced
    them, so the switch moves nothing. The arm is held from the start until the first
    command arrives (tau_hold = 0 there).
    Each change between commanded and held is appended to ``events`` (time, what).

    .. pydrake_system::

        name: CommandWatchdog
        input_ports:
        - lcmt_panda_command
        - commanded
        - state
        - gravity_compensation
        output_ports:
        - actuation
        - hold
    """

    def __init__(
        self,
        *,
        mode: str,
        period: float,
        command_timeout: float,
        joint_stiffness: np.ndarray,
        joint_damping: np.ndarray,
        effort_limits: np.ndarray,
        initial_position: np.ndarray,
    ) -> None:
        super().__init__()
        if mode not in ("torque", "position"):
            raise ValueError(f"mode must be torque or position, got {mode!r}")
        self._torque_mode = mode == "torque"
        self._timeout = float(command_timeout)
        self._kp = np.asarray(joint_stiffness, dtype=float)
        self._kd = np.asarray(joint_damping, dtype=float)
        self._limits = np.asarray(effort_limits, dtype=float)
        self.events: list[tuple[float, str]] = []
        self._message = self.DeclareAbstractInputPort(
            "lcmt_panda_command", Value(lcmt_panda_command())
        )
        self._commanded = self.DeclareVectorInputPort("commanded", NUM_JOINTS)
        self._state = self.DeclareVectorInputPort("state", 2 * NUM_JOINTS)
        self._gravity = self.DeclareVectorInputPort("gravity_compensation", NUM_JOINTS)
        # [last utime seen, time it was first seen, hold (0/1), q_hold (7), tau_hold (7)]
        initial = np.concatenate(
            [[0.0, 0.0, 1.0], np.asarray(initial_position, dtype=float), np.zeros(NUM_JOINTS)]
        )
        self._memory = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self._actuation = self.DeclareVectorOutputPort(
            "actuation", NUM_JOINTS, self._calc_actuation
        )
        self.DeclareVectorOutputPort(
            "hold",
            1,
            lambda context, output: output.SetAtIndex(
                0, context.get_discrete_state(self._memory).get_value()[2]
            ),
            {self.xd_ticket()},
        )

    def _update(self, context, discrete_state) -> None:
        time = context.get_time()
        memory = context.get_discrete_state(self._memory).get_value()
        utime = int(self._message.Eval(context).utime)
        last_utime, fresh_time, hold = memory[0], memory[1], memory[2] > 0.5
        if utime != 0 and utime != int(last_utime):
            last_utime, fresh_time = float(utime), time
        stale = utime == 0 or time - fresh_time > self._timeout
        new = memory.copy()
        new[0], new[1] = last_utime, fresh_time
        if stale and not hold:
            new[2] = 1.0
            new[3 : 3 + NUM_JOINTS] = self._state.Eval(context)[:NUM_JOINTS]
            new[3 + NUM_JOINTS :] = self._commanded_effort(context)
            age = (
                "no command yet" if utime == 0 else f"newest command {time - fresh_time:.4f} s old"
            )
            self.events.append((time, f"hold: {age}"))
        elif not stale and hold:
            new[2] = 0.0
            self.events.append((time, "commanded: fresh command"))
        discrete_state.set_value(self._memory, new)

    def _commanded_effort(self, context) -> np.ndarray:
        """The torque the command asks for, on top of gravity."""
        if self._torque_mode:
            return np.array(self._commanded.Eval(context))
        state = self._state.Eval(context)
        q, v = state[:NUM_JOINTS], state[NUM_JOINTS:]
        return self._kp * (self._commanded.Eval(context) - q) - self._kd * v

    def _calc_actuation(self, context, output: BasicVector) -> None:
        memory = context.get_discrete_state(self._memory).get_value()
        if memory[2] > 0.5:
            state = self._state.Eval(context)
            q, v = state[:NUM_JOINTS], state[NUM_JOINTS:]
            q_hold, tau_hold = memory[3 : 3 + NUM_JOINTS], memory[3 + NUM_JOINTS :]
            u = tau_hold + self._kp * (q_hold - q) - self._kd * v
        else:
            u = self._commanded_effort(context)
        gravity = self._gravity.Eval(context)
        output.SetFromVector(np.clip(u + gravity, -self._limits, self._limits))


class WristWrenchSensor(LeafSystem):
    """The wrist's 6-axis force/torque sensor, tared (the tool's weight removed): the wrench
    that the tool's contacts exert on it, about the sensor frame's origin and expressed in
    the sensor frame S, as ``lcmt_force_torque`` (timestamp in microseconds of the station's
    time) and as a vector [f_W (3), f_S (3), tau_S (3)] for the station's log.

    .. pydrake_system::

        name: WristWrenchSensor
        input_ports:
        - contact_results
        - body_poses
        output_ports:
        - lcmt_force_torque
        - wrench
    """

    def __init__(self, plant, tool_body) -> None:
        super().__init__()
        self._tool_index = tool_body.index()
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", plant.get_contact_results_output_port().Allocate()
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", plant.get_body_poses_output_port().Allocate()
        )
        self.DeclareAbstractOutputPort(
            "lcmt_force_torque", lambda: Value(lcmt_force_torque()), self._calc_message
        )
        self.DeclareVectorOutputPort("wrench", 9, self._calc_wrench)

    def wrench(self, context) -> np.ndarray:
        """[f_W, f_S, tau_S]: the contact force on the tool in world and sensor frames and
        the torque about the sensor's origin in the sensor frame."""
        results = self._contacts.Eval(context)
        X_WS = self._poses.Eval(context)[int(self._tool_index)]
        p_WS = X_WS.translation()
        f_W = np.zeros(3)
        tau_W = np.zeros(3)
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            force = info.contact_force()  # on body B
            if info.bodyB_index() == self._tool_index:
                sign = 1.0
            elif info.bodyA_index() == self._tool_index:
                sign = -1.0
            else:
                continue
            f_W += sign * force
            tau_W += np.cross(info.contact_point() - p_WS, sign * force)
        R_SW = X_WS.rotation().inverse()
        return np.concatenate([f_W, R_SW.multiply(f_W), R_SW.multiply(tau_W)])

    def _calc_message(self, context, output) -> None:
        wrench = self.wrench(context)
        message = lcmt_force_torque()
        message.timestamp = int(round(context.get_time() * 1e6))
        message.fx, message.fy, message.fz = (float(x) for x in wrench[3:6])
        message.tx, message.ty, message.tz = (float(x) for x in wrench[6:9])
        output.set_value(message)

    def _calc_wrench(self, context, output: BasicVector) -> None:
        output.SetFromVector(self.wrench(context))


class WrenchMessage(LeafSystem):
    """A wrench [fx, fy, fz, tx, ty, tz] (in the sensor frame) as ``lcmt_force_torque``,
    ``timestamp`` in microseconds of the station's time: what the force/torque sensor's
    driver publishes (the scenario's wrist sensor, ``systems.wrench_sensor.WrenchSensor``,
    with its bias, noise, low-pass and readout period).

    .. pydrake_system::

        name: WrenchMessage
        input_ports:
        - wrench
        output_ports:
        - lcmt_force_torque
    """

    def __init__(self) -> None:
        super().__init__()
        self._wrench = self.DeclareVectorInputPort("wrench", 6)
        self.DeclareAbstractOutputPort(
            "lcmt_force_torque", lambda: Value(lcmt_force_torque()), self._calc_message
        )

    def _calc_message(self, context, output) -> None:
        wrench = self._wrench.Eval(context)
        message = lcmt_force_torque()
        message.timestamp = int(round(context.get_time() * 1e6))
        message.fx, message.fy, message.fz = (float(x) for x in wrench[:3])
        message.tx, message.ty, message.tz = (float(x) for x in wrench[3:])
        output.set_value(message)


def joint_gains(arm, q, config, period: float) -> dict:
    """The station's joint PD gains, per joint: ``joint_damping`` and ``joint_stiffness``
    capped where the joint is light. The discrete plant applies the PD's torque explicitly
    over each step, which is stable for d_i h / M_ii < 2 (M_ii the joint's inertia at the
    start posture q, h the step); the cap keeps d_i <= 0.5 M_ii / h, and k_i <= d_i^2 / M_ii
    (damping ratio 0.5 or more). The wrist's last joint (M_77 = 0.0067 kg m^2, the Panda
    without its motors' reflected inertia, which the URDF does not give) gets d = 3.3 N m s/rad.
    """
    context = arm.CreateDefaultContext()
    arm.SetPositions(context, q)
    inertia = np.diag(arm.CalcMassMatrix(context))
    damping = np.minimum(config.joint_damping, 0.5 * inertia / period)
    stiffness = np.minimum(config.joint_stiffness, damping**2 / inertia)
    return {"joint_stiffness": stiffness, "joint_damping": damping}
