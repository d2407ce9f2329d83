"""The optimal admittance law of the paper (eq. 10), in its derivative-free form.

The paper minimises I = 1/2 |E + alpha dE/dt|^2 over the reference offset Xr by a gradient
flow (eq. 8). With E = Fr - F and the impedance model of eq. 5, dE/dXr = -K, so

    dXr/dt = + Gamma K (E + alpha dE/dt)                          (eq. 10', docs/paper-notes.md §2)

The printed eq. 9-10 carry the opposite sign, which drives the arm away from the wall; this
module implements the corrected sign: while the measured force is below the desired one
(E > 0) the reference moves along +axis (into the wall), and while it is above (E < 0) the
reference recedes. Integrating once (docs/paper-notes.md §3) removes the derivative of the
noisy force:

    Xr(t) = Gamma K [ z(t) + alpha (E(t) - E(0)) ],   dz/dt = E.

Seen from the force error this is a proportional-integral law with proportional gain
Gamma K alpha and integral gain Gamma K. The block never differentiates the measured force.

Explicit force bound (the paper's future work). With an upper bound Fmax > Fr the
cost gets an exterior penalty on the force above a guard level Fg = (Fr + Fmax) / 2,

    I_b = 1/2 |E + alpha dE/dt|^2 + mu/2 |G + alpha dG/dt|^2,   G = max(0, F - Fg),

and, with dF/dXr = K as above, the gradient flow of I_b integrates once to the same PI law
driven by the bounded error E_b = E - mu G:

    Xr = Gamma K [ z + alpha (E_b - E(0)) ],   dz/dt = E_b.

Below Fg nothing changes, so Fr is tracked as before. Above it the reference recedes with
gains (1 + mu) times the paper's. A wall that pushes the force up steadily, so that Xr must
recede at a speed v, settles where dz/dt = -v / (Gamma K):

    F = Fg + (Fr - Fg + v / (Gamma K)) / (1 + mu)  <=  Fmax
    for every  v <= Gamma K (Fmax - Fr) (1 + mu / 2)

(0.18 m/s with paper_moving_wall's gains, Fmax = 2 Fr, mu = 4). The arm sets a tighter
limit: the PID's D term acts on the velocity of Xd alone, so a wall that pushes the tip at v
costs Kd v of force that no reference offset removes (Kd = 170 N s/m in paper_moving_wall:
8.5 N at 50 mm/s), and the bound can hold only while Kd v < Fmax - Fr. What no law on the
force can prevent: a stiffness jump at a fixed penetration (the force jumps before any
reference can move), the impact of the first contact, and walls faster than that.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.force_axes import check_axes, force_error, per_axis, scatter
from admittance.systems.ports import set_output

__all__ = ["OptimalAdmittance", "OptimalAdmittance_"]


@TemplateSystem.define("OptimalAdmittance_", T_list=[float, AutoDiffXd])
def OptimalAdmittance_(T):
    class Impl(LeafSystem_[T]):
        """Optimal admittance (paper eq. 10 with the corrected sign), one integrator per axis.

        For each force-controlled axis i (an index into the Cartesian vector X = (x, y, theta)):

            E_i = desired_force_i - measured_force_i
            dz_i/dt = E_i
            Xr_i = gamma_i * stiffness_i * (z_i + alpha_i * (E_i - E0_i))

        and Xr = 0 on the other axes. ``stiffness`` is K of eq. 5 and 10: the Cartesian
        stiffness of the position-controlled arm, i.e. the PID's Kp on that axis. E0 is the
        force error at t = 0 (a numeric parameter, see ``set_initial_force_error``) so that
        Xr(0) = 0.

        Safety: a reading that is not finite (a broken sensor) freezes the integral
        and takes E = 0, holding Xr at its settled value; Xr stays within
        [-max_retract, max_push], and past a bound a back-calculation term
        (clamped Xr - unclamped Xr) / (Gamma K tau_aw), tau_aw = max(10 ms, 5 period), pulls
        the integral back (anti-windup), so the block leaves the bound within a few tau_aw
        once the force error changes sign.

        Force bound (``max_force`` finite): the law runs on E_b = E - mu max(0, F - Fg),
        Fg = (Fr + Fmax) / 2 (module docstring), mu = ``force_bound_gain``.

        With ``period > 0`` the law is sampled as a digital controller would run it: at each
        sample k, Xr[k] = Gamma K (z[k] + alpha (E[k] - E0)) is latched (zero-order hold) and
        z[k+1] = z[k] + period * E[k]. The output is the held Xr, a discrete state read
        directly (a state output port): nothing of the law runs between samples.

        .. pydrake_system::

            name: OptimalAdmittance
            input_ports:
            - measured_force
            - desired_force
            output_ports:
            - reference_offset
        """

        def _construct(
            self,
            *,
            gamma: float | Sequence[float],
            alpha: float | Sequence[float],
            stiffness: float | Sequence[float],
            force_axes: Sequence[int] = (0,),
            num_axes: int = 3,
            period: float = 0.0,
            max_push: float | Sequence[float] = math.inf,
            max_retract: float | Sequence[float] = math.inf,
            max_force: float | Sequence[float] = math.inf,
            force_bound_gain: float = 4.0,
            converter=None,
        ) -> None:
            """
            Args:
                gamma: Gamma of eq. 10 per force-controlled axis (> 0), m/(N s) per unit K.
                alpha: weight of dE/dt in the cost of eq. 7, per axis (>= 0), s.
                stiffness: K of eq. 10 per axis (> 0): the PID's Kp on that axis, N/m.
                force_axes: indices of the force-controlled axes in X (x=0, y=1, theta=2).
                num_axes: size of the reference offset output (3 for a planar arm).
                period: 0 for the continuous law, otherwise the sampling period in s.
                max_push: the largest Xr along +axis (into the wall), m (> 0; inf = none).
                max_retract: the largest Xr along -axis (away from the wall), m (> 0).
                max_force: Fmax, the upper bound on the measured force per axis, N (> 0;
                    inf = no bound).
                force_bound_gain: mu, the weight of the force-bound penalty in I_b (> 0).
            """
            LeafSystem_[T].__init__(self, converter=converter)
            axes = check_axes(force_axes, num_axes)
            if not (np.isfinite(period) and period >= 0):
                raise ValueError(f"period must be >= 0 s (0 = continuous), got {period}")
            size = len(axes)
            self._axes = axes
            self._num_axes = int(num_axes)
            self._period = float(period)
            self._gamma = per_axis("gamma", gamma, size, allow_zero=False)
            self._alpha = per_axis("alpha", alpha, size, allow_zero=True)
            self._stiffness = per_axis("stiffness", stiffness, size, allow_zero=False)
            self._max_push = np.broadcast_to(np.asarray(max_push, dtype=float), (size,)).copy()
            self._max_retract = np.broadcast_to(
                np.asarray(max_retract, dtype=float), (size,)
            ).copy()
            for name, bound in (("max_push", self._max_push), ("max_retract", self._max_retract)):
                if np.any(np.isnan(bound)) or np.any(bound <= 0):
                    raise ValueError(f"{name} must be > 0 m, got {bound.tolist()}")
            self._max_force = np.broadcast_to(np.asarray(max_force, dtype=float), (size,)).copy()
            if np.any(np.isnan(self._max_force)) or np.any(self._max_force <= 0):
                raise ValueError(f"max_force must be > 0 N, got {self._max_force.tolist()}")
            if not (math.isfinite(force_bound_gain) and force_bound_gain > 0):
                raise ValueError(f"force_bound_gain must be > 0, got {force_bound_gain}")
            self._force_bound_gain = float(force_bound_gain)
            self._bounded = np.isfinite(self._max_force)
            # Back-calculation anti-windup time constant, s: fast next to the force loop
            # (~0.1 s), slow enough to be a stable discrete update at the sampling period.
            self._windup_time_constant = max(0.01, 5.0 * self._period)
            # The gains of the equivalent PI law on the force error.
            self._integral_gain = self._gamma * self._stiffness
            self._proportional_gain = self._integral_gain * self._alpha
            # The same constants as Python floats, for the law's per-axis arithmetic.
            self._integral_gain_list = self._integral_gain.tolist()
            self._alpha_list = self._alpha.tolist()
            self._max_push_list = self._max_push.tolist()
            self._max_retract_list = self._max_retract.tolist()

            self.measured_force_input = self.DeclareVectorInputPort("measured_force", size)
            self.desired_force_input = self.DeclareVectorInputPort("desired_force", size)
            self._initial_error_index = self.DeclareNumericParameter(
                BasicVector_[T](np.zeros(size))
            )
            if self._period == 0.0:
                self.DeclareContinuousState(size)
                # Xr and dz/dt come from one evaluation of the law per context, read by
                # both the output and the derivatives.
                self._law_cache = self.DeclareCacheEntry(
                    description="reference offset and integral rate",
                    value_producer=ValueProducer(
                        allocate=Value[object]().Clone, calc=self._CalcContinuousLaw
                    ),
                    prerequisites_of_calc={
                        self.xc_ticket(),
                        self.all_parameters_ticket(),
                        self.measured_force_input.ticket(),
                        self.desired_force_input.ticket(),
                    },
                )
                self.reference_offset_output = self.DeclareVectorOutputPort(
                    "reference_offset",
                    self._num_axes,
                    self._CalcContinuousOutput,
                    prerequisites_of_calc={self._law_cache.ticket()},
                )
            else:
                # Discrete state: z (the integral of E) and the held Xr (num_axes), the
                # latter output as it is: nothing of the law runs between samples.
                self._state_index = self.DeclareDiscreteState(size)
                self._held_index = self.DeclareDiscreteState(self._num_axes)
                self.DeclarePeriodicDiscreteUpdateEvent(
                    period_sec=self._period, offset_sec=0.0, update=self._DiscreteUpdate
                )
                self.reference_offset_output = self.DeclareStateOutputPort(
                    "reference_offset", self._held_index
                )

        def _construct_copy(self, other, converter=None) -> None:
            Impl._construct(
                self,
                gamma=other._gamma,
                alpha=other._alpha,
                stiffness=other._stiffness,
                force_axes=other._axes,
                num_axes=other._num_axes,
                period=other._period,
                max_push=other._max_push,
                max_retract=other._max_retract,
                max_force=other._max_force,
                force_bound_gain=other._force_bound_gain,
                converter=converter,
            )

        # --- accessors -------------------------------------------------------------------
        @property
        def force_axes(self) -> list[int]:
            return list(self._axes)

        @property
        def period(self) -> float:
            return self._period

        @property
        def proportional_gain(self) -> np.ndarray:
            """Gamma K alpha per axis, m/N: the direct reaction of Xr to a force change."""
            return self._proportional_gain.copy()

        @property
        def integral_gain(self) -> np.ndarray:
            """Gamma K per axis, m/(N s): the rate of Xr per newton of force error."""
            return self._integral_gain.copy()

        def set_initial_force_error(self, context, initial_force_error) -> None:
            """Sets E(0), so that Xr(0) = 0 (usually desired - measured force at t = 0)."""
            context.get_mutable_numeric_parameter(self._initial_error_index).SetFromVector(
                np.atleast_1d(initial_force_error)
            )

        def set_integral(self, context, integral) -> None:
            """Sets z, the integral of the force error (for a warm start or an analysis)."""
            integral = np.atleast_1d(integral)
            if self._period == 0.0:
                context.SetContinuousState(integral)
            else:
                context.SetDiscreteState(self._state_index, integral)

        # --- the law ----------------------------------------------------------------------
        def _law(self, context, integral):
            """(Xr, dz/dt) per force axis, with the invalid-measurement and push bounds.

            Written on Python scalars (floats, or AutoDiffXd after conversion), per axis.
            """
            desired = self.desired_force_input.Eval(context)
            measured = self.measured_force_input.Eval(context)
            initial_error = (
                context.get_numeric_parameter(self._initial_error_index).CopyToVector().tolist()
            )
            # A reading that is not finite (a broken sensor) gives E = 0: the integral
            # freezes and Xr holds its settled value until the sensor recovers.
            errors = force_error(T, desired, measured)
            gains, alphas = self._integral_gain_list, self._alpha_list
            offsets, rates = [], []
            for i in range(len(self._axes)):
                error = errors[i]
                if self._bounded[i]:
                    force = measured[i]
                    guard = 0.5 * (desired[i] + self._max_force[i])
                    # (NaN compares False: a broken reading adds no penalty.)
                    if (force if T is float else force.value()) > (
                        guard if T is float else guard.value()
                    ):
                        # The force-bound penalty: E_b = E - mu (F - Fg).
                        error = error - self._force_bound_gain * (force - guard)
                offset = gains[i] * (integral[i] + alphas[i] * (error - initial_error[i]))
                rate = error
                offset_value = offset if T is float else offset.value()
                # Xr stays within [-max_retract, max_push]. Past a bound, back-calculation
                # anti-windup pulls the integral back towards the bound with the time
                # constant _windup_time_constant: the unclamped Xr exceeds the bound by at
                # most Gamma K tau_aw |E|, so Xr leaves the bound within a few tau_aw once
                # the force error changes sign. (A hard freeze of dz/dt switches the
                # right-hand side on the bound and stalls an error-controlled integrator.)
                if offset_value > self._max_push_list[i]:
                    clamped = T(self._max_push_list[i])
                elif offset_value < -self._max_retract_list[i]:
                    clamped = T(-self._max_retract_list[i])
                else:
                    clamped = None
                if clamped is not None:
                    rate = error + (clamped - offset) / (gains[i] * self._windup_time_constant)
                    offset = clamped
                offsets.append(offset)
                rates.append(rate)
            return offsets, rates

        def _CalcContinuousLaw(self, context, value) -> None:
            integral = context.get_continuous_state_vector().CopyToVector().tolist()
            offsets, rates = self._law(context, integral)
            value.set_value((scatter(T, self._axes, self._num_axes, offsets), rates))

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            if self._period > 0:  # the sampled law has no continuous state
                return
            derivatives.SetFromVector(self._law_cache.Eval(context)[1])

        def _CalcContinuousOutput(self, context, output) -> None:
            set_output(T, output, self._law_cache.Eval(context)[0])

        def _DiscreteUpdate(self, context, discrete_state) -> None:
            integral = context.get_discrete_state(self._state_index).CopyToVector()
            offsets, rates = self._law(context, integral.tolist())
            discrete_state.get_mutable_vector(self._state_index).SetFromVector(
                integral + self._period * np.array(rates)
            )
            discrete_state.get_mutable_vector(self._held_index).SetFromVector(
                scatter(T, self._axes, self._num_axes, offsets)
            )

    return Impl


OptimalAdmittance = OptimalAdmittance_[None]
