"""The Cartesian PID motion controller of the paper (eq. 14-16)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.math import max as scalar_max
from pydrake.math import min as scalar_min
from pydrake.systems.framework import LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.planar_kinematics import PlanarFrameKinematics, wrap_angle

__all__ = ["CartesianPid", "CartesianPid_"]


def _gain_vector(name: str, value, size: int, *, allow_zero: bool) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    bad = (array < 0) if allow_zero else (array <= 0)
    if not np.all(np.isfinite(array)) or np.any(bad):
        relation = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {relation}, got {array.tolist()}")
    return array


@TemplateSystem.define("CartesianPid_", T_list=[float, AutoDiffXd])
def CartesianPid_(T):
    class Impl(LeafSystem_[T]):
        """Cartesian PID with joint torques through the Jacobian transpose (paper eq. 14-16).

            ec = Xc - h(q),  dec/dt = dXc/dt - J(q) v                        (eq. 15)
            F_PID = Kp ec + Kd dec/dt + Ki integral(ec)                      (eq. 14)
            tau = clip(J(q)^T F_PID, -effort_limit, effort_limit)            (eq. 16)

        X = (x, y, theta) of the controlled frame and J come from the plant's kinematics. The
        angle error is wrapped to (-pi, pi]. The commanded velocity is whatever the caller
        wires in; the project feeds dXd/dt only, so the admittance offset Xr is never
        differentiated (its derivative would carry the force noise). Torques are clipped to
        the actuators' effort limits read from the plant (the URDF), and mapped to the
        actuation vector through the plant's actuation matrix. There is no gravity
        compensation, as in the paper: the integral term carries the arm's weight. While an
        actuator saturates, back-calculation anti-windup pulls the integral back (see
        ``_integral_rate``), so a blocked arm does not wind it up.

        With ``period > 0`` the controller is sampled: at each sample the torque is computed
        and held (zero-order hold) and the integral advances by period * ec.

        .. pydrake_system::

            name: CartesianPid
            input_ports:
            - commanded_position
            - commanded_velocity
            - estimated_state
            output_ports:
            - actuation
        """

        def _construct(
            self,
            plant,
            *,
            frame_name: str = "fingertip",
            kp: float | Sequence[float],
            kd: float | Sequence[float],
            ki: float | Sequence[float],
            period: float = 0.0,
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] of the arm (fully actuated).
                frame_name: the controlled frame (the fingertip contact point).
                kp, kd, ki: diagonal gains on (x, y, theta): N/m, N s/m, N/(m s) and the
                    rotational equivalents. kp > 0, kd >= 0, ki >= 0.
                period: 0 for a continuous controller, otherwise its sampling period in s.
            """
            LeafSystem_[T].__init__(self, converter=converter)
            self._plant = plant
            self._frame_name = frame_name
            self._kinematics = PlanarFrameKinematics(plant, frame_name)
            num_positions = plant.num_positions()
            num_velocities = plant.num_velocities()
            num_actuators = plant.num_actuated_dofs()
            if num_actuators != num_velocities:
                raise ValueError(
                    f"the Cartesian PID needs a fully actuated arm: {num_actuators} actuators "
                    f"for {num_velocities} velocities"
                )
            self._kp = _gain_vector("kp", kp, 3, allow_zero=False)
            self._kd = _gain_vector("kd", kd, 3, allow_zero=True)
            self._ki = _gain_vector("ki", ki, 3, allow_zero=True)
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
                selection[row, actuator.joint().velocity_start()] = 1.0
                limit = actuator.effort_limit()
                limits.append(limit)  # Drake keeps it > 0 (inf where the URDF gives none)
            self._actuation_from_generalized = selection
            self._actuators_in_joint_order = bool(np.array_equal(selection, np.eye(num_actuators)))
            self._effort_limits = np.array(limits)
            self._effort_limits_list = self._effort_limits.tolist()

            self.commanded_position_input = self.DeclareVectorInputPort("commanded_position", 3)
            self.commanded_velocity_input = self.DeclareVectorInputPort("commanded_velocity", 3)
            self.estimated_state_input = self.DeclareVectorInputPort(
                "estimated_state", num_positions + num_velocities
            )
            # The whole law (kinematics, torque and dz/dt) is computed once per context and
            # read by both the output and the state update: one Python evaluation of the
            # kinematics per derivative evaluation of the closed loop. The integral is the
            # continuous state, or the first 3 discrete states of the sampled controller.
            self._law_cache = self.DeclareCacheEntry(
                description="actuation and integral rate",
                value_producer=ValueProducer(allocate=Value[object]().Clone, calc=self._CalcLaw),
                prerequisites_of_calc={
                    self.xc_ticket() if self._period == 0.0 else self.xd_ticket(),
                    *(
                        self.input_port_ticket(port.get_index())
                        for port in (
                            self.commanded_position_input,
                            self.commanded_velocity_input,
                            self.estimated_state_input,
                        )
                    ),
                },
            )
            if self._period == 0.0:
                self.DeclareContinuousState(3)
                self.actuation_output = self.DeclareVectorOutputPort(
                    "actuation",
                    num_actuators,
                    self._CalcContinuousActuation,
                    prerequisites_of_calc={self._law_cache.ticket()},
                )
            else:
                # Discrete state: [integral of ec (3), held actuation (nu)].
                self._state_index = self.DeclareDiscreteState(3 + num_actuators)
                self.DeclarePeriodicDiscreteUpdateEvent(
                    period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
                )
                self.actuation_output = self.DeclareVectorOutputPort(
                    "actuation",
                    num_actuators,
                    self._CalcSampledActuation,
                    prerequisites_of_calc={self.xd_ticket()},
                )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                other._plant.ToScalarType[T](),
                frame_name=other._frame_name,
                kp=other._kp,
                kd=other._kd,
                ki=other._ki,
                period=other._period,
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
        def effort_limits(self) -> np.ndarray:
            return self._effort_limits.copy()

        def set_integral(self, context, integral) -> None:
            """Sets the integral of the Cartesian error (e.g. to hold the arm at t = 0)."""
            integral = np.asarray(integral)
            if self._period == 0.0:
                context.SetContinuousState(integral)
            else:
                state = context.get_mutable_discrete_state(self._state_index)
                value = np.array(state.CopyToVector())
                value[:3] = integral
                state.SetFromVector(value)

        def cartesian_error(self, context) -> np.ndarray:
            """ec = Xc - h(q) (angle wrapped) at the context's inputs."""
            return self._law_cache.Eval(context)[2].copy()

        def holding_integral(self, state, generalized_force) -> np.ndarray:
            """The integral at which, with zero error, the PID applies `generalized_force`.

            Used to start the arm at rest held against gravity: solves J^T Ki z = tau.
            """
            kinematics = self._kinematics
            kinematics.set_state(state)
            wrench = np.linalg.solve(kinematics.jacobian().T, generalized_force)
            if np.any(self._ki == 0):
                raise ValueError("holding the arm through the integral needs ki > 0 on all axes")
            return wrench / self._ki

        # --- the law ----------------------------------------------------------------------
        def _CalcLaw(self, context, value) -> None:
            """Caches (tau, dz/dt, ec) for the context's state and inputs."""
            kinematics = self._kinematics
            state = self.estimated_state_input.Eval(context)
            kinematics.set_state(state)
            pose = kinematics.pose()
            jacobian = kinematics.jacobian()
            error = self.commanded_position_input.Eval(context) - pose
            error[2] = wrap_angle(error[2])
            error_rate = (
                self.commanded_velocity_input.Eval(context)
                - jacobian @ state[kinematics.num_positions :]
            )
            if self._period == 0.0:
                integral = context.get_continuous_state_vector().CopyToVector()
            else:
                integral = context.get_discrete_state(self._state_index).CopyToVector()[:3]
            wrench = self._kp * error + self._kd * error_rate + self._ki * integral
            torque = jacobian.T @ wrench
            if not self._actuators_in_joint_order:
                torque = self._actuation_from_generalized @ torque
            values = torque.tolist() if T is float else [t.value() for t in torque]
            saturated = any(
                abs(t) > limit for t, limit in zip(values, self._effort_limits_list, strict=True)
            )
            if not saturated:
                value.set_value((torque, error, error))
                return
            clipped = self._clip(torque)
            rate = self._integral_rate(error, clipped - torque, jacobian)
            value.set_value((clipped, rate, error))

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
            for i in range(3):
                if self._ki[i] > 0:
                    rate[i] = error[i] + wrench_excess[i] / (self._ki[i] * self._tracking_time[i])
            return rate

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            if self._period > 0:  # the sampled controller has no continuous state
                return
            derivatives.get_mutable_vector().SetFromVector(self._law_cache.Eval(context)[1])

        def _CalcContinuousActuation(self, context, output) -> None:
            output.SetFromVector(self._law_cache.Eval(context)[0])

        def _DiscreteUpdate(self, context, discrete_state) -> None:
            integral = context.get_discrete_state(self._state_index).CopyToVector()[:3]
            torque, rate, _ = self._law_cache.Eval(context)
            discrete_state.get_mutable_vector(self._state_index).SetFromVector(
                np.concatenate([integral + self._period * rate, torque])
            )

        def _CalcSampledActuation(self, context, output) -> None:
            state = context.get_discrete_state(self._state_index).CopyToVector()
            output.SetFromVector(state[3:])

    return Impl


CartesianPid = CartesianPid_[None]
