"""The law of the paper's Cartesian PID (eq. 14-16), as one LeafSystem.

``CartesianPidLaw`` computes the torque and the rate of the integral term in one calc per
evaluation, from one input vector (systems/cartesian_pid.py wraps it with the
Multiplexer of its inputs and, continuous, the Integrator of z).

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
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.posture_task import JointSpaceTorque, PostureTask
from admittance.systems.spatial_kinematics import orientation_error
from admittance.systems.task_kinematics import (
    ROTATION_COORDINATES,
    kinematics_size,
    task_coordinates,
    wrap_angle,
)

__all__ = ["CartesianPidLaw", "CartesianPidLaw_"]


def _gain_vector(name: str, value, size: int, *, allow_zero: bool) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    bad = (array < 0) if allow_zero else (array <= 0)
    if not np.all(np.isfinite(array)) or np.any(bad):
        relation = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {relation}, got {array.tolist()}")
    return array


class _CartesianPidLaw:
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
        LeafSystem_[self._T].__init__(self, converter=converter)
        self._plant = plant
        self._set_task(coordinates)
        self._gravity_compensation = bool(gravity_compensation)
        self._posture = posture
        self._joint_space = JointSpaceTorque(
            plant, gravity_compensation=gravity_compensation, posture=posture
        )
        self._uses_state = self._joint_space.active
        self._set_layout(plant)
        self._set_gains(kp, kd, ki, period)
        self._set_actuation(plant)
        self._declare_ports(plant.num_actuated_dofs())

    def _set_task(self, coordinates) -> None:
        """X's coordinates, and where its angle and its rotation vector sit in it."""
        self._coordinates = task_coordinates(coordinates)
        self._size = len(self._coordinates)
        self._angle_index = (
            self._coordinates.index("theta") if "theta" in self._coordinates else None
        )
        # Where rx, ry, rz sit in X (None without a rotation vector).
        self._rotation_indices = (
            [self._coordinates.index(c) for c in ROTATION_COORDINATES]
            if ROTATION_COORDINATES[0] in self._coordinates
            else None
        )

    def _set_layout(self, plant) -> None:
        """Where the parts of ``law_input`` start, and the code of tau = J^T F_PID."""
        size = self._size
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
        self._input_sizes = [size, size, kinematics_size(num_velocities, size)]
        if self._uses_state:
            self._input_sizes.append(num_states)

    def _set_gains(self, kp, kd, ki, period) -> None:
        """Kp, Kd, Ki per axis (checked), the period and the anti-windup tracking time."""
        size = self._size
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

    def _set_actuation(self, plant) -> None:
        """u = B^T tau, with B (nv x nu) the actuation matrix of single-dof actuators, and
        the actuators' effort limits."""
        num_actuators = plant.num_actuated_dofs()
        selection = np.zeros((num_actuators, self._num_velocities))
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

    def _declare_ports(self, num_actuators: int) -> None:
        """``law_input``, and the output: [tau; dz/dt], or the held tau of the sampled law."""
        size = self._size
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
        _CartesianPidLaw._construct(
            self,
            other._plant.ToScalarType[self._T](),
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
        if not self._beyond_limits(torque if self._T is float else [t.value() for t in torque]):
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
        T = self._T
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
        T = self._T
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


@TemplateSystem.define("CartesianPidLaw_", T_list=[float, AutoDiffXd])
def CartesianPidLaw_(T):
    class Impl(_CartesianPidLaw, LeafSystem_[T]):
        __doc__ = _CartesianPidLaw.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _CartesianPidLaw._construct
        _construct_copy = _CartesianPidLaw._construct_copy

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
