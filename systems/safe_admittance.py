"""The paper's admittance law with the safety layer's limits (docs/safety.md).

On the wall-normal axis, with the trusted force F (systems/fault_detector.py), the
stiffness estimate k_hat (systems/stiffness_estimator.py) and the reduced contact model
(systems/contact_model.py, m the apparent mass from the plant as built, the motors'
reflected inertia included when the plant has it, and a stated payload m_p at the
fingertip: M(q) + m_p J_t^T J_t, J_t the fingertip point's translational rows of J;
contact_model.apparent_mass; with ``held_axes``, the spatial arm's, the task-space
inertia's Lambda_nn with the other task axes held, systems/safety_numbers.py). The task
vector X is the planar arm's (x, y, theta) or any of systems/spatial_kinematics.py's (the
spatial arm's tool tip, x, y, z, rx, ry, rz in its control frame, the normal z):

**The law in contact is eq. 10 with a scheduled gain.** With Gamma_s = s Gamma,

    Xr = y + Gamma_s K alpha E_u,
    dy/dt = Gamma_s K E_u - (dGamma_s/dt) K alpha E_u,

so that d(y + Gamma_s K alpha E_u)/dt = Gamma_s K (E_u + alpha dE_u/dt) exactly: the
gradient flow of the paper's cost (eq. 8-10) with the positive gain Gamma_s, for which
eq. 13 gives dV/dt = -(E + alpha dE/dt)^2 K Gamma_s K <= 0 as for any Gamma > 0. The
noisy force is still never differentiated (y carries the integral). E_u is the force
error of the paper with the force-bound penalty of systems/optimal_admittance.py,
E_b = E - mu max(0, F - Fg), capped from above (below).

**Stiffness-aware gain.** s follows (time constant tau_g) the target

    s* = min(1, Gamma*(k_hat) / (margin Gamma)),

Gamma* the critical Gamma of the reduced loop on a wall of stiffness k_hat (Routh-Hurwitz,
contact_model.critical_gamma, 10-20 % below the full linearization's): the loop gain stays
a factor `margin` inside the stable region. ds/dt is known, so dGamma_s/dt above is exact.

**Damping along the normal.** Xr also carries -(c / Kp) x' (x' the tip's speed along the
normal): through the PID's spring that is a damper c, with c the least that gives the
contact mode the damping ratio zeta_target at Ke_max (contact_model.injected_damping): a
first contact with less than 0.19 always bounces. At an equilibrium x' = 0: the term adds
damping and nothing else.

**The plan's velocity.** The PID's D term is Kd (dXd/dt - x') (docs/paper-notes.md,
section 10): a plan moving along the normal pushes Kd dXd/dt through it whatever Xr is.
Xr carries -(Kd / Kp) dXd/dt, which the PID's spring turns into -Kd dXd/dt: the PID then
acts as Kp (Xd + y + P - X) - (Kd + c) x' along the normal, the reduced model's
m x'' + (Kd + c) x' + (Kp + Ke) x = Kp Xc with Xc = Xd + y + P (systems/contact_model.py)
for any plan. With the plan still along the normal the term is zero.

**Approach.** While F < F_c (no contact) the command Xd + y may approach the wall no faster
than v_max, the speed whose impact on a wall of Ke_max peaks at Fmax
(contact_model.safe_approach_speed, with Kd + c and the apparent mass with the payload
allowance): dy/dt <= v_max - dXd/dt, applied after every other term of dy/dt (the push
bound's back-calculation included), so that nothing lifts it. When F reaches F_c the limit
is lifted; y and E are continuous there, so Xr does not jump.

**Advance in contact.** A reading that drops (a fault not yet detected, or a real loss of
force) must not throw the reference into the wall. E_u <= E_cap = v_adv / (Gamma_s K)
bounds the advance to v_adv and the proportional path's push to alpha v_adv. Over the
detector's longest delay t_d that moves the reference by at most v_adv (alpha + t_d), and
a step of the reference into a wall overshoots by (1 + os), os the contact mode's step
overshoot, so the force rises by at most Kp v_adv (alpha + t_d)(1 + os) before the fault
is caught; that is Fmax - Fr for

    v_adv = (Fmax - Fr) / (Kp (alpha + t_d) (1 + os)).

In contact a plan that advances into the wall does not move the command: dy/dt loses
max(dXd/dt, 0), so Xd + y advances only at the law's own rate, at most v_adv. Retracting is
never limited, and the layer has no bound on how far Xr retracts (admittance.max_retract
is the paper's law's travel, not the layer's): only the arm's reach stops it
(the robot's safety layer reports it). Within |E| <= E_cap and with the plan still or
receding (normal tracking) the law is exactly the paper's; beyond, it pushes less than the
paper's would.

**Faults.** While the detector flags the reading, the command does not advance
(dy/dt <= min(0, -dXd/dt)) and the law runs on the held reading, so Xd + y holds (or
retracts). When the flag clears it returns at the rates above: v_adv in contact, v_max in
free motion.

**Collision reflex.** Once the detector flags a collision on a link (its ``collision``
output, latched), the arm stops and backs off the wall: the plan's motion along the normal
no longer moves the command (dy/dt loses dXd/dt), the law may only retract (E_u <= 0), and
while the trusted force shows contact the command Xd + y moves away from the wall at
v_max, then holds where the contact released. v_max is the speed whose impact on a wall of
Ke_max peaks at Fmax: a retreat that strikes something as stiff stays under Fmax too. The
PID keeps the arm at that command against the collision's torque; the damper c x' stays.
Without a value on the ``collision`` input there is no reflex.

**Beyond the stated bounds** (docs/safety.md, section 7). Above ``backoff_stiffness`` (a
wall reported stiffer than stated) the command moves toward the wall at most at
v_f = v_max (Fmax - Fr) / Fmax, in contact and in free motion. In contact, a wall that
approaches faster than v_f (``wall_approach_speed``, systems/wall_motion_monitor.py) moves
the command back at that speed on top of the law's rate. Without a value on that input,
nothing.

Push bound: y + P is kept below max_push by back-calculation (time constant 10 ms, as in
systems/optimal_admittance.py), without a hard clamp of the output: a clamp would tie the
command to Xd and let it approach at the plan's speed. y + P passes max_push by at most
10 ms times the law's rate (0.1 mm at v_adv = 11.5 mm/s). The limits above act after it.

**A sampled controller** (``period`` h > 0, the PID's period too): y and s are discrete
states advanced at each tick, y by h dy/dt and s exactly, s + (1 - exp(-h / tau_g)) (s* - s)
(dGamma_s/dt above is that step over h), while Xr is computed from them and the inputs at
the tick the PID reads it, as one controller computes both in one tick. Gamma* is then the
sampled loop's with the reading ``latency`` L late (systems/sampled_loop.py: the
spectral radius of the reduced loop over one tick, the delay as states), in place of the
continuous Routh-Hurwitz bound, which at h = 1 ms is 17 to 30 times too high on a 1e6 N/m
wall (L from 0 to 0.5 ms; docs/safety.md, section 8).

For AutoDiffXd (Linearize), the schedule's inputs that are not the loop's (m, c, v_max,
v_adv, the branch of each min) are taken at their values: at an equilibrium they are
frozen, and y, s, E and x' carry the derivatives.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems import contact_model
from admittance.systems.planar_kinematics import PLANAR_COORDINATES
from admittance.systems.safety_numbers import SafetyNumbers, backed_off, task_apparent_mass
from admittance.systems.sampled_loop import SampledContactLoop
from admittance.systems.spatial_kinematics import frame_kinematics

__all__ = ["SafeAdmittance", "SafeAdmittance_"]

# Back-calculation anti-windup time constant, s (as in optimal_admittance).
WINDUP_TIME_CONSTANT = 0.01


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


@TemplateSystem.define("SafeAdmittance_", T_list=[float, AutoDiffXd])
def SafeAdmittance_(T):
    class Impl(LeafSystem_[T]):
        """Optimal admittance with a scheduled gain, an approach limit and fault holds.

        State: [y, s] (m, and Gamma_s / Gamma). Outputs: Xr (zero off the normal axis), s.

        .. pydrake_system::

            name: SafeAdmittance
            input_ports:
            - measured_force
            - desired_force
            - desired_position
            - desired_velocity
            - estimated_state
            - stiffness_estimate
            - sensor_fault
            - collision
            - wall_approach_speed
            output_ports:
            - reference_offset
            - gain_scale
        """

        def _construct(
            self,
            plant,
            *,
            frame_name: str = "fingertip",
            gamma: float,
            alpha: float,
            stiffness: float,
            pid_kp: float,
            pid_kd: float,
            max_force: float,
            force_bound_gain: float,
            max_push: float,
            max_stiffness: float,
            damping_ratio: float,
            stability_margin: float,
            filter_time_constant: float,
            contact_force: float,
            detection_delay: float,
            schedule_time_constant: float = 0.005,
            payload_mass: float = 0.0,
            period: float = 0.0,
            latency: float = 0.0,
            normal_axis: int = 0,
            num_axes: int = 3,
            backoff_stiffness: float = math.inf,
            coordinates=PLANAR_COORDINATES,
            expressed_in: str = "world",
            held_axes: bool = False,
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] of the arm.
                frame_name: the contact frame.
                gamma, alpha, stiffness: Gamma, alpha and K of eq. 10 (K = the PID's Kp).
                pid_kp, pid_kd: the PID's gains along the normal, N/m and N s/m.
                max_force: Fmax, N (finite).
                force_bound_gain: mu of the force-bound penalty.
                max_push: the bound of Xr into the wall around Xd, m (the layer has no
                    bound on the retract side: only the arm's reach).
                max_stiffness: Ke_max, the stated upper bound on the wall stiffness, N/m.
                damping_ratio: zeta_target of the contact mode at Ke_max.
                stability_margin: the factor between Gamma* and the scheduled Gamma.
                filter_time_constant: tau of the sensor's filter, s (0 = ideal sensor).
                contact_force: F_c, N.
                detection_delay: t_d, the fault detector's longest delay, s.
                schedule_time_constant: tau_g, s.
                payload_mass: m_p, an unmodelled payload or tool at the fingertip, kg
                    (>= 0): added to the plant's M(q) as a point mass there.
                period: h, the controller's period, s (0 = the continuous law).
                latency: L, how late the reading reaches the law, s (used with h > 0).
                normal_axis: the wall normal's index in X.
                num_axes: size of Xr.
                backoff_stiffness: above this estimate (a wall reported stiffer than
                    stated) the command moves toward the wall at most at
                    v_f = v_max (Fmax - Fr) / Fmax, in contact and in free motion, N/m.
                coordinates, expressed_in: the task vector X and the frame it is in
                    (the planar arm's x, y, theta in world by default; the spatial arm's
                    x, y, z, rx, ry, rz in its control frame).
                held_axes: the apparent mass with the other task axes held,
                    Lambda_nn of (J M^-1 J^T)^-1, rather than free, 1 / (j M^-1 j^T)
                    (systems/safety_numbers.py).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            positive = {
                "gamma": gamma,
                "stiffness": stiffness,
                "pid_kp": pid_kp,
                "max_force": max_force,
                "force_bound_gain": force_bound_gain,
                "max_push": max_push,
                "max_stiffness": max_stiffness,
                "damping_ratio": damping_ratio,
                "stability_margin": stability_margin,
                "contact_force": contact_force,
                "detection_delay": detection_delay,
                "schedule_time_constant": schedule_time_constant,
            }
            for name, value in positive.items():
                if not (math.isfinite(value) and value > 0):
                    raise ValueError(f"{name} must be finite and > 0, got {value}")
            for name, value in (
                ("alpha", alpha),
                ("pid_kd", pid_kd),
                ("filter_time_constant", filter_time_constant),
                ("payload_mass", payload_mass),
                ("period", period),
                ("latency", latency),
            ):
                if not (math.isfinite(value) and value >= 0):
                    raise ValueError(f"{name} must be finite and >= 0, got {value}")
            self._plant = plant
            self._frame_name = frame_name
            self._args = dict(
                positive,
                alpha=float(alpha),
                pid_kd=float(pid_kd),
                filter_time_constant=float(filter_time_constant),
                payload_mass=float(payload_mass),
                period=float(period),
                latency=float(latency),
                normal_axis=int(normal_axis),
                num_axes=int(num_axes),
                backoff_stiffness=float(backoff_stiffness),
                coordinates=tuple(coordinates),
                expressed_in=expressed_in,
                held_axes=bool(held_axes),
            )
            self._held_axes = bool(held_axes)
            self._backoff_stiffness = float(backoff_stiffness)
            self._gamma = float(gamma)
            self._alpha = float(alpha)
            self._stiffness = float(stiffness)
            self._kp = float(pid_kp)
            self._kd = float(pid_kd)
            self._max_force = float(max_force)
            self._mu = float(force_bound_gain)
            self._max_push = float(max_push)
            self._payload = float(payload_mass)
            self._max_stiffness = float(max_stiffness)
            self._damping_ratio = float(damping_ratio)
            self._margin = float(stability_margin)
            self._tau_filter = float(filter_time_constant)
            self._contact_force = float(contact_force)
            self._detection_delay = float(detection_delay)
            self._tau_schedule = float(schedule_time_constant)
            self._period = float(period)
            self._latency = float(latency)
            # ds/dt = (s* - s) / this: tau_g, or h over the exact step's share.
            self._schedule_time = (
                self._period / -math.expm1(-self._period / self._tau_schedule)
                if self._period > 0
                else self._tau_schedule
            )
            self._axis = int(normal_axis)
            self._num_axes = int(num_axes)
            self._kinematics = frame_kinematics(
                plant, frame_name, coordinates=coordinates, expressed_in=expressed_in
            )
            # The rows of X that are the point's translation (for a payload's mass).
            self._translational_rows = [
                row
                for row, name in enumerate(self._kinematics.coordinates)
                if name in ("x", "y", "z")
            ]
            nq, nv = plant.num_positions(), plant.num_velocities()
            self._num_positions = nq

            self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
            self.desired_force_input = self.DeclareVectorInputPort("desired_force", 1)
            self.desired_position_input = self.DeclareVectorInputPort("desired_position", num_axes)
            self.desired_velocity_input = self.DeclareVectorInputPort("desired_velocity", num_axes)
            self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", nq + nv)
            self.stiffness_estimate_input = self.DeclareVectorInputPort("stiffness_estimate", 1)
            self.sensor_fault_input = self.DeclareVectorInputPort("sensor_fault", 1)
            self.collision_input = self.DeclareVectorInputPort("collision", 1)
            self.wall_approach_speed_input = self.DeclareVectorInputPort("wall_approach_speed", 1)
            if self._period > 0:
                self.DeclareDiscreteState(BasicVector_[T]([0.0, 1.0]))
                self.DeclarePeriodicDiscreteUpdateEvent(
                    period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
                )
                state_ticket = self.xd_ticket()
            else:
                self.DeclareContinuousState(BasicVector_[T]([0.0, 1.0]))
                state_ticket = self.xc_ticket()
            self._law_cache = self.DeclareCacheEntry(
                description="reference offset and state rates",
                value_producer=ValueProducer(allocate=Value[object]().Clone, calc=self._CalcLaw),
                prerequisites_of_calc={state_ticket, self.all_input_ports_ticket()},
            )
            self.reference_offset_output = self.DeclareVectorOutputPort(
                "reference_offset",
                num_axes,
                self._CalcOutput,
                prerequisites_of_calc={self._law_cache.ticket()},
            )
            self.gain_scale_output = self.DeclareVectorOutputPort(
                "gain_scale",
                1,
                lambda context, output: output.SetFromVector([self._state(context)[1]]),
                prerequisites_of_calc={state_ticket},
            )

        def _construct_copy(self, other, converter=None) -> None:
            args = dict(other._args)
            Impl._construct(
                self,
                other._plant.ToScalarType[T](),
                frame_name=other._frame_name,
                converter=converter,
                **args,
            )

        # --- the derived numbers ------------------------------------------------------
        def numbers(self, context) -> SafetyNumbers:
            """m, c, v_max, v_adv, the target schedule and the contact state at `context`."""
            return self._law_cache.Eval(context)[2]

        @property
        def plant(self):
            """The arm's plant the layer takes M(q) and J(q) from."""
            return self._plant

        def numbers_at(
            self, state, force_reference: float, stiffness_estimate: float | None = None
        ) -> SafetyNumbers:
            """m, m_p, c, v_max and v_adv at the plant state `state` (q, v), with the
            schedule at `stiffness_estimate` (the prior Ke_max by default: the bounds a
            logged sample was held to)."""
            self._kinematics.set_state(state)
            estimate = self._max_stiffness if stiffness_estimate is None else stiffness_estimate
            return self._derived(self._kinematics.jacobian(), estimate, force_reference)

        def _derived(self, jacobian, stiffness_estimate: float, force_reference: float):
            """The schedule's numbers (values only) from J and M(q) at the state the
            kinematics were last set to."""
            mass_matrix = self._plant.CalcMassMatrix(self._kinematics.context)
            if T is not float:
                jacobian = np.array([[_value(x) for x in row] for row in jacobian])
                mass_matrix = np.array([[_value(x) for x in row] for row in mass_matrix])
            mass = task_apparent_mass(
                mass_matrix,
                jacobian,
                self._axis,
                translational_rows=self._translational_rows,
                payload_mass=self._payload,
                held_axes=self._held_axes,
            )
            # Beyond the stated bound (docs/safety.md, section 7): on a wall the estimate
            # shows stiffer than Ke_max, the approach speed is the estimate's (any
            # re-contact peaks under Fmax there); the damper stays Ke_max's.
            stiffest = max(self._max_stiffness, stiffness_estimate)
            damping = contact_model.injected_damping(
                mass, self._kp, self._kd, self._max_stiffness, self._damping_ratio
            )
            total_damping = self._kd + damping
            approach_speed = contact_model.safe_approach_speed(
                self._max_force, mass, self._kp, total_damping, stiffest
            )
            overshoot = contact_model.step_overshoot(
                contact_model.damping_ratio(mass, self._kp, total_damping, stiffest)
            )
            advance_speed = max(self._max_force - force_reference, 0.0) / (
                self._kp * (self._alpha + self._detection_delay) * (1.0 + overshoot)
            )
            if stiffness_estimate > self._backoff_stiffness:
                approach_speed, advance_speed = backed_off(
                    approach_speed, advance_speed, self._max_force, force_reference
                )
            if self._period > 0:
                loop = SampledContactLoop(
                    mass,
                    self._kp,
                    total_damping,
                    self._alpha,
                    self._tau_filter,
                    self._stiffness,
                    self._period,
                )
                critical = loop.rounded().critical_gamma(
                    float(f"{stiffness_estimate:.2e}"), self._latency
                )
            else:
                critical = contact_model.critical_gamma(
                    stiffness_estimate,
                    mass=mass,
                    kp=self._kp,
                    kd=total_damping,
                    alpha=self._alpha,
                    filter_time_constant=self._tau_filter,
                    admittance_stiffness=self._stiffness,
                )
            return SafetyNumbers(
                apparent_mass=mass,
                payload_mass=self._payload,
                injected_damping=damping,
                approach_speed=approach_speed,
                advance_speed=advance_speed,
                critical_gamma=critical,
                schedule_target=min(1.0, critical / (self._margin * self._gamma)),
            )

        # --- initial conditions --------------------------------------------------------
        def start_at_tip(self, context) -> None:
            """Xc = the tip's position along the normal, s = its target (a run's start).

            Raises:
                ValueError: the tip is farther into the wall's side of Xd than max_push
                    (the reference could not start at the tip). The retract side has no
                    bound with the layer.
            """
            state = self.estimated_state_input.Eval(context)
            self._kinematics.set_state(state)
            tip = _value(self._kinematics.pose()[self._axis])
            desired = _value(self.desired_position_input.Eval(context)[self._axis])
            offset = tip - desired
            if offset > self._max_push:
                raise ValueError(
                    f"the tip starts {offset:+.4g} m from Xd along the normal, beyond "
                    f"max_push = {self._max_push:g} m"
                )
            self._set_offset(context, offset)

        def set_equilibrium(self, context, offset: float) -> None:
            """Xr = `offset` and s at its target (an equilibrium of the analysis)."""
            self._set_offset(context, offset)

        def _set_offset(self, context, offset: float) -> None:
            estimate = _value(self.stiffness_estimate_input.Eval(context)[0])
            reference = _value(self.desired_force_input.Eval(context)[0])
            state = self.estimated_state_input.Eval(context)
            self._kinematics.set_state(state)
            numbers = self._derived(self._kinematics.jacobian(), estimate, reference)
            scale = numbers["schedule_target"]
            self._set_state(context, [0.0, scale])
            proportional = self._law_cache.Eval(context)[3]  # Gamma_s K alpha E_u
            self._set_state(context, [offset - _value(proportional), scale])

        def _state(self, context):
            if self._period > 0:
                return context.get_discrete_state_vector().value()
            return context.get_continuous_state_vector().CopyToVector()

        def _set_state(self, context, values) -> None:
            if self._period > 0:
                context.SetDiscreteState(values)
            else:
                context.SetContinuousState(values)

        # --- the law ------------------------------------------------------------------
        def _CalcLaw(self, context, value) -> None:
            y, scale = self._state(context)
            state = self.estimated_state_input.Eval(context)
            force = self.measured_force_input.Eval(context)[0]
            reference = self.desired_force_input.Eval(context)[0]
            estimate = self.stiffness_estimate_input.Eval(context)[0]
            fault = _value(self.sensor_fault_input.Eval(context)[0]) > 0.5
            collision = (
                self.collision_input.HasValue(context)
                and _value(self.collision_input.Eval(context)[0]) > 0.5
            )
            # The tip's speed along the normal (carries derivatives: the injected damper).
            self._kinematics.set_state(state)
            jacobian = self._kinematics.jacobian()
            speed = jacobian[self._axis] @ state[self._num_positions :]
            numbers = self._derived(jacobian, _value(estimate), _value(reference))
            numbers["in_contact"] = _value(force) >= self._contact_force

            scale_rate = (numbers["schedule_target"] - scale) / self._schedule_time
            integral_gain = self._gamma * self._stiffness * scale  # Gamma_s K
            error = reference - force
            guard = 0.5 * (_value(reference) + self._max_force)
            if _value(force) > guard:
                error = error - self._mu * (force - guard)
            cap = numbers["advance_speed"] / _value(integral_gain)
            if _value(error) > cap:
                error = T(cap)
            if collision and _value(error) > 0.0:
                error = T(0.0)  # the reflex: the law may only retract
            proportional = integral_gain * self._alpha * error
            rate = integral_gain * error - self._gamma * self._stiffness * scale_rate * (
                self._alpha * error
            )
            law = y + proportional
            # The push bound: back-calculation only (a clamp would tie Xc to Xd).
            if _value(law) > self._max_push:
                rate = rate + (T(self._max_push) - law) / WINDUP_TIME_CONSTANT
            # The limits on the command Xd + y, after every other term of dy/dt.
            desired_speed = self.desired_velocity_input.Eval(context)[self._axis]
            plan_speed = _value(desired_speed)
            if not numbers["in_contact"]:
                approach = numbers["approach_speed"] - desired_speed
                if _value(rate) > _value(approach):
                    rate = approach
            elif plan_speed > 0.0:
                rate = rate - desired_speed
            if fault and _value(rate) > min(0.0, -plan_speed):
                rate = T(0.0) if plan_speed <= 0.0 else -desired_speed
            if numbers["in_contact"]:
                rate = self._retreat_from_approaching_wall(
                    context, rate, numbers, _value(reference)
                )
            if collision:
                # Stop, and back off the wall at v_max while in contact.
                retract = numbers["approach_speed"] if numbers["in_contact"] else 0.0
                rate = -retract - desired_speed
            offset = (
                law
                - (numbers["injected_damping"] / self._kp) * speed
                - (self._kd / self._kp) * desired_speed
            )
            output = [T(0.0)] * self._num_axes
            output[self._axis] = offset
            value.set_value((np.array(output), np.array([rate, scale_rate]), numbers, proportional))

        def _retreat_from_approaching_wall(self, context, rate, numbers, reference):
            """dy/dt with the command moving back at v_hat, the wall's approach speed
            (systems/wall_motion_monitor.py), on top of the law's own rate, when v_hat is
            above the speed the layer guarantees, v_f = v_max (Fmax - Fr) / Fmax
            (docs/safety.md, section 7): the law's integral then need not lag the wall."""
            if not self.wall_approach_speed_input.HasValue(context):
                return rate
            speed = _value(self.wall_approach_speed_input.Eval(context)[0])
            guaranteed = backed_off(
                numbers["approach_speed"], math.inf, self._max_force, reference
            )[0]
            return rate - speed if speed > guaranteed else rate

        def _DiscreteUpdate(self, context, discrete_state) -> None:
            rates = self._law_cache.Eval(context)[1]
            discrete_state.get_mutable_vector().SetFromVector(
                self._state(context) + self._period * rates
            )

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            if self._period > 0:
                return  # no continuous state
            derivatives.get_mutable_vector().SetFromVector(self._law_cache.Eval(context)[1])

        def _CalcOutput(self, context, output) -> None:
            output.SetFromVector(self._law_cache.Eval(context)[0])

    return Impl


SafeAdmittance = SafeAdmittance_[None]
