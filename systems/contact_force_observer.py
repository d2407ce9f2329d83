"""The contact force seen from the arm's own motion: a generalized-momentum observer.

The arm's dynamics M(q) v' + C(q, v) v = tau + tau_g(q) + tau_ext give, with p = M v and
M' = C + C^T, p' = tau + tau_g + C^T v + tau_ext. The observer of De Luca and Mattone
("Sensorless robot collision detection and hybrid force/motion control", ICRA 2005)

    r = K_o (p - p_I),    dp_I/dt = tau + tau_g + C(q, v)^T v + r

gives dr/dt = K_o (tau_ext - r): r follows the external joint torque through a first-order
lag 1 / K_o, from the joint state and the applied torques alone (no acceleration, no
force sensor, no model of the wall). The contact pushes the point back along its normal
(the planar arm's wall along -x, the spatial arm's table along -z of the control frame),
so tau_ext = J^T (-F e_n) and the estimate of the compressive contact force is

    F_hat = -(J^-T r)_n,

J the Jacobian of the contact frame's task coordinates and n the normal's index in X
(systems/contact_frame.py); for a redundant arm J^-T is the least-squares solve.

**C(q, v)^T v** is the Lagrangian's dT/dq at fixed v (T = v^T M(q) v / 2, for q' = v), so
that p' = tau + tau_g + dT/dq + tau_ext. It is computed as dM/dt v - C(q, v) v (from
M' = C + C^T), C v the plant's bias term and dM/dt a central difference of M(q) along
q' = N(q) v over a step of 1e-5 rad at the fastest joint (truncation and rounding both
below 1e-9 of the term), so for each evaluation two more mass matrices and a bias term.
Left out (``coriolis=False``, the observer as it was), the observer reads the term as a
contact: r settles at -C^T v, quadratic in the joint speeds (docs/evidence/safety.md, "The
observer's full momentum dynamics").

The fault detector compares the sensor's reading with F_hat
(systems/fault_detector.py), and r itself with what a force along the normal can explain:
r off the direction J_n^T is a collision on a link (docs/evidence/safety-collision.md, "The
collision
reflex"); the output `external_torque` is r.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.contact_frame import ContactFrame

__all__ = ["ContactForceObserver", "ContactForceObserver_", "velocity_product"]

# The central difference of M(q) along q' moves the fastest joint by this much, rad.
DIFFERENCE_STEP = 1e-5


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


def velocity_product(plant, context, shifted_context):
    """C(q, v)^T v = dM/dt v - C(q, v) v at the state of the plant's `context`.

    dM/dt is the central difference of M(q) along q' = N(q) v (MapVelocityToQDot) over
    a step that moves the fastest coordinate by DIFFERENCE_STEP; `shifted_context` is a
    second context of `plant` for the shifted positions. Zero when the arm is at rest.
    Float or AutoDiffXd (the step is taken at the values).
    """
    v = plant.GetVelocities(context)
    q = plant.GetPositions(context)
    qdot = plant.MapVelocityToQDot(context, v)
    fastest = max(abs(_value(x)) for x in qdot)
    if fastest == 0.0:
        return np.zeros(plant.num_velocities())
    step = DIFFERENCE_STEP / fastest
    plant.SetPositions(shifted_context, q + step * qdot)
    ahead = plant.CalcMassMatrix(shifted_context)
    plant.SetPositions(shifted_context, q - step * qdot)
    behind = plant.CalcMassMatrix(shifted_context)
    mass_rate = (ahead - behind) / (2.0 * step)
    return mass_rate @ v - plant.CalcBiasTerm(context)


class _ContactForceObserver:
    """Momentum observer of the contact force along the wall normal (module docstring).

    State: p_I (nv). Outputs: F_hat, N (compressive positive), and r, N m. F_hat is an
    estimate for monitoring: for AutoDiffXd it carries the value only.

    .. pydrake_system::

        name: ContactForceObserver
        input_ports:
        - estimated_state
        - actuation
        output_ports:
        - contact_force
        - external_torque
    """

    def _construct(
        self,
        plant,
        *,
        contact: ContactFrame,
        gain: float = 100.0,
        coriolis: bool = True,
        period: float = 0.0,
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] of the arm.
            contact: the contact frame, its task vector X and the normal's index in X.
            gain: K_o, the observer's bandwidth, 1/s (> 0).
            coriolis: integrate C(q, v)^T v (False: the observer without it, for the
                comparison of docs/evidence/safety.md).
            period: 0 integrates p_I continuously; > 0 steps it by Euler once per
                period, s (a sampled loop's tick: K_o period must stay below 2).
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        if not (math.isfinite(gain) and gain > 0):
            raise ValueError(f"gain must be > 0 1/s, got {gain}")
        if not (math.isfinite(period) and 0 <= period and gain * period < 2):
            raise ValueError(f"period must be >= 0 s with gain x period < 2, got {period}")
        self._period = float(period)
        self._plant = plant
        self._contact = contact
        self._gain = float(gain)
        self._normal_axis = contact.normal_axis
        self._coriolis = bool(coriolis)
        self._kinematics = contact.kinematics(plant)
        self._shifted_context = plant.CreateDefaultContext()
        nq, nv = plant.num_positions(), plant.num_velocities()
        self._num_positions = nq
        self._actuation_matrix = plant.MakeActuationMatrix()
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", nq + nv)
        self.actuation_input = self.DeclareVectorInputPort("actuation", plant.num_actuated_dofs())
        if self._period > 0:
            self.DeclareDiscreteState(nv)
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
            )
            integral_ticket = self.xd_ticket()
        else:
            self.DeclareContinuousState(nv)
            integral_ticket = self.xc_ticket()
        self.contact_force_output = self.DeclareVectorOutputPort(
            "contact_force",
            1,
            self._CalcContactForce,
            prerequisites_of_calc={integral_ticket, self.estimated_state_input.ticket()},
        )
        self.external_torque_output = self.DeclareVectorOutputPort(
            "external_torque",
            nv,
            lambda context, output: output.SetFromVector(self._residual(context)),
            prerequisites_of_calc={integral_ticket, self.estimated_state_input.ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _ContactForceObserver._construct(
            self,
            other._plant.ToScalarType[self._T](),
            contact=other._contact,
            gain=other._gain,
            coriolis=other._coriolis,
            period=other._period,
            converter=converter,
        )

    @property
    def gain(self) -> float:
        return self._gain

    def _momentum(self, context):
        """M(q) v at the context's state; leaves the kinematics set to that state."""
        state = self.estimated_state_input.Eval(context)
        self._kinematics.set_state(state)
        mass_matrix = self._plant.CalcMassMatrix(self._kinematics.context)
        return mass_matrix @ state[self._num_positions :]

    def _integral(self, context):
        """p_I, the observer's state (continuous, or discrete with a period)."""
        if self._period > 0:
            return context.get_discrete_state_vector().CopyToVector()
        return context.get_continuous_state_vector().CopyToVector()

    def _residual(self, context):
        """r = K_o (M v - p_I) at the context's state and input."""
        momentum = self._momentum(context)
        return self._gain * (momentum - self._integral(context))

    def set_external_torque(self, context, external_torque) -> None:
        """Sets p_I so that r equals `external_torque` at the context's state (warm start)."""
        integral = self._momentum(context) - np.asarray(external_torque) / self._gain
        if self._period > 0:
            context.SetDiscreteState(integral)
        else:
            context.SetContinuousState(integral)

    def _rate(self, context):
        """dp_I/dt = tau + tau_g + C(q, v)^T v + r at the context's state and input."""
        residual = self._residual(context)
        torque = self._actuation_matrix @ self.actuation_input.Eval(context)
        plant_context = self._kinematics.context
        rate = torque + self._plant.CalcGravityGeneralizedForces(plant_context) + residual
        if self._coriolis:
            rate = rate + velocity_product(self._plant, plant_context, self._shifted_context)
        return rate

    def DoCalcTimeDerivatives(self, context, derivatives) -> None:
        derivatives.get_mutable_vector().SetFromVector(self._rate(context))

    def _DiscreteUpdate(self, context, discrete_state) -> None:
        discrete_state.set_value(self._integral(context) + self._period * self._rate(context))

    def _CalcContactForce(self, context, output) -> None:
        T = self._T
        residual = self._residual(context)  # sets the kinematics to the context's state
        jacobian = self._kinematics.jacobian()
        if T is not float:
            residual = np.array([r.value() for r in residual])
            jacobian = np.array([[j.value() for j in row] for row in jacobian])
        wrench = np.linalg.lstsq(jacobian.T, residual, rcond=None)[0]
        output.SetFromVector([T(-wrench[self._normal_axis])])


@TemplateSystem.define("ContactForceObserver_", T_list=[float, AutoDiffXd])
def ContactForceObserver_(T):
    class Impl(_ContactForceObserver, LeafSystem_[T]):
        __doc__ = _ContactForceObserver.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _ContactForceObserver._construct
        _construct_copy = _ContactForceObserver._construct_copy

    return Impl


ContactForceObserver = ContactForceObserver_[None]
