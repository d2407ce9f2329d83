"""The paper's admittance law with the safety layer's limits (docs/evidence/safety.md).

On the wall-normal axis, with the trusted force F (systems/fault_detector.py), the
stiffness estimate k_hat (systems/stiffness_estimator.py) and the reduced contact model
(systems/contact_model.py, m the apparent mass from the plant as built, the motors'
reflected inertia included when the plant has it, and a stated payload m_p at the
fingertip: M(q) + m_p J_t^T J_t, J_t the fingertip point's translational rows of J;
contact_model.apparent_mass; with ``held_axes``, the spatial arm's, the task-space
inertia's Lambda_nn with the other task axes held, systems/safety_numbers.py). The task
vector X is the contact frame's (systems/contact_frame.py: a planar arm's x, y, theta, or
a spatial arm's tool tip, x, y, z, rx, ry, rz in its control frame, the normal z):

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

**The plan's velocity.** The PID's D term is Kd (dXd/dt - x') (docs/evidence/paper-notes.md,
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

**Beyond the stated bounds** (docs/evidence/safety-beyond-bounds.md, section 7). Above
``backoff_stiffness`` (a
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
wall (L from 0 to 0.5 ms; docs/evidence/safety-sampled.md, section 8).

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

from admittance.systems.contact_frame import ContactFrame
from admittance.systems.safety_numbers import (
    SafeAdmittanceParams,
    SafetyNumbers,
    backed_off,
    derived_numbers,
)

__all__ = ["SafeAdmittance", "SafeAdmittance_"]

# Back-calculation anti-windup time constant, s (as in optimal_admittance).
WINDUP_TIME_CONSTANT = 0.01


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


class _SafeAdmittance:
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
        self, plant, *, contact: ContactFrame, params: SafeAdmittanceParams, converter=None
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] of the arm.
            contact: the contact frame, its task vector X (Xr is as long) and the normal's
                index in X.
            params: the law's numbers.
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        params.check()
        self._plant = plant
        self._contact = contact
        self._params = params
        self._set_numbers(params)
        self._axis = contact.normal_axis
        self._num_axes = contact.num_axes
        self._kinematics = contact.kinematics(plant)
        # The rows of X that are the point's translation (for a payload's mass).
        self._translational_rows = [
            row for row, name in enumerate(self._kinematics.coordinates) if name in ("x", "y", "z")
        ]
        self._num_positions = plant.num_positions()
        self._declare_inputs(plant.num_positions() + plant.num_velocities())
        self._declare_law()

    def _construct_copy(self, other, converter=None) -> None:
        _SafeAdmittance._construct(
            self,
            other._plant.ToScalarType[self._T](),
            contact=other._contact,
            params=other._params,
            converter=converter,
        )

    def _set_numbers(self, params: SafeAdmittanceParams) -> None:
        """The law's constants as plain floats, for its per-evaluation arithmetic."""
        self._gamma = params.gamma
        self._alpha = params.alpha
        self._stiffness = params.stiffness
        self._kp = params.pid_kp
        self._kd = params.pid_kd
        self._max_force = params.max_force
        self._mu = params.force_bound_gain
        self._max_push = params.max_push
        self._max_stiffness = params.max_stiffness
        self._contact_force = params.contact_force
        self._period = params.period
        # ds/dt = (s* - s) / this: tau_g, or h over the exact step's share.
        self._schedule_time = (
            self._period / -math.expm1(-self._period / params.schedule_time_constant)
            if self._period > 0
            else params.schedule_time_constant
        )

    def _declare_inputs(self, num_states: int) -> None:
        size = self._num_axes
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
        self.desired_force_input = self.DeclareVectorInputPort("desired_force", 1)
        self.desired_position_input = self.DeclareVectorInputPort("desired_position", size)
        self.desired_velocity_input = self.DeclareVectorInputPort("desired_velocity", size)
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", num_states)
        self.stiffness_estimate_input = self.DeclareVectorInputPort("stiffness_estimate", 1)
        self.sensor_fault_input = self.DeclareVectorInputPort("sensor_fault", 1)
        self.collision_input = self.DeclareVectorInputPort("collision", 1)
        self.wall_approach_speed_input = self.DeclareVectorInputPort("wall_approach_speed", 1)

    def _declare_law(self) -> None:
        """The state [y, s] (discrete with a period), the law's cache and the outputs."""
        if self._period > 0:
            self.DeclareDiscreteState(BasicVector_[self._T]([0.0, 1.0]))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
            )
            state_ticket = self.xd_ticket()
        else:
            self.DeclareContinuousState(BasicVector_[self._T]([0.0, 1.0]))
            state_ticket = self.xc_ticket()
        self._law_cache = self.DeclareCacheEntry(
            description="reference offset and state rates",
            value_producer=ValueProducer(allocate=Value[object]().Clone, calc=self._CalcLaw),
            prerequisites_of_calc={state_ticket, self.all_input_ports_ticket()},
        )
        self.reference_offset_output = self.DeclareVectorOutputPort(
            "reference_offset",
            self._num_axes,
            self._CalcOutput,
            prerequisites_of_calc={self._law_cache.ticket()},
        )
        self.gain_scale_output = self.DeclareVectorOutputPort(
            "gain_scale",
            1,
            lambda context, output: output.SetFromVector([self._state(context)[1]]),
            prerequisites_of_calc={state_ticket},
        )

    # --- the derived numbers ----------------------------------------------------------
    def numbers(self, context) -> SafetyNumbers:
        """m, c, v_max, v_adv, the target schedule and the contact state at `context`."""
        return self._law_cache.Eval(context)[2]

    @property
    def plant(self):
        """The arm's plant the layer takes M(q) and J(q) from."""
        return self._plant

    @property
    def params(self) -> SafeAdmittanceParams:
        """The law's numbers."""
        return self._params

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
        if self._T is not float:
            jacobian = np.array([[_value(x) for x in row] for row in jacobian])
            mass_matrix = np.array([[_value(x) for x in row] for row in mass_matrix])
        return derived_numbers(
            self._params,
            mass_matrix,
            jacobian,
            self._axis,
            translational_rows=self._translational_rows,
            stiffness_estimate=stiffness_estimate,
            force_reference=force_reference,
        )

    # --- initial conditions -----------------------------------------------------------
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

    # --- the law ----------------------------------------------------------------------
    def _CalcLaw(self, context, value) -> None:
        T = self._T
        y, scale = self._state(context)
        state = self.estimated_state_input.Eval(context)
        force = self.measured_force_input.Eval(context)[0]
        reference = self.desired_force_input.Eval(context)[0]
        estimate = self.stiffness_estimate_input.Eval(context)[0]
        collision = self.collision_input.HasValue(context) and (
            _value(self.collision_input.Eval(context)[0]) > 0.5
        )
        # The tip's speed along the normal (carries derivatives: the injected damper).
        self._kinematics.set_state(state)
        jacobian = self._kinematics.jacobian()
        speed = jacobian[self._axis] @ state[self._num_positions :]
        numbers = self._derived(jacobian, _value(estimate), _value(reference))
        numbers["in_contact"] = _value(force) >= self._contact_force

        scale_rate = (numbers["schedule_target"] - scale) / self._schedule_time
        integral_gain = self._gamma * self._stiffness * scale  # Gamma_s K
        cap = numbers["advance_speed"] / _value(integral_gain)
        error = self._bounded_error(force, reference, cap, collision)
        proportional = integral_gain * self._alpha * error
        rate = integral_gain * error - self._gamma * self._stiffness * scale_rate * (
            self._alpha * error
        )
        law = y + proportional
        # The push bound: back-calculation only (a clamp would tie Xc to Xd).
        if _value(law) > self._max_push:
            rate = rate + (T(self._max_push) - law) / WINDUP_TIME_CONSTANT
        desired_speed = self.desired_velocity_input.Eval(context)[self._axis]
        rate = self._command_rate(context, rate, numbers, desired_speed, reference, collision)
        offset = (
            law
            - (numbers["injected_damping"] / self._kp) * speed
            - (self._kd / self._kp) * desired_speed
        )
        output = [T(0.0)] * self._num_axes
        output[self._axis] = offset
        value.set_value((np.array(output), np.array([rate, scale_rate]), numbers, proportional))

    def _bounded_error(self, force, reference, cap: float, collision: bool):
        """E_u: Fr - F with the force-bound penalty, capped from above at E_cap, and at 0
        under the collision reflex (the law may only retract)."""
        T = self._T
        error = reference - force
        guard = 0.5 * (_value(reference) + self._max_force)
        if _value(force) > guard:
            error = error - self._mu * (force - guard)
        if _value(error) > cap:
            error = T(cap)
        if collision and _value(error) > 0.0:
            error = T(0.0)  # the reflex: the law may only retract
        return error

    def _command_rate(self, context, rate, numbers, desired_speed, reference, collision):
        """dy/dt with the limits on the command Xd + y, after every other term of dy/dt:
        the approach speed in free motion, the plan's advance in contact, the fault's
        hold, the approaching wall's retreat and the collision reflex."""
        T = self._T
        fault = _value(self.sensor_fault_input.Eval(context)[0]) > 0.5
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
            rate = self._retreat_from_approaching_wall(context, rate, numbers, _value(reference))
        if collision:
            # Stop, and back off the wall at v_max while in contact.
            retract = numbers["approach_speed"] if numbers["in_contact"] else 0.0
            rate = -retract - desired_speed
        return rate

    def _retreat_from_approaching_wall(self, context, rate, numbers, reference):
        """dy/dt with the command moving back at v_hat, the wall's approach speed
        (systems/wall_motion_monitor.py), on top of the law's own rate, when v_hat is
        above the speed the layer guarantees, v_f = v_max (Fmax - Fr) / Fmax
        (docs/evidence/safety-beyond-bounds.md, section 7): the law's integral then need not lag
        the wall."""
        if not self.wall_approach_speed_input.HasValue(context):
            return rate
        speed = _value(self.wall_approach_speed_input.Eval(context)[0])
        guaranteed = backed_off(numbers["approach_speed"], math.inf, self._max_force, reference)[0]
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


@TemplateSystem.define("SafeAdmittance_", T_list=[float, AutoDiffXd])
def SafeAdmittance_(T):
    class Impl(_SafeAdmittance, LeafSystem_[T]):
        __doc__ = _SafeAdmittance.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _SafeAdmittance._construct
        _construct_copy = _SafeAdmittance._construct_copy

    return Impl


SafeAdmittance = SafeAdmittance_[None]
