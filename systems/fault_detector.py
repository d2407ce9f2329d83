"""A monitor of the force reading: what may be trusted, and which fault it shows.

It checks the reading r at each ADC sample (period T, the sensor's sample period) and
passes on a trusted force: r while r is trusted, else the last trusted reading (held).
Four kinds of fault, each one flag of ``fault_flags``:

* ``nonfinite`` (instant): r is NaN or infinite (a broken cable, an ADC error);
* ``saturated`` (instant): r >= 98 % of the sensor's full scale (the op-amp at its rail:
  the true force may be anything above);
* ``stuck`` (after N_s = 3 samples): the reading does not vary while it must, i.e.
  |r[k] - r[k-1]| < sigma / 100 while the sensor's noise sigma is expected (a change that
  small has a chance of 0.56 % per sample for Gaussian noise, so three in a row once in
  5.7e6 samples), or r is unchanged while the tip moves in contact fast enough that the
  stiffness estimate predicts a change beyond the tolerance (k_hat |x'| T > F_tol);
* ``implausible`` (after N_i = 3 samples): r disagrees with the arm's own estimate of the
  contact force F_hat (the momentum observer, systems/contact_force_observer.py, which uses
  the measured motion and the applied torques) by more than
  F_tol + (|r[k] - r[k-1]| + |F_hat[k] - F_hat[k-1]|) / (T K_o): the observer follows the
  force through the lag 1 / K_o (dF_hat/dt = K_o (F - F_hat)), so the true force is
  F_hat + F_hat' / K_o; the allowance is that lag seen in the observer's own rate, plus the
  reading's rate, which covers the one-sample difference quotient's lag behind F_hat' at
  an impact (docs/evidence/safety-sensor-faults.md section 3 derives it). A tip following a moving
  wall at a
  constant force moves without changing F_hat, so the wall's speed does not widen it.

A fifth flag, ``collision`` (after N_c = 3 samples, latched to the end of the run), is not
a sensor fault: the observer's residual r (the external joint torque, N m) has a part that
no fingertip force along the normal can produce. Such a force gives r = -F j, j = J_x^T
(the normal row of the fingertip's Jacobian), whatever the reading says; so

    r_perp = r - j (j . r) / (j . j)

is zero for any contact force and any sensor fault (a fault changes the reading, never r),
and a torque on a link shows in it. Evidence: |r_perp| > |j| F_tol, the norm of the torque
that a fingertip force error at the plausibility check's base tolerance F_tol makes
(docs/evidence/safety-collision.md, "The collision reflex", derives it). While there is evidence of
a
collision, or once one is flagged, the plausibility check takes no evidence (F_hat then
carries the collision's torque, not the contact force), and once one is flagged the stuck
check's contact is the reading's alone. ``sensor_fault`` ignores it; the
``collision`` output is its flag. Without a value on the ``external_torque`` input there
is no collision check.

A detected stuck or implausible reading stays flagged until N_r = 4 samples in a row show
no evidence of it. The held value is the reading of the sample before the first sample of
evidence, so a fault caught after N samples leaves no trace in it. The ``sensor_fault``
output is 1 while any flag is set.

At an analysis equilibrium there is no fault: with ``frozen`` the block has no state and
passes the reading on (trusted_force = measured_force, no flag).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.collision_check import contact_torque_check
from admittance.systems.contact_frame import ContactFrame

__all__ = [
    "FAULT_FLAGS",
    "FaultDetectorParams",
    "SensorFaultDetector",
    "SensorFaultDetector_",
    "detection_delay",
    "plausibility_allowance",
]

#: The kinds of fault, in the order of the ``fault_flags`` output.
FAULT_FLAGS = ("nonfinite", "saturated", "stuck", "implausible")

# Samples of evidence before a stuck / implausible reading is flagged, and without
# evidence before the flag clears.
STUCK_SAMPLES = 3
IMPLAUSIBLE_SAMPLES = 3
COLLISION_SAMPLES = 3
CLEAR_SAMPLES = 4
# A reading at or above this share of full scale is saturated.
SATURATED_SHARE = 0.98
# A change below sigma / UNCHANGED_NOISE_SHARE counts as no change (noise expected).
UNCHANGED_NOISE_SHARE = 100.0
# ... and below this without noise, N.
UNCHANGED_FORCE = 1e-9

# Discrete state layout.
_PREVIOUS, _STUCK, _IMPLAUSIBLE, _CLEAR_STUCK, _CLEAR_IMPLAUSIBLE = 0, 1, 2, 3, 4
_STUCK_FLAG, _IMPLAUSIBLE_FLAG, _HELD = 5, 6, 7
_COLLISION, _COLLISION_FLAG = 8, 9
_PREVIOUS_OBSERVED = 10
_STATE_SIZE = 11


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


def detection_delay(period: float) -> float:
    """The monitor's longest delay from a fault's onset to its flag at the sample period
    `period`, s: N + 1 samples."""
    return (max(STUCK_SAMPLES, IMPLAUSIBLE_SAMPLES) + 1) * period


@dataclass(frozen=True)
class FaultDetectorParams:
    """The monitor's numbers (``SensorFaultDetector``).

    Attributes:
        period: T, the sample period of the reading (the ADC's), s.
        noise_std: sigma, the noise expected on the reading, N (0 = none).
        saturation_force: the sensor's full scale, N.
        contact_force: F_c, the force above which the tip is in contact, N.
        force_tolerance: F_tol, the base tolerance of the plausibility check, N.
        observer_gain: K_o of the force observer, 1/s.
        frozen: no state, no check (analysis diagrams).
        contact_axes: the indices in X of the forces a contact at the frame can make,
            which the collision check takes as explained (None: the normal alone, a
            frictionless contact; a tool on a table with friction: its x, y and z).
    """

    period: float
    noise_std: float
    saturation_force: float
    contact_force: float
    force_tolerance: float
    observer_gain: float
    frozen: bool = False
    contact_axes: tuple[int, ...] | None = None

    @property
    def detection_delay(self) -> float:
        """The longest delay from a fault's onset to its flag, s: N + 1 samples."""
        return detection_delay(self.period)


def plausibility_allowance(
    reading_change: float, observed_change: float, period: float, observer_gain: float
) -> float:
    """The plausibility check's allowance beyond F_tol, N: (|dr| + |dF_hat|) / (T K_o), the
    observer's lag F_hat' / K_o seen in its own change over the last sample, plus the
    reading's (docs/evidence/safety-sensor-faults.md section 3)."""
    return (abs(reading_change) + abs(observed_change)) / (period * observer_gain)


def _check(params: FaultDetectorParams) -> None:
    """Raises ValueError naming the first of the monitor's numbers out of its range."""
    for name in ("period", "saturation_force", "contact_force", "force_tolerance", "observer_gain"):
        value = getattr(params, name)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be > 0, got {value}")
    if not (math.isfinite(params.noise_std) and params.noise_std >= 0):
        raise ValueError(f"noise_std must be >= 0 N, got {params.noise_std}")


class _SensorFaultDetector:
    """Sampled monitor of the force reading (module docstring).

    State (discrete, updated every `period`): previous reading, evidence counters,
    the stuck and implausible flags, the held force, the collision's count and flag,
    the previous observer estimate.

    .. pydrake_system::

        name: SensorFaultDetector
        input_ports:
        - measured_force
        - observed_force
        - stiffness_estimate
        - estimated_state
        - external_torque
        output_ports:
        - trusted_force
        - sensor_fault
        - fault_flags
        - collision
    """

    def _construct(
        self,
        plant,
        *,
        contact: ContactFrame,
        params: FaultDetectorParams,
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] of the arm.
            contact: the contact frame, its task vector X and the normal's index in X.
            params: the monitor's numbers.
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        _check(params)
        self._plant = plant
        self._contact = contact
        self._params = params
        normal_axis = contact.normal_axis
        contact_axes = params.contact_axes
        self._contact_axes = [normal_axis] if contact_axes is None else list(contact_axes)
        self._period = float(params.period)
        self._noise_std = float(params.noise_std)
        self._saturation_force = float(params.saturation_force)
        self._contact_force = float(params.contact_force)
        self._force_tolerance = float(params.force_tolerance)
        self._observer_gain = float(params.observer_gain)
        self._normal_axis = normal_axis
        self._frozen = bool(params.frozen)
        self._kinematics = contact.kinematics(plant)
        self._num_positions = plant.num_positions()
        self._declare_ports(plant.num_positions() + plant.num_velocities())

    def _declare_ports(self, num_states: int) -> None:
        """The five inputs, the state and its update (none when frozen), the flags' cache
        and the four outputs."""
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
        self.observed_force_input = self.DeclareVectorInputPort("observed_force", 1)
        self.stiffness_estimate_input = self.DeclareVectorInputPort("stiffness_estimate", 1)
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", num_states)
        self.external_torque_input = self.DeclareVectorInputPort(
            "external_torque", self._plant.num_velocities()
        )
        reading = {self.measured_force_input.ticket()}
        if not self._frozen:
            initial = np.zeros(_STATE_SIZE)
            initial[_PREVIOUS] = math.nan
            initial[_PREVIOUS_OBSERVED] = math.nan
            self._state_index = self.DeclareDiscreteState(BasicVector_[self._T](initial))
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._Update
            )
            reading.add(self.xd_ticket())
        # The flags are computed once per context and read by the three outputs.
        self._flags_cache = self.DeclareCacheEntry(
            description="fault flags",
            value_producer=ValueProducer(
                allocate=Value[object]().Clone,
                calc=lambda context, value: value.set_value(self._flags(context)),
            ),
            prerequisites_of_calc=reading,
        )
        flags = {self._flags_cache.ticket()}
        self.trusted_force_output = self.DeclareVectorOutputPort(
            "trusted_force", 1, self._CalcTrusted, prerequisites_of_calc=reading | flags
        )
        self.sensor_fault_output = self.DeclareVectorOutputPort(
            "sensor_fault", 1, self._CalcFault, prerequisites_of_calc=flags
        )
        self.fault_flags_output = self.DeclareVectorOutputPort(
            "fault_flags", len(FAULT_FLAGS), self._CalcFlags, prerequisites_of_calc=flags
        )
        self.collision_output = self.DeclareVectorOutputPort(
            "collision",
            1,
            self._CalcCollision,
            prerequisites_of_calc={self.nothing_ticket() if self._frozen else self.xd_ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _SensorFaultDetector._construct(
            self,
            other._plant.ToScalarType[self._T](),
            contact=other._contact,
            params=other._params,
            converter=converter,
        )

    # --- accessors ---------------------------------------------------------------
    @property
    def period(self) -> float:
        return self._period

    @property
    def detection_delay(self) -> float:
        """The longest delay from a fault's onset to its flag, s: N + 1 samples."""
        return detection_delay(self._period)

    def set_reading(self, context, reading: float) -> None:
        """Starts the monitor with `reading` as the previous and held value."""
        if self._frozen:
            return
        state = np.zeros(_STATE_SIZE)
        state[_PREVIOUS] = reading
        state[_HELD] = reading
        state[_PREVIOUS_OBSERVED] = math.nan  # the observer's next sample starts its rate
        context.get_mutable_discrete_state(self._state_index).SetFromVector(state)

    # --- checks ------------------------------------------------------------------
    def _instant_flags(self, reading: float) -> tuple[bool, bool]:
        finite = math.isfinite(reading)
        return (not finite, finite and reading >= SATURATED_SHARE * self._saturation_force)

    def _flags(self, context) -> list[bool]:
        reading = _value(self.measured_force_input.Eval(context)[0])
        nonfinite, saturated = self._instant_flags(reading)
        if self._frozen:
            return [nonfinite, saturated, False, False]
        state = context.get_discrete_state(self._state_index).CopyToVector()
        return [
            nonfinite,
            saturated,
            _value(state[_STUCK_FLAG]) > 0.5,
            _value(state[_IMPLAUSIBLE_FLAG]) > 0.5,
        ]

    def _CalcFlags(self, context, output) -> None:
        output.SetFromVector([self._T(float(flag)) for flag in self._flags_cache.Eval(context)])

    def _CalcFault(self, context, output) -> None:
        output.SetFromVector([self._T(float(any(self._flags_cache.Eval(context))))])

    def _CalcCollision(self, context, output) -> None:
        T = self._T
        if self._frozen:
            output.SetFromVector([T(0.0)])
            return
        state = context.get_discrete_state(self._state_index).CopyToVector()
        output.SetFromVector([T(float(_value(state[_COLLISION_FLAG]) > 0.5))])

    def _CalcTrusted(self, context, output) -> None:
        reading = self.measured_force_input.Eval(context)[0]
        if self._frozen or not any(self._flags_cache.Eval(context)):
            output.SetFromVector([reading])
            return
        held = context.get_discrete_state(self._state_index).CopyToVector()[_HELD]
        output.SetFromVector([held])

    def _Update(self, context, discrete_state) -> None:
        T = self._T
        state = [_value(x) for x in context.get_discrete_state(self._state_index).CopyToVector()]
        reading = _value(self.measured_force_input.Eval(context)[0])
        nonfinite, saturated = self._instant_flags(reading)
        previous = state[_PREVIOUS]
        observed = _value(self.observed_force_input.Eval(context)[0])
        previous_observed = state[_PREVIOUS_OBSERVED]
        state[_PREVIOUS_OBSERVED] = observed
        if nonfinite or saturated or not math.isfinite(previous):
            # No evidence either way; the held value stays.
            state[_PREVIOUS] = reading if not (nonfinite or saturated) else previous
            if not math.isfinite(previous) and not (nonfinite or saturated):
                state[_HELD] = reading
            discrete_state.get_mutable_vector(self._state_index).SetFromVector(
                [T(x) for x in state]
            )
            return
        change = abs(reading - previous)
        observed_change = observed - previous_observed if math.isfinite(previous_observed) else 0.0
        jacobian, velocity = self._sample_jacobian(context)
        speed = abs((jacobian @ velocity)[self._normal_axis])
        stuck_evidence = self._stuck_evidence(context, state, reading, observed, change, speed)
        allowance = plausibility_allowance(
            change, observed_change, self._period, self._observer_gain
        )
        implausible_evidence = abs(reading - observed) > self._force_tolerance + allowance
        collision_evidence = self._collision_evidence(context, jacobian)
        _count_collision(state, collision_evidence)
        if collision_evidence or state[_COLLISION_FLAG] > 0.5:
            implausible_evidence = False
        _count_faults(state, stuck_evidence, implausible_evidence)
        clean = (
            state[_STUCK] == 0
            and state[_IMPLAUSIBLE] == 0
            and state[_STUCK_FLAG] == 0
            and state[_IMPLAUSIBLE_FLAG] == 0
        )
        if clean:
            # The previous sample: a fault caught at this sample has not reached it.
            state[_HELD] = previous
        state[_PREVIOUS] = reading
        discrete_state.get_mutable_vector(self._state_index).SetFromVector([T(x) for x in state])

    def _sample_jacobian(self, context):
        """(J, v) as float arrays at the sample's plant state (its values, for AutoDiffXd)."""
        T = self._T
        plant_state = self.estimated_state_input.Eval(context)
        if T is float:  # every sample of a run: no conversion element by element
            self._kinematics.set_state(plant_state)
            velocity = plant_state[self._num_positions :]
            jacobian = np.asarray(self._kinematics.jacobian(), dtype=float)
        else:  # the values of an AutoDiffXd diagram's sample
            self._kinematics.set_state(np.array([T(_value(x)) for x in plant_state]))
            velocity = np.array([_value(x) for x in plant_state[self._num_positions :]])
            jacobian = np.array([[_value(x) for x in row] for row in self._kinematics.jacobian()])
        return jacobian, velocity

    def _stuck_evidence(self, context, state, reading, observed, change, speed) -> bool:
        """Whether the reading did not vary while it must: below the noise's least change
        (noise expected), or unchanged in contact while k_hat |x'| T passes F_tol."""
        stiffness = _value(self.stiffness_estimate_input.Eval(context)[0])
        predicted_rate = stiffness * speed
        if self._noise_std > 0:
            unchanged = change < self._noise_std / UNCHANGED_NOISE_SHARE
            stuck_evidence = unchanged
        else:
            unchanged = change < UNCHANGED_FORCE
            stuck_evidence = False
        collided = state[_COLLISION_FLAG] > 0.5  # F_hat then carries the collision's torque
        in_contact = reading >= self._contact_force or (
            observed >= self._contact_force and not collided
        )
        if unchanged and in_contact:
            stuck_evidence = stuck_evidence or (
                predicted_rate * self._period > self._force_tolerance
            )
        return stuck_evidence

    def _collision_evidence(self, context, jacobian) -> bool:
        """Whether the observer's residual has more than F_tol's torque that no force of the
        contact axes explains (False without a value on ``external_torque``)."""
        if not self.external_torque_input.HasValue(context):
            return False
        residual = [_value(x) for x in self.external_torque_input.Eval(context)]
        rows = jacobian[self._contact_axes]
        if len(self._contact_axes) == 1:
            rows = rows[0]
        unexplained, tolerance = contact_torque_check(residual, rows, self._force_tolerance)
        return unexplained > tolerance


def _count_collision(state: list, evidence: bool) -> None:
    """The collision's count of samples with evidence, and its flag, latched once set."""
    if evidence:
        state[_COLLISION] += 1
        if state[_COLLISION] >= COLLISION_SAMPLES:
            state[_COLLISION_FLAG] = 1.0  # latched
    else:
        state[_COLLISION] = 0


def _count_faults(state: list, stuck_evidence: bool, implausible_evidence: bool) -> None:
    """The stuck and implausible counts and flags: set after N samples of evidence,
    cleared after CLEAR_SAMPLES without."""
    for evidence, count, clear, flag, needed in (
        (stuck_evidence, _STUCK, _CLEAR_STUCK, _STUCK_FLAG, STUCK_SAMPLES),
        (
            implausible_evidence,
            _IMPLAUSIBLE,
            _CLEAR_IMPLAUSIBLE,
            _IMPLAUSIBLE_FLAG,
            IMPLAUSIBLE_SAMPLES,
        ),
    ):
        if evidence:
            state[count] += 1
            state[clear] = 0
            if state[count] >= needed:
                state[flag] = 1.0
        else:
            state[count] = 0
            state[clear] += 1
            if state[clear] >= CLEAR_SAMPLES:
                state[flag] = 0.0


@TemplateSystem.define("SensorFaultDetector_", T_list=[float, AutoDiffXd])
def SensorFaultDetector_(T):
    class Impl(_SensorFaultDetector, LeafSystem_[T]):
        __doc__ = _SensorFaultDetector.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _SensorFaultDetector._construct
        _construct_copy = _SensorFaultDetector._construct_copy

    return Impl


SensorFaultDetector = SensorFaultDetector_[None]
