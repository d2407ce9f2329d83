"""An online estimate of the contact stiffness from the measured force and the tip's motion.

No model of the wall: only the trusted force reading F (systems/fault_detector.py) and the
fingertip's own position x along the wall normal, from the plant's state, sampled at the
sensor's sample period T. For the linear spring of eq. 4 on a static wall every two points
in contact lie on one line, F = Ke (x - Xe), so their secant slope is Ke, whatever Xe is:

    k_obs = (F[k] - F_a) / (x[k] - x_a),

with (x_a, F_a) an anchor sample in contact (F >= F_c). The secant is taken only when
the force has moved far from the anchor, |F[k] - F_a| >= dF_min (so the reading's noise
is a small share of it), and only if force and position moved the same way (a spring
pushes back harder when pressed deeper); then the sample becomes the new anchor. The
anchor is dropped in free motion and while the reading is not trusted.

The estimate moves toward k_obs in log scale (the stiffness spans decades):

    ln k_hat <- ln k_hat + g (ln k_obs - ln k_hat),

g = 1 toward a stiffer wall, with k_obs limited to 2 k_hat per sample (a stiffness jump at
fixed penetration shows a force step with almost no motion: its secant is meaningless,
and the next samples, as the law backs off, show the new slope), and g = 3/4 toward a
softer one, but only during the loading that follows a contact's onset (the first
`loading_time`, 0.5 s): its three or four informative samples bring the prior to within
(1/4)^3 of the wall's log-distance from it. Later in a contact the estimate only rises: a
wall that moves while in contact adds its travel to x - x_a without a force change, so
the secant of a later loading (a receding wall that stops) would be biased low, the unsafe
way. Before any contact k_hat is the prior, the scenario's upper bound on the wall's
stiffness: the gains are the most cautious until the wall has shown how soft it is.

In an analysis diagram the estimate is frozen (``frozen_estimate``): no state, the
constant as output, as the gain schedule is frozen at an equilibrium.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.contact_frame import ContactFrame

__all__ = ["StiffnessEstimator", "StiffnessEstimatorParams", "StiffnessEstimator_"]

# Per-sample gains of the log-scale update toward a stiffer and a softer observation, and
# the largest step toward a stiffer one (a factor).
GAIN_UP = 1.0
GAIN_DOWN = 0.75
MAX_RISE = 2.0

# How long after a contact's onset the estimate may fall, s.
LOADING_TIME = 0.5

# Discrete state layout: ln k_hat, anchor position, anchor force, the contact's onset
# time, anchored (0/1), ln of the highest estimate so far, in free motion (0/1).
_LOG_ESTIMATE, _ANCHOR_POSITION, _ANCHOR_FORCE, _ONSET, _ANCHORED, _LOG_TOP, _FREE = range(7)


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be > 0, got {value}")
    return float(value)


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


@dataclass(frozen=True)
class StiffnessEstimatorParams:
    """The estimator's numbers (``StiffnessEstimator``).

    Attributes:
        period: T, the sample period (the sensor's), s.
        prior_stiffness: k_prior, the estimate before any contact, N/m.
        contact_force: F_c, the threshold of contact, N.
        informative_force: dF_min, N.
        frozen_estimate: None, or a constant estimate (N/m) for analysis.
        latch_stiffness: once the estimate has been above it (a wall stiffer than
            stated), it never falls below the highest value it reached, N/m.
    """

    period: float
    prior_stiffness: float
    contact_force: float
    informative_force: float
    frozen_estimate: float | None = None
    latch_stiffness: float = math.inf


def update_estimate(
    log_estimate: float,
    anchor: tuple[float, float, float] | None,
    position: float,
    force: float,
    time: float,
    *,
    contact_force: float,
    informative_force: float,
    trusted: bool = True,
    contact_start: float = -math.inf,
    floor: float = -math.inf,
) -> tuple[float, tuple[float, float, float] | None]:
    """One sample of the estimator (module docstring): the new (ln k_hat, anchor).

    Args:
        log_estimate: ln k_hat before the sample.
        anchor: (x_a, F_a, the contact's onset time), or None when there is none.
        position: x[k], m; force: F[k], N; time: t[k], s.
        contact_start: the ln k_hat a contact starts from, at least: applied on the
            sample that anchors a new contact (the caller passes it after free motion).
        floor: the ln k_hat below which the estimate may not fall.
        contact_force: F_c; informative_force: dF_min, N.
        trusted: the reading may be used.
    """
    if not (trusted and math.isfinite(force)) or force < contact_force:
        return log_estimate, None
    if anchor is None:
        return max(log_estimate, contact_start), (position, force, time)
    onset = anchor[2]
    force_change = force - anchor[1]
    if abs(force_change) < informative_force:
        return log_estimate, anchor
    position_change = position - anchor[0]
    if force_change * position_change > 0:
        log_observed = math.log(force_change / position_change)
        if log_observed > log_estimate:
            limited = min(log_observed, log_estimate + math.log(MAX_RISE))
            log_estimate += GAIN_UP * (limited - log_estimate)
        elif time - onset <= LOADING_TIME:
            log_estimate += GAIN_DOWN * (log_observed - log_estimate)
            log_estimate = max(log_estimate, floor)
    return log_estimate, (position, force, onset)


class _StiffnessEstimator:
    """Sampled secant stiffness between anchor samples in contact (module docstring).

    State (discrete, period T): [ln k_hat, x_a, F_a, onset, anchored]. Output: k_hat, N/m.

    .. pydrake_system::

        name: StiffnessEstimator
        input_ports:
        - measured_force
        - estimated_state
        - sensor_fault
        output_ports:
        - stiffness_estimate
    """

    def _construct(
        self,
        plant,
        *,
        contact: ContactFrame,
        params: StiffnessEstimatorParams,
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] of the arm.
            contact: the contact frame, its task vector X and the normal's index in X.
            params: the estimator's numbers.
        """
        T = self._T
        LeafSystem_[T].__init__(self, converter=converter)
        self._plant = plant
        self._contact = contact
        self._params = params
        if not params.latch_stiffness > 0:
            raise ValueError(f"latch_stiffness must be > 0, got {params.latch_stiffness}")
        self._latch = math.log(params.latch_stiffness)
        self._period = _positive("period", params.period)
        self._prior = _positive("prior_stiffness", params.prior_stiffness)
        self._contact_force = _positive("contact_force", params.contact_force)
        self._informative_force = _positive("informative_force", params.informative_force)
        self._normal_axis = contact.normal_axis
        frozen = params.frozen_estimate
        self._frozen = None if frozen is None else _positive("frozen_estimate", frozen)
        self._kinematics = contact.kinematics(plant)
        nx = plant.num_positions() + plant.num_velocities()
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", nx)
        self.sensor_fault_input = self.DeclareVectorInputPort("sensor_fault", 1)
        if self._frozen is None:
            self._state_index = self.DeclareDiscreteState(
                BasicVector_[T](self._initial_state(self._prior))
            )
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._Update
            )
            calc, ticket = self._CalcEstimate, self.xd_ticket()
        else:
            calc, ticket = self._CalcFrozen, self.nothing_ticket()
        self.stiffness_estimate_output = self.DeclareVectorOutputPort(
            "stiffness_estimate", 1, calc, prerequisites_of_calc={ticket}
        )

    def _construct_copy(self, other, converter=None) -> None:
        _StiffnessEstimator._construct(
            self,
            other._plant.ToScalarType[self._T](),
            contact=other._contact,
            params=other._params,
            converter=converter,
        )

    @property
    def prior_stiffness(self) -> float:
        return self._prior

    @property
    def contact_force(self) -> float:
        return self._contact_force

    def set_estimate(self, context, stiffness: float) -> None:
        """Sets k_hat (N/m) and drops the anchor; the next contact starts from it."""
        state = self._initial_state(_positive("stiffness", stiffness))
        state[_FREE] = 0.0
        context.get_mutable_discrete_state(self._state_index).SetFromVector(state)

    def _initial_state(self, stiffness: float) -> list[float]:
        log_stiffness = math.log(stiffness)
        top = max(log_stiffness, math.log(self._prior))
        return [log_stiffness, 0.0, 0.0, 0.0, 0.0, top, 1.0]

    def _CalcFrozen(self, context, output) -> None:
        output.SetFromVector([self._T(self._frozen)])

    def _CalcEstimate(self, context, output) -> None:
        log_estimate = context.get_discrete_state(self._state_index).CopyToVector()[0]
        output.SetFromVector([self._T(math.exp(_value(log_estimate)))])

    def _Update(self, context, discrete_state) -> None:
        T = self._T
        state = [_value(x) for x in context.get_discrete_state(self._state_index).CopyToVector()]
        force = _value(self.measured_force_input.Eval(context)[0])
        trusted = _value(self.sensor_fault_input.Eval(context)[0]) < 0.5
        plant_state = self.estimated_state_input.Eval(context)
        self._kinematics.set_state(
            plant_state if T is float else np.array([T(_value(x)) for x in plant_state])
        )
        position = _value(self._kinematics.pose()[self._normal_axis])
        anchor = (
            (state[_ANCHOR_POSITION], state[_ANCHOR_FORCE], state[_ONSET])
            if state[_ANCHORED]
            else None
        )
        # A new contact after free motion starts from the highest estimate so far (at
        # least the prior): a fall belongs to the contact that showed it. Above the
        # latch, the estimate keeps the highest value it reached.
        top = state[_LOG_TOP]
        log_estimate, anchor = update_estimate(
            state[_LOG_ESTIMATE],
            anchor,
            position,
            force,
            _value(context.get_time()),
            contact_force=self._contact_force,
            informative_force=self._informative_force,
            trusted=trusted,
            contact_start=top if state[_FREE] else -math.inf,
            floor=top if top > self._latch else -math.inf,
        )
        free = trusted and math.isfinite(force) and force < self._contact_force
        if not (free or anchor):
            free = bool(state[_FREE])  # an untrusted reading says nothing of contact
        new = [
            log_estimate,
            *(anchor if anchor else (0.0, 0.0, 0.0)),
            float(bool(anchor)),
            max(top, log_estimate),
            float(free),
        ]
        discrete_state.get_mutable_vector(self._state_index).SetFromVector([T(x) for x in new])


@TemplateSystem.define("StiffnessEstimator_", T_list=[float, AutoDiffXd])
def StiffnessEstimator_(T):
    class Impl(_StiffnessEstimator, LeafSystem_[T]):
        __doc__ = _StiffnessEstimator.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _StiffnessEstimator._construct
        _construct_copy = _StiffnessEstimator._construct_copy

    return Impl


StiffnessEstimator = StiffnessEstimator_[None]
