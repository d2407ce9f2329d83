"""The optimal admittance law of the paper (eq. 10), in its derivative-free form.

The paper minimises I = 1/2 |E + alpha dE/dt|^2 over the reference offset Xr by a gradient
flow (eq. 8). With E = Fr - F and the impedance model of eq. 5, dE/dXr = -K, so

    dXr/dt = + Gamma K (E + alpha dE/dt)                          (eq. 10',
    docs/evidence/paper-notes.md §2)

The printed eq. 9-10 carry the opposite sign, which drives the arm away from the wall; this
module implements the corrected sign: while the measured force is below the desired one
(E > 0) the reference moves along +axis (into the wall), and while it is above (E < 0) the
reference recedes. Integrating once (docs/evidence/paper-notes.md §3) removes the derivative of the
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
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import ConstantVectorSource, Multiplexer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.force_axes import check_axes, per_axis
from admittance.systems.law_integral import AddLawIntegral

__all__ = ["OptimalAdmittance", "OptimalAdmittanceLaw", "OptimalAdmittanceLaw_"]


class _OptimalAdmittanceLaw:
    """The law of the optimal admittance (paper eq. 10, corrected sign); see
    ``OptimalAdmittance``.

    For each force-controlled axis i (an index into the task vector X):

        E_i = desired_force_i - measured_force_i
        Xr_i = gamma_i * stiffness_i * (z_i + alpha_i * (E_i - E0_i))
        dz_i/dt = E_i

    and Xr = 0 on the other axes, with the safety terms of ``OptimalAdmittance``.

    The law reads its inputs as one vector ``law_input``, gathered by a Multiplexer in
    ``OptimalAdmittance`` (one port read instead of four, each about 0.5 us): the desired
    forces Fr (one per force axis), the measured forces Fm, the initial force errors E0
    and, for the continuous law, the integrals z.

    Continuous (``period`` 0): memoryless; the one output ``reference_offset_and_rate``
    = [Xr (num_axes); dz/dt (one per force axis)] is computed in one calc. Sampled
    (``period`` > 0): z and the held Xr are discrete states; at each sample Xr is
    latched and z advances by period * dz/dt; the output ``reference_offset`` reads the
    held Xr (a state output port).

    .. pydrake_system::

        name: OptimalAdmittanceLaw
        input_ports:
        - law_input
        output_ports:
        - reference_offset_and_rate (continuous) or reference_offset (sampled)
    """

    def _construct(
        self,
        *,
        gamma: float | Sequence[float],
        alpha: float | Sequence[float],
        stiffness: float | Sequence[float],
        force_axes: Sequence[int],
        num_axes: int,
        period: float,
        max_push: float | Sequence[float],
        max_retract: float | Sequence[float],
        max_force: float | Sequence[float],
        force_bound_gain: float,
        converter=None,
    ) -> None:
        """The arguments of ``OptimalAdmittance``, every one given."""
        LeafSystem_[self._T].__init__(self, converter=converter)
        axes = check_axes(force_axes, num_axes)
        if not (np.isfinite(period) and period >= 0):
            raise ValueError(f"period must be >= 0 s (0 = continuous), got {period}")
        size = len(axes)
        self._axes = axes
        self._size = size
        self._num_axes = int(num_axes)
        self._period = float(period)
        self._gamma = per_axis("gamma", gamma, size, allow_zero=False)
        self._alpha = per_axis("alpha", alpha, size, allow_zero=True)
        self._stiffness = per_axis("stiffness", stiffness, size, allow_zero=False)
        self._max_push = np.broadcast_to(np.asarray(max_push, dtype=float), (size,)).copy()
        self._max_retract = np.broadcast_to(np.asarray(max_retract, dtype=float), (size,)).copy()
        for name, bound in (("max_push", self._max_push), ("max_retract", self._max_retract)):
            if np.any(np.isnan(bound)) or np.any(bound <= 0):
                raise ValueError(f"{name} must be > 0 m, got {bound.tolist()}")
        self._max_force = np.broadcast_to(np.asarray(max_force, dtype=float), (size,)).copy()
        if np.any(np.isnan(self._max_force)) or np.any(self._max_force <= 0):
            raise ValueError(f"max_force must be > 0 N, got {self._max_force.tolist()}")
        if not (math.isfinite(force_bound_gain) and force_bound_gain > 0):
            raise ValueError(f"force_bound_gain must be > 0, got {force_bound_gain}")
        self._force_bound_gain = float(force_bound_gain)
        self._bounded = np.isfinite(self._max_force).tolist()
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
        self._max_force_list = self._max_force.tolist()

        inputs = 3 if self._period > 0.0 else 4
        self.law_input = self.DeclareVectorInputPort("law_input", inputs * size)
        if self._period == 0.0:
            self.reference_offset_and_rate_output = self.DeclareVectorOutputPort(
                "reference_offset_and_rate",
                self._num_axes + size,
                self._CalcLaw,
                prerequisites_of_calc={self.law_input.ticket()},
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
        _OptimalAdmittanceLaw._construct(self, **other.arguments, converter=converter)

    # --- accessors -------------------------------------------------------------------
    @property
    def arguments(self) -> dict:
        """The constructor's arguments (for a copy, or another scalar type)."""
        return dict(
            gamma=self._gamma,
            alpha=self._alpha,
            stiffness=self._stiffness,
            force_axes=self._axes,
            num_axes=self._num_axes,
            period=self._period,
            max_push=self._max_push,
            max_retract=self._max_retract,
            max_force=self._max_force,
            force_bound_gain=self._force_bound_gain,
        )

    @property
    def force_axes(self) -> list[int]:
        return list(self._axes)

    @property
    def period(self) -> float:
        return self._period

    @property
    def proportional_gain(self) -> np.ndarray:
        return self._proportional_gain.copy()

    @property
    def integral_gain(self) -> np.ndarray:
        return self._integral_gain.copy()

    def set_integral(self, context, integral) -> None:
        """Sets z in this system's context (the sampled law's discrete state)."""
        if self._period == 0.0:
            raise ValueError("the continuous law's integral is its input, not its state")
        context.SetDiscreteState(self._state_index, np.atleast_1d(integral))

    # --- the law ----------------------------------------------------------------------
    def _law(self, values, integral):
        """(Xr on every axis of X, dz/dt per force axis) as lists of Python scalars.

        `values` holds [Fr; Fm; E0] (each one entry per force axis; z may follow, unused
        here), `integral` z; floats, or AutoDiffXd after conversion.
        """
        T = self._T
        size = self._size
        gains, alphas = self._integral_gain_list, self._alpha_list
        offsets = [T(0.0)] * self._num_axes
        rates = []
        for i in range(size):
            desired, measured = values[i], values[size + i]
            measured_value = measured if T is float else measured.value()
            # A reading that is not finite (a broken sensor) gives E = 0: the integral
            # freezes and Xr holds its settled value until the sensor recovers.
            error = desired - measured if math.isfinite(measured_value) else T(0.0)
            if self._bounded[i]:
                guard = 0.5 * (desired + self._max_force_list[i])
                # (NaN compares False: a broken reading adds no penalty.)
                if measured_value > (guard if T is float else guard.value()):
                    # The force-bound penalty: E_b = E - mu (F - Fg).
                    error = error - self._force_bound_gain * (measured - guard)
            offset = gains[i] * (integral[i] + alphas[i] * (error - values[2 * size + i]))
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
            offsets[self._axes[i]] = offset
            rates.append(rate)
        return offsets, rates

    def _CalcLaw(self, context, output) -> None:
        values = self.law_input.Eval(context).tolist()  # floats, or AutoDiffXd objects
        offsets, rates = self._law(values, values[3 * self._size :])
        output.SetFromVector(offsets + rates)

    def _DiscreteUpdate(self, context, discrete_state) -> None:
        values = self.law_input.Eval(context).tolist()  # floats, or AutoDiffXd objects
        integral = context.get_discrete_state(self._state_index).CopyToVector()
        offsets, rates = self._law(values, integral.tolist())
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(
            integral + self._period * np.array(rates)
        )
        discrete_state.get_mutable_vector(self._held_index).SetFromVector(offsets)


