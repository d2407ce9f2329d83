"""The Cartesian PID motion controller of the paper (eq. 14-16).

``CartesianPid`` is a small Diagram. Its law, ``CartesianPidLaw``, is a Python LeafSystem
that computes the torque and the rate of the integral term in one calc per evaluation. The
continuous controller keeps that integral in Drake's ``Integrator`` (a C++ primitive) and
splits the law's output with a ``Demultiplexer``, so that each derivative evaluation of a
closed loop calls the PID's Python once (a LeafSystem with its own continuous state needs
three: the law, its output and its derivatives). The sampled controller keeps the integral
and the held torque as the law's discrete states, and outputs the held torque directly.

In six dimensions X = (p, r), r = log(R_EF) the rotation vector of the tool's orientation
in the control frame E (systems/spatial_kinematics.py). The rotational part of ec is not
r_c - r, which jumps by 2 pi across |r| = pi and is not a rotation, but the rotation
vector of the relative rotation, in E:  e_R = log(R_d R^T),  R_d = exp(r_c), R = exp(r).
R_d R^T turns the measured orientation into the commanded one (R_d = (R_d R^T) R). With
dR/dt = [omega]x R in E, d(R_d R^T)/dt = [omega_d - R_d R^T omega]x R_d R^T, so to first
order in e_R, de_R/dt = omega_d - omega: the rate eq. 15 uses, read from J's angular rows.
e_R is defined for every orientation (|e_R| <= pi), with no Euler-angle singularity.
A real arm's torque interface adds g(q) and a null-space posture (systems/posture_task.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import max as scalar_max
from pydrake.math import min as scalar_min
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import Multiplexer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.law_integral import AddLawIntegral
from admittance.systems.posture_task import JointSpaceTorque, PostureTask
from admittance.systems.spatial_kinematics import frame_kinematics, orientation_error
from admittance.systems.task_kinematics import (
    ROTATION_COORDINATES,
    kinematics_size,
    task_coordinates,
    wrap_angle,
)

__all__ = ["CartesianPid", "CartesianPidLaw", "CartesianPidLaw_", "PostureTask"]


def _gain_vector(name: str, value, size: int, *, allow_zero: bool) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    bad = (array < 0) if allow_zero else (array <= 0)
    if not np.all(np.isfinite(array)) or np.any(bad):
        relation = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {relation}, got {array.tolist()}")
    return array


@TemplateSystem.define("CartesianPidLaw_", T_list=[float, AutoDiffXd])
def CartesianPidLaw_(T):
    class Impl(LeafSystem_[T]):
        """The law of the Cartesian PID (paper eq. 14-16); see ``CartesianPid``.

            ec = Xc - h(q),  dec/dt = dXc/dt - J(q) v                        (eq. 15)
            F_PID = Kp ec + Kd dec/dt + Ki z,  z = integral(ec)              (eq. 14)
            tau = clip(J(q)^T F_PID, -effort_limit, effort_limit)            (eq. 16)
            dz/dt = ec  (+ back-calculation while an actuator saturates)

        X is the task vector of ``coordinates`` (an arm's (x, y, theta); a finger of a
        hand's (x, y) of its tip in its face's frame), m = len(coordinates) long; the angle
        error, if X has theta, is wrapped. tau drives only the actuators whose joints move
        the frame (a finger's PID gives zero torque to the others).

        The law reads its inputs as one vector ``law_input``, gathered by a Multiplexer in
        ``CartesianPid`` (one port read instead of four, each about 0.5 us): the commanded
        position Xc (m), the commanded velocity dXc/dt (m), the ``kinematics`` vector
        [X; dX/dt; J] (2 m + m nv) and, for the continuous law, the integral z (m).

        Continuous (``period`` 0): memoryless. The one output is
        ``actuation_and_integral_rate`` = [tau; dz/dt] (nu + m), computed in one calc.
        Sampled (``period`` > 0): z and the held torque are discrete states; at each
        sample tau is latched and z advances by period * dz/dt; the output ``actuation``
        reads the held torque (a state output port), and z is not in the input.

        .. pydrake_system::

            name: CartesianPidLaw
            input_ports:
            - law_input
            output_ports:
            - actuation_and_integral_rate (continuous) or actuation (sampled)
        """

        def _construct(
            self,
            plant,
            *,
            kp: float | Sequence[float],
            kd: float | Sequence[float],
            ki: float | Sequence[float],
            coordinates: Sequence[str],
            period: float = 0.0,
            gravity_compensation: bool = False,
            posture: PostureTask | None = None,
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] (the arm, or a hand with its object).
                coordinates: the task vector X, names among TASK_COORDINATES.
                kp, kd, ki: diagonal gains on X: N/m, N s/m, N/(m s) and the rotational
                    equivalents. kp > 0, kd >= 0, ki >= 0.
                period: 0 for a continuous controller, otherwise its sampling period in s.
                gravity_compensation: add -tau_g(q) = g(q) from the plant.
                posture: a joint-space posture task in the null space of J, or None.
            """
            LeafSystem_[T].__init__(self, converter=converter)
            self._plant = plant
            self._coordinates = task_coordinates(coordinates)
            size = len(self._coordinates)
            self._size = size
            self._angle_index = (
                self._coordinates.index("theta") if "theta" in self._coordinates else None
            )
            # Where rx, ry, rz sit in X (None without a rotation vector).
            self._rotation_indices = (
                [self._coordinates.index(c) for c in ROTATION_COORDINATES]
                if ROTATION_COORDINATES[0] in self._coordinates
                else None
            )
            self._gravity_compensation = bool(gravity_compensation)
            self._posture = posture
            self._joint_space = JointSpaceTorque(
                plant, gravity_compensation=gravity_compensation, posture=posture
            )
            self._uses_state = self._joint_space.active
            num_velocities = plant.num_velocities()
            num_actuators = plant.num_actuated_dofs()
            if num_actuators < size:
                raise ValueError(
                    f"the Cartesian PID needs a fully actuated frame: at least {size} actuators "
                    f"for its {size} task coordinates; the plant has {num_actuators}"
                )
            self._num_velocities = num_velocities
            # Where the parts of the law's input start: Xc, dXc/dt, [X; dX/dt; J], z.
            self._kinematics_start = 2 * size
            self._jacobian_start = 4 * size
            self._state_start = 4 * size + size * num_velocities
            num_states = plant.num_positions() + num_velocities if self._uses_state else 0
            self._integral_start = self._state_start + num_states
            # tau = J^T F_PID as straight-line code on the input vector.
            self._transpose_product = _transpose_product(size, num_velocities, self._jacobian_start)
            self._kp = _gain_vector("kp", kp, size, allow_zero=False)
            self._kd = _gain_vector("kd", kd, size, allow_zero=True)
            self._ki = _gain_vector("ki", ki, size, allow_zero=True)
            self._kp_list, self._kd_list, self._ki_list = (
                gains.tolist() for gains in (self._kp, self._kd, self._ki)
            )
            if not (np.isfinite(period) and period >= 0):
                raise ValueError(f"period must be >= 0 s (0 = continuous), got {period}")
            self._period = float(period)
            # Anti-windup tracking time per axis, s: Astrom and Hagglund's sqrt(Ti Td) =
            # sqrt(Kd / Ki), at least 10 ms and 5 sampling periods (a stable discrete update).
            with np.errstate(divide="ignore", invalid="ignore"):
                tracking = np.sqrt(np.where(self._ki > 0, self._kd / self._ki, 0.0))
            self._tracking_time = np.maximum(tracking, max(0.01, 5.0 * self._period))
            # u = B^T tau, with B (nv x nu) the actuation matrix of single-dof actuators.
            selection = np.zeros((num_actuators, num_velocities))
            limits = []
            for row, index in enumerate(plant.GetJointActuatorIndices()):
                actuator = plant.get_joint_actuator(index)
                column = actuator.joint().velocity_start()
                if selection[:, column].any():
                    raise ValueError(
                        "the Cartesian PID needs a fully actuated arm, one actuator per joint: "
                        f"joint '{actuator.joint().name()}' has two"
                    )
                selection[row, column] = 1.0
                limit = actuator.effort_limit()
                limits.append(limit)  # Drake keeps it > 0 (inf where the URDF gives none)
            self._actuation_from_generalized = selection
            self._actuators_in_joint_order = bool(np.array_equal(selection, np.eye(num_actuators)))
            self._effort_limits = np.array(limits)
            self._beyond_limits = _beyond_limits(limits)

            self._input_sizes = [size, size, kinematics_size(num_velocities, size)]
            if self._uses_state:
                self._input_sizes.append(num_states)
            if self._period == 0.0:
                self._input_sizes.append(size)
            self.law_input = self.DeclareVectorInputPort("law_input", sum(self._input_sizes))
            if self._period == 0.0:
                self.actuation_and_integral_rate_output = self.DeclareVectorOutputPort(
                    "actuation_and_integral_rate",
                    num_actuators + size,
                    self._CalcLaw,
                    prerequisites_of_calc={self.law_input.ticket()},
                )
            else:
                # Discrete state: the integral of ec (m) and the held actuation (nu), the
                # latter output as it is: nothing of the law runs between samples.
                self._integral_index = self.DeclareDiscreteState(size)
                self._held_index = self.DeclareDiscreteState(num_actuators)
                self.DeclarePeriodicDiscreteUpdateEvent(
                    period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
                )
                self.actuation_output = self.DeclareStateOutputPort("actuation", self._held_index)

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                other._plant.ToScalarType[T](),
                kp=other._kp,
                kd=other._kd,
                ki=other._ki,
                period=other._period,
                coordinates=other._coordinates,
                gravity_compensation=other._gravity_compensation,
                posture=other._posture,
                converter=converter,
            )

        # --- accessors -------------------------------------------------------------------
        @property
        def gains(self) -> dict[str, np.ndarray]:
            return {"kp": self._kp.copy(), "kd": self._kd.copy(), "ki": self._ki.copy()}

        @property
        def period(self) -> float:
            return self._period

        @property
        def coordinates(self) -> tuple[str, ...]:
            """The task coordinates, in the order of X and of the gains."""
            return self._coordinates

        @property
        def effort_limits(self) -> np.ndarray:
            return self._effort_limits.copy()

        @property
        def input_sizes(self) -> list[int]:
            """The sizes of the parts of ``law_input``: Xc, dXc/dt, kinematics (, state)
            (and z)."""
            return list(self._input_sizes)

        @property
        def uses_state(self) -> bool:
            """Whether ``law_input`` holds the plant's state (gravity or posture on)."""
            return self._uses_state

        def set_integral(self, context, integral) -> None:
            """Sets z in this system's context (the sampled law's discrete state)."""
            if self._period == 0.0:
                raise ValueError("the continuous law's integral is its input, not its state")
            context.SetDiscreteState(self._integral_index, np.asarray(integral))

        def cartesian_error(self, context) -> np.ndarray:
            """ec = Xc - h(q) (angle wrapped) at the context's inputs."""
            return np.array(self._error(self.law_input.Eval(context).tolist()))

        def _error(self, values) -> list:
            """ec (eq. 15): Xc - X, the angle wrapped, the rotation part log(R_d R^T)."""
            start = self._kinematics_start  # X, then dX/dt
            error = [values[i] - values[start + i] for i in range(self._size)]
            if self._angle_index is not None:
                error[self._angle_index] = wrap_angle(error[self._angle_index])
            if self._rotation_indices is not None:
                rows = self._rotation_indices
                rotation = orientation_error(
                    [values[i] for i in rows], [values[start + i] for i in rows]
                )
                for row, value in zip(rows, rotation, strict=True):
                    error[row] = value
            return error

        # --- the law ----------------------------------------------------------------------
        def _law(self, values, integral):
            """(tau, dz/dt, ec) as lists from the input vector and the integral z.

            `values` is ``law_input`` as a list [Xc; dXc/dt; X; dX/dt; J (; z)]. Written per
            axis on Python scalars (floats, or AutoDiffXd after conversion): on
            three-element vectors that is several times cheaper than numpy's calls.
            """
            kp, kd, ki = self._kp_list, self._kd_list, self._ki_list
            size = self._size
            start = self._kinematics_start  # X, then dX/dt
            error = self._error(values)  # eq. 15
            wrench = [  # eq. 14
                kp[i] * error[i]
                + kd[i] * (values[size + i] - values[start + size + i])
                + ki[i] * integral[i]
                for i in range(size)
            ]
            torque = self._transpose_product(values, wrench)  # tau = J^T F_PID (eq. 16)
            jacobian = None
            if self._uses_state:  # + g(q) and the null-space posture
                jacobian = self._jacobian(values)
                state = values[self._state_start : self._integral_start]
                extra = self._joint_space.torque(state, jacobian)
                torque = [t + e for t, e in zip(torque, extra.tolist(), strict=True)]
            if not self._actuators_in_joint_order:
                torque = (self._actuation_from_generalized @ np.array(torque)).tolist()
            if not self._beyond_limits(torque if T is float else [t.value() for t in torque]):
                return torque, error, error
            torque = np.array(torque)
            clipped = self._clip(torque)
            if jacobian is None:
                jacobian = self._jacobian(values)
            rate = self._integral_rate(error, clipped - torque, jacobian)
            return clipped.tolist(), rate.tolist(), error

        def _jacobian(self, values) -> np.ndarray:
            """J (m x nv) from ``law_input`` as a list."""
            start, size = self._jacobian_start, self._size
            return np.array(values[start : start + size * self._num_velocities]).reshape(
                size, self._num_velocities
            )

        def _clip(self, torque):
            """tau clipped to the effort limits."""
            if T is float:
                return np.clip(torque, -self._effort_limits, self._effort_limits)
            return np.array(
                [
                    scalar_max(T(-limit), scalar_min(T(limit), value))
                    for value, limit in zip(torque, self._effort_limits, strict=True)
                ]
            )

        def _integral_rate(self, error, excess, jacobian):
            """dz/dt = ec + back-calculation while an actuator saturates (anti-windup).

            With dtau = clip(tau) - tau (`excess`, zero unless saturated) mapped back to a
            Cartesian wrench dF = J^-T dtau, dz_i/dt = ec_i + dF_i / (Ki_i Tt_i): the
            integral is pulled back until the torque it asks for is what the actuators give.
            (A hard freeze switches the right-hand side on the limit and stalls an
            error-controlled integrator.) The wrench is recovered with the Jacobian's value
            only: the term is zero, with zero derivative, wherever the loop is linearized
            unsaturated.
            """
            jacobian_value = np.array(
                [[j if T is float else j.value() for j in row] for row in jacobian]
            )
            to_wrench = np.linalg.pinv(self._actuation_from_generalized @ jacobian_value.T)
            wrench_excess = to_wrench @ excess
            rate = np.array(error, dtype=object if T is not float else float)
            for i in range(self._size):
                if self._ki[i] > 0:
                    rate[i] = error[i] + wrench_excess[i] / (self._ki[i] * self._tracking_time[i])
            return rate

        def _CalcLaw(self, context, output) -> None:
            values = self.law_input.Eval(context).tolist()
            torque, rate, _ = self._law(values, values[self._integral_start :])
            output.SetFromVector(torque + rate)

        def _DiscreteUpdate(self, context, discrete_state) -> None:
            integral = context.get_discrete_state(self._integral_index).CopyToVector()
            torque, rate, _ = self._law(self.law_input.Eval(context).tolist(), integral.tolist())
            discrete_state.get_mutable_vector(self._integral_index).SetFromVector(
                integral + self._period * np.array(rate)
            )
            discrete_state.get_mutable_vector(self._held_index).SetFromVector(torque)

    return Impl


