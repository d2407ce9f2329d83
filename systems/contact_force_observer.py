"""The contact force seen from the arm's own motion: a generalized-momentum observer.

The arm's dynamics M(q) v' + C(q, v) v = tau + tau_g(q) + tau_ext give, with p = M v and
M' = C + C^T, p' = tau + tau_g + C^T v + tau_ext. The observer of De Luca and Mattone
("Sensorless robot collision detection and hybrid force/motion control", ICRA 2005)

    r = K_o (p - p_I),    dp_I/dt = tau + tau_g + r

gives dr/dt = K_o (tau_ext - r): r follows the external joint torque through a first-order
lag 1 / K_o, from the joint state and the applied torques alone (no acceleration, no
force sensor, no model of the wall). The wall pushes the fingertip along -x, so
tau_ext = J^T (-F, 0, 0) and the estimate of the compressive contact force is

    F_hat = -(J^-T r)_x.

C^T v is left out: at the fingertip speeds of this arm (below 0.1 m/s, links of 0.2 m)
it is below 1e-3 N m. The fault detector compares the sensor's reading with F_hat
(systems/fault_detector.py), and r itself with what a force along the normal can explain:
r off the direction J_x^T is a collision on a link (docs/safety.md, "The collision
reflex"); the output `external_torque` is r.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = ["ContactForceObserver", "ContactForceObserver_"]


@TemplateSystem.define("ContactForceObserver_", T_list=[float, AutoDiffXd])
def ContactForceObserver_(T):
    class Impl(LeafSystem_[T]):
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
            frame_name: str = "fingertip",
            gain: float = 100.0,
            normal_axis: int = 0,
            converter=None,
        ) -> None:
            """
            Args:
                plant: finalized MultibodyPlant_[T] of the arm.
                frame_name: the contact frame.
                gain: K_o, the observer's bandwidth, 1/s (> 0).
                normal_axis: the wall normal's index in X = (x, y, theta).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            if not (math.isfinite(gain) and gain > 0):
                raise ValueError(f"gain must be > 0 1/s, got {gain}")
            self._plant = plant
            self._frame_name = frame_name
            self._gain = float(gain)
            self._normal_axis = int(normal_axis)
            self._kinematics = PlanarFrameKinematics(plant, frame_name)
            nq, nv = plant.num_positions(), plant.num_velocities()
            self._num_positions = nq
            self._actuation_matrix = plant.MakeActuationMatrix()
            self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", nq + nv)
            self.actuation_input = self.DeclareVectorInputPort(
                "actuation", plant.num_actuated_dofs()
            )
            self.DeclareContinuousState(nv)
            self.contact_force_output = self.DeclareVectorOutputPort(
                "contact_force",
                1,
                self._CalcContactForce,
                prerequisites_of_calc={self.xc_ticket(), self.estimated_state_input.ticket()},
            )
            self.external_torque_output = self.DeclareVectorOutputPort(
                "external_torque",
                nv,
                lambda context, output: output.SetFromVector(self._residual(context)),
                prerequisites_of_calc={self.xc_ticket(), self.estimated_state_input.ticket()},
            )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                other._plant.ToScalarType[T](),
                frame_name=other._frame_name,
                gain=other._gain,
                normal_axis=other._normal_axis,
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

        def _residual(self, context):
            """r = K_o (M v - p_I) at the context's state and input."""
            momentum = self._momentum(context)
            return self._gain * (momentum - context.get_continuous_state_vector().CopyToVector())

        def set_external_torque(self, context, external_torque) -> None:
            """Sets p_I so that r equals `external_torque` at the context's state (warm start)."""
            momentum = self._momentum(context)
            context.SetContinuousState(momentum - np.asarray(external_torque) / self._gain)

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            residual = self._residual(context)
            torque = self._actuation_matrix @ self.actuation_input.Eval(context)
            gravity = self._plant.CalcGravityGeneralizedForces(self._kinematics.context)
            derivatives.get_mutable_vector().SetFromVector(torque + gravity + residual)

        def _CalcContactForce(self, context, output) -> None:
            residual = self._residual(context)  # sets the kinematics to the context's state
            jacobian = self._kinematics.jacobian()
            if T is not float:
                residual = np.array([r.value() for r in residual])
                jacobian = np.array([[j.value() for j in row] for row in jacobian])
            wrench = np.linalg.lstsq(jacobian.T, residual, rcond=None)[0]
            output.SetFromVector([T(-wrench[self._normal_axis])])

    return Impl


ContactForceObserver = ContactForceObserver_[None]