@TemplateSystem.define("OptimalAdmittanceLaw_", T_list=[float, AutoDiffXd])
def OptimalAdmittanceLaw_(T):
    class Impl(_OptimalAdmittanceLaw, LeafSystem_[T]):
        __doc__ = _OptimalAdmittanceLaw.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _OptimalAdmittanceLaw._construct
        _construct_copy = _OptimalAdmittanceLaw._construct_copy

    return Impl


OptimalAdmittanceLaw = OptimalAdmittanceLaw_[None]


class OptimalAdmittance(Diagram):
    """Optimal admittance (paper eq. 10 with the corrected sign), one integrator per axis.

    For each force-controlled axis i (an index into the task vector X):

        E_i = desired_force_i - measured_force_i
        dz_i/dt = E_i
        Xr_i = gamma_i * stiffness_i * (z_i + alpha_i * (E_i - E0_i))

    and Xr = 0 on the other axes. ``stiffness`` is K of eq. 5 and 10: the Cartesian
    stiffness of the position-controlled arm, i.e. the PID's Kp on that axis. E0 is the
    force error at t = 0 (see ``set_initial_force_error``) so that Xr(0) = 0.

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

    Inside: the law (``OptimalAdmittanceLaw``, named ``law``, the only Python), its inputs
    gathered by ``inputs`` (a ``Multiplexer``) with E0 from ``initial_force_error`` (a
    ``ConstantVectorSource`` whose value lives in the context) and, for the continuous law,
    z from ``integral`` (Drake's ``Integrator``) fed with dz/dt through ``split`` (a
    ``Demultiplexer`` of the law's [Xr; dz/dt]). Each derivative evaluation of a closed
    loop then calls the block's Python once (a LeafSystem with its own continuous state
    needs three: the law, its output and its derivatives).

    .. pydrake_system::

        name: OptimalAdmittance
        input_ports:
        - measured_force
        - desired_force
        output_ports:
        - reference_offset
    """

    def __init__(
        self,
        *,
        gamma: float | Sequence[float],
        alpha: float | Sequence[float],
        stiffness: float | Sequence[float],
        force_axes: Sequence[int],
        num_axes: int,
        period: float = 0.0,
        max_push: float | Sequence[float] = math.inf,
        max_retract: float | Sequence[float] = math.inf,
        max_force: float | Sequence[float] = math.inf,
        force_bound_gain: float = 4.0,
    ) -> None:
        """
        Args:
            gamma: Gamma of eq. 10 per force-controlled axis (> 0), m/(N s) per unit K.
            alpha: weight of dE/dt in the cost of eq. 7, per axis (>= 0), s.
            stiffness: K of eq. 10 per axis (> 0): the PID's Kp on that axis, N/m.
            force_axes: indices of the force-controlled axes in X.
            num_axes: size of the reference offset output (the size of X).
            period: 0 for the continuous law, otherwise the sampling period in s.
            max_push: the largest Xr along +axis (into the wall), m (> 0; inf = none).
            max_retract: the largest Xr along -axis (away from the wall), m (> 0).
            max_force: Fmax, the upper bound on the measured force per axis, N (> 0;
                inf = no bound).
            force_bound_gain: mu, the weight of the force-bound penalty in I_b (> 0).
        """
        Diagram.__init__(self)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem(
            "law",
            OptimalAdmittanceLaw(
                gamma=gamma,
                alpha=alpha,
                stiffness=stiffness,
                force_axes=force_axes,
                num_axes=num_axes,
                period=period,
                max_push=max_push,
                max_retract=max_retract,
                max_force=max_force,
                force_bound_gain=force_bound_gain,
            ),
        )
        self._law = law
        size = len(law.force_axes)
        continuous = law.period == 0.0
        inputs = builder.AddNamedSystem("inputs", Multiplexer([size] * (4 if continuous else 3)))
        # The measured force first: the port indices of the LeafSystem this block was.
        builder.ExportInput(inputs.get_input_port(1), "measured_force")
        builder.ExportInput(inputs.get_input_port(0), "desired_force")
        initial = builder.AddNamedSystem(
            "initial_force_error", ConstantVectorSource(np.zeros(size))
        )
        builder.Connect(initial.get_output_port(), inputs.get_input_port(2))
        builder.Connect(inputs.get_output_port(), law.law_input)
        self._initial_force_error = initial
        self._integrator = None
        if continuous:
            self._integrator = AddLawIntegral(
                builder,
                law.reference_offset_and_rate_output,
                inputs.get_input_port(3),
                "reference_offset",
            )
        else:
            builder.ExportOutput(law.reference_offset_output, "reference_offset")
        builder.BuildInto(self)
        self.measured_force_input = self.GetInputPort("measured_force")
        self.desired_force_input = self.GetInputPort("desired_force")
        self.reference_offset_output = self.GetOutputPort("reference_offset")

    # --- accessors -----------------------------------------------------------------------
    @property
    def law(self) -> OptimalAdmittanceLaw:
        return self._law

    @property
    def force_axes(self) -> list[int]:
        return self._law.force_axes

    @property
    def period(self) -> float:
        return self._law.period

    @property
    def proportional_gain(self) -> np.ndarray:
        """Gamma K alpha per axis, m/N: the direct reaction of Xr to a force change."""
        return self._law.proportional_gain

    @property
    def integral_gain(self) -> np.ndarray:
        """Gamma K per axis, m/(N s): the rate of Xr per newton of force error."""
        return self._law.integral_gain

    def set_initial_force_error(self, context, initial_force_error) -> None:
        """Sets E(0), so that Xr(0) = 0 (usually desired - measured force at t = 0).

        Args:
            context: this block's context (``GetMyMutableContextFromRoot`` in a diagram).
            initial_force_error: E0, one value per force axis.
        """
        source = self._initial_force_error
        source.get_mutable_source_value(
            self.GetMutableSubsystemContext(source, context)
        ).SetFromVector(np.atleast_1d(initial_force_error))

    def set_integral(self, context, integral) -> None:
        """Sets z, the integral of the force error (for a warm start or an analysis).

        Args:
            context: this block's context (``GetMyMutableContextFromRoot`` in a diagram).
            integral: z, one value per force axis.
        """
        integral = np.atleast_1d(integral)
        if self._integrator is not None:
            self._integrator.set_integral_value(
                self.GetMutableSubsystemContext(self._integrator, context), integral
            )
        else:
            self._law.set_integral(self.GetMutableSubsystemContext(self._law, context), integral)