CartesianPidLaw = CartesianPidLaw_[None]


def _transpose_product(size: int, num_velocities: int, first: int) -> Callable[[list, list], list]:
    """``function(values, wrench) -> tau``, tau_j = sum_i J_ij F_i, as one line of code.

    J (size x num_velocities) is read row by row from `values`, starting at index `first`.
    The sum runs axis after axis (J_xj F_x + J_yj F_y + J_thetaj F_theta for the arm), on
    Python floats or AutoDiffXd alike. Generated once for the task's size: a written-out
    sum of constant indices costs a third of a loop over the axes.
    """
    sums = (
        " + ".join(f"k[{first + axis * num_velocities + j}] * w[{axis}]" for axis in range(size))
        for j in range(num_velocities)
    )
    source = f"lambda k, w: [{', '.join(sums)}]"
    return eval(compile(source, f"<J^T F, {size} x {num_velocities}>", "eval"), {})


def _beyond_limits(limits: Sequence[float]) -> Callable[[list], bool]:
    """``function(tau) -> bool``: whether any |tau_j| exceeds its effort limit, as one line.

    ``abs(t[0]) > L[0] or abs(t[1]) > L[1] or ...`` for the plant's actuators, generated once
    (a quarter of the cost of ``any`` over a generator; an infinite limit is never exceeded).
    """
    checks = " or ".join(f"abs(t[{j}]) > L[{j}]" for j in range(len(limits))) or "False"
    source = f"lambda t, L={tuple(float(limit) for limit in limits)!r}: {checks}"
    return eval(
        compile(source, f"<|tau| > limit, {len(limits)} actuators>", "eval"), {"inf": math.inf}
    )


def _check_frame_actuated(plant, frame_name: str) -> None:
    """Raises ValueError unless every joint that moves `frame_name` has an actuator."""
    body_index = plant.GetFrameByName(frame_name).body().index()
    actuated = {
        plant.get_joint_actuator(index).joint().index() for index in plant.GetJointActuatorIndices()
    }
    for joint_index in plant.GetJointIndices():
        joint = plant.get_joint(joint_index)
        # (A weld moves no body: Drake's GetBodiesKinematicallyAffectedBy gives none for it.)
        if joint_index in actuated:
            continue
        if body_index in plant.GetBodiesKinematicallyAffectedBy([joint_index]):
            raise ValueError(
                f"the Cartesian PID needs a fully actuated arm: joint '{joint.name()}' moves "
                f"'{frame_name}' but has no actuator"
            )


class CartesianPid(Diagram):
    """Cartesian PID with joint torques through the Jacobian transpose (paper eq. 14-16).

        ec = Xc - h(q),  dec/dt = dXc/dt - J(q) v                        (eq. 15)
        F_PID = Kp ec + Kd dec/dt + Ki integral(ec)                      (eq. 14)
        tau = clip(J(q)^T F_PID, -effort_limit, effort_limit)            (eq. 16)

    X of the controlled frame, its rate J v and J come from the ``kinematics`` input: the
    output of a ``PlanarKinematics`` (or ``SpatialKinematics``, for rx, ry, rz) of the
    same plant, frame and task space. The task space is given at construction: which
    coordinates of the frame (TASK_COORDINATES: its origin's x, y, z, its rotation theta
    about z, or its rotation vector rx, ry, rz) measured in which frame: (x, y, theta)
    in world for a planar arm. A finger of a hand is controlled on (x, y) of
    its tip in a frame fixed at the face it touches, and drives only its own joints. The
    angle error is wrapped to [-pi, pi]; the rotation error is log(R_d R^T) (see the
    module). The commanded velocity is whatever the caller wires in; the project feeds
    dXd/dt only, so the admittance offset Xr is never differentiated. Torques are clipped
    to the actuators' effort limits read from the plant, and mapped to the actuation
    vector through the plant's actuation matrix. By default there is no gravity
    compensation, as in the paper (the integral term carries the arm's weight); a real
    arm's adds g(q), and a redundant arm's a posture in the null space of J
    (``gravity_compensation``, ``posture``; the ``state`` input then reads [q; v]). While
    an actuator saturates, back-calculation anti-windup pulls the integral back (see
    ``CartesianPidLaw._integral_rate``), so a blocked arm does not wind it up.

    Inside: the law (``CartesianPidLaw``, named ``law``) and, for the continuous
    controller, ``integral`` (Drake's ``Integrator``, state z = integral(ec)) fed with dz/dt
    through ``split`` (a ``Demultiplexer`` of the law's [tau; dz/dt]). With ``period > 0``
    the controller is sampled: at each sample the torque is computed and held (zero-order
    hold) and the integral advances by period * ec; nothing runs between samples.

    .. pydrake_system::

        name: CartesianPid
        input_ports:
        - commanded_position
        - commanded_velocity
        - kinematics
        - state (with gravity compensation or a posture task)
        output_ports:
        - actuation
    """

    def __init__(
        self,
        plant,
        *,
        frame_name: str,
        coordinates: Sequence[str],
        kp: float | Sequence[float],
        kd: float | Sequence[float],
        ki: float | Sequence[float],
        period: float = 0.0,
        expressed_in: str = "world",
        gravity_compensation: bool = False,
        posture: PostureTask | None = None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant (the arm, or a hand with its object).
            frame_name: the controlled frame (the contact point's).
            coordinates: the task vector X, names among TASK_COORDINATES.
            kp, kd, ki: diagonal gains on X: N/m, N s/m, N/(m s) and the rotational
                equivalents (N m/rad, N m s/rad, N m/(rad s)). kp > 0, kd >= 0, ki >= 0.
            period: 0 for a continuous controller, otherwise its sampling period in s.
            expressed_in: the frame X is measured and expressed in (fixed in world).
            gravity_compensation: add g(q) = -tau_g(q) from the plant (the ``state``
                input is then declared).
            posture: a joint-space posture task in the null space of J (systems/
                posture_task.py), or None (with one, the ``state`` input is declared).
        """
        Diagram.__init__(self)
        self._kinematics = frame_kinematics(
            plant, frame_name, coordinates=coordinates, expressed_in=expressed_in
        )
        _check_frame_actuated(plant, frame_name)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem(
            "law",
            CartesianPidLaw(
                plant,
                kp=kp,
                kd=kd,
                ki=ki,
                period=period,
                coordinates=coordinates,
                gravity_compensation=gravity_compensation,
                posture=posture,
            ),
        )
        self._law = law
        self._actuation_from_generalized = law._actuation_from_generalized
        self._integrator = None
        inputs = builder.AddNamedSystem("inputs", Multiplexer(law.input_sizes))
        builder.Connect(inputs.get_output_port(), law.law_input)
        names = ["commanded_position", "commanded_velocity", "kinematics"]
        if law.uses_state:
            names.append("state")
        for index, name in enumerate(names):
            builder.ExportInput(inputs.get_input_port(index), name)
        if law.period == 0.0:
            self._integrator = AddLawIntegral(
                builder,
                law.actuation_and_integral_rate_output,
                inputs.get_input_port(len(names)),
                "actuation",
            )
        else:
            builder.ExportOutput(law.actuation_output, "actuation")
        builder.BuildInto(self)
        self.commanded_position_input = self.GetInputPort("commanded_position")
        self.commanded_velocity_input = self.GetInputPort("commanded_velocity")
        self.kinematics_input = self.GetInputPort("kinematics")
        #: The plant's state [q; v] (None unless gravity compensation or a posture is on).
        self.state_input = self.GetInputPort("state") if law.uses_state else None
        self.actuation_output = self.GetOutputPort("actuation")

    # --- accessors -----------------------------------------------------------------------
    @property
    def law(self) -> CartesianPidLaw:
        return self._law

    @property
    def gains(self) -> dict[str, np.ndarray]:
        return self._law.gains

    @property
    def period(self) -> float:
        return self._law.period

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The task coordinates, in the order of X and of the gains."""
        return self._law.coordinates

    @property
    def effort_limits(self) -> np.ndarray:
        return self._law.effort_limits

    def set_integral(self, context, integral) -> None:
        """Sets the integral of the Cartesian error (e.g. to hold the arm at t = 0).

        Args:
            context: this PID's context (``GetMyMutableContextFromRoot`` in a diagram).
            integral: z, one value per task coordinate.
        """
        integral = np.asarray(integral, dtype=float)
        if self._integrator is not None:
            self._integrator.set_integral_value(
                self.GetMutableSubsystemContext(self._integrator, context), integral
            )
        else:
            self._law.set_integral(self.GetMutableSubsystemContext(self._law, context), integral)

    def cartesian_error(self, context) -> np.ndarray:
        """ec = Xc - h(q) (angle wrapped) at the inputs of this PID's context."""
        return self._law.cartesian_error(self.GetSubsystemContext(self._law, context))

    def holding_integral(self, state, generalized_force) -> np.ndarray:
        """The integral at which, with zero error, the PID applies `generalized_force`.

        Used to start the arm at rest held against gravity: solves J^T Ki z = tau. When J
        is not square (a finger of a hand, whose J has a column per joint of the plant),
        over the actuated joints in the least-squares sense: exact for the joints that
        move the frame, the others being other PIDs' to hold.
        """
        kinematics = self._kinematics
        kinematics.set_state(state)
        jacobian = kinematics.jacobian()
        if jacobian.shape[0] == jacobian.shape[1] == len(self._actuation_from_generalized):
            wrench = np.linalg.solve(jacobian.T, generalized_force)
        else:
            selection = self._actuation_from_generalized
            wrench = np.linalg.lstsq(
                selection @ jacobian.T, selection @ np.asarray(generalized_force), rcond=None
            )[0]
        ki = self._law.gains["ki"]
        if np.any(ki == 0):
            raise ValueError("holding the arm through the integral needs ki > 0 on all axes")
        return wrench / ki
