"""The safety layer's four systems at one force point, built and wired alike on every
robot (docs/evidence/safety.md): the momentum observer, the sensor monitor, the stiffness
estimator and the safe law. Each robot's layer (robots.planar_arm.safety_layer for the planar arm,
robots.spatial_arm.safety_layer for a spatial arm's tool tip) says what is its own through
``LayerNumbers`` and wires the reading, Fr, Xd and the law's Xr.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.systems.framework import DiagramBuilder

from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import (
    FaultDetectorParams,
    SensorFaultDetector,
    detection_delay,
)
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.safety_numbers import SafeAdmittanceParams
from admittance.systems.stiffness_estimator import StiffnessEstimator, StiffnessEstimatorParams

__all__ = [
    "AddLayerSystems",
    "CONTACT_NOISE_DEVIATIONS",
    "CONTACT_SHARE",
    "INFORMATIVE_SHARE",
    "LayerNumbers",
    "OBSERVER_GAIN",
    "STIFFER_FACTOR",
    "TOLERANCE_NOISE_DEVIATIONS",
    "TOLERANCE_SHARE",
    "detector_params",
    "estimator_params",
    "law_params",
]

# The force observer's bandwidth, 1/s: 10 ms, two ADC samples at the default 5 ms.
OBSERVER_GAIN = 100.0
# Contact: the trusted force above this share of Fr, or 5 noise deviations if more.
CONTACT_SHARE = 0.1
CONTACT_NOISE_DEVIATIONS = 5.0
# The plausibility check's base tolerance: this share of Fr plus 6 noise deviations.
TOLERANCE_SHARE = 0.2
TOLERANCE_NOISE_DEVIATIONS = 6.0
# The stiffness estimate updates once F - F_c is above this share of Fr.
INFORMATIVE_SHARE = 0.2
# A contact stiffer than stated (docs/evidence/safety-beyond-bounds.md, section 7): the estimate
# above this
# factor times Ke_max. It starts at the prior Ke_max and rises only on a stiffer secant:
# 1.07e6 N/m at most on the 1e6 N/m walls measured; 2 leaves room for the secant's noise.
STIFFER_FACTOR = 2.0


@dataclass(frozen=True)
class LayerNumbers:
    """What one force point's layer is built from, beyond its plant: the contact frame
    every system of the layer reads, the law's numbers (``law_params``: F_c and Ke_max are
    the law's), and what the monitors derive their thresholds from the same way on every
    robot (``detector_params``, ``estimator_params``)."""

    contact: ContactFrame
    force_reference: float
    noise: float  # sigma, the sensor's force noise, N
    reading_period: float  # s
    saturation_force: float  # N
    law: SafeAdmittanceParams
    frozen: bool = False  # an analysis diagram: the detector passes the reading on
    frozen_estimate: float | None = None  # an analysis diagram: the estimate, N/m
    observer_period: float = 0.0  # 0: the observer integrates continuously; > 0: its tick, s
    # The task axes whose forces a contact at the point can make (the collision check's
    # explained torques; None: the normal alone).
    contact_axes: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.law.detection_delay != detection_delay(self.reading_period):
            raise ValueError(
                f"law.detection_delay {self.law.detection_delay} s is not the detector's at "
                f"the reading's period {self.reading_period} s (law_params)"
            )

    @property
    def contact_force(self) -> float:
        """F_c, N."""
        return self.law.contact_force

    @property
    def max_stiffness(self) -> float:
        """Ke_max, N/m."""
        return self.law.max_stiffness


def law_params(
    admittance,
    safety,
    *,
    kp: float,
    kd: float,
    max_force: float,
    force_bound_gain: float,
    filter_time_constant: float,
    period: float,
    latency: float,
    contact_force: float,
    reading_period: float,
    held_axes: bool = False,
) -> SafeAdmittanceParams:
    """SafeAdmittance's numbers from a scenario's `admittance` and `safety` sections, the
    PID's gains along the normal (K of eq. 10 is Kp), what the robot sets (Fmax and its
    penalty, the sensor's filter, the law's period, the reading's latency, the apparent
    mass with the other axes held) and what the layer derives: F_c, the detector's delay
    at the reading's period, and the back-off above STIFFER_FACTOR Ke_max."""
    return SafeAdmittanceParams(
        gamma=admittance.gamma,
        alpha=admittance.alpha,
        stiffness=kp,
        pid_kp=kp,
        pid_kd=kd,
        max_force=max_force,
        force_bound_gain=force_bound_gain,
        max_push=admittance.max_push,
        max_stiffness=safety.max_stiffness,
        damping_ratio=safety.damping_ratio,
        stability_margin=safety.stability_margin,
        filter_time_constant=filter_time_constant,
        contact_force=contact_force,
        detection_delay=detection_delay(reading_period),
        payload_mass=safety.payload_mass,
        period=period,
        latency=latency,
        backoff_stiffness=STIFFER_FACTOR * safety.max_stiffness,
        held_axes=held_axes,
    )


def detector_params(numbers: LayerNumbers) -> FaultDetectorParams:
    """The sensor monitor's numbers: the tolerance F_tol = 0.2 Fr + 6 sigma."""
    reference, noise = numbers.force_reference, numbers.noise
    return FaultDetectorParams(
        period=numbers.reading_period,
        noise_std=noise,
        saturation_force=numbers.saturation_force,
        contact_force=numbers.contact_force,
        force_tolerance=TOLERANCE_SHARE * reference + TOLERANCE_NOISE_DEVIATIONS * noise,
        observer_gain=OBSERVER_GAIN,
        frozen=numbers.frozen,
        contact_axes=numbers.contact_axes,
    )


def estimator_params(numbers: LayerNumbers) -> StiffnessEstimatorParams:
    """The stiffness estimator's numbers: the prior Ke_max, dF_min = 0.2 Fr, the latch at
    STIFFER_FACTOR Ke_max."""
    return StiffnessEstimatorParams(
        period=numbers.reading_period,
        prior_stiffness=numbers.max_stiffness,
        contact_force=numbers.contact_force,
        informative_force=INFORMATIVE_SHARE * numbers.force_reference,
        frozen_estimate=numbers.frozen_estimate,
        latch_stiffness=STIFFER_FACTOR * numbers.max_stiffness,
    )


def AddLayerSystems(
    builder: DiagramBuilder,
    plant,
    model,
    pid,
    numbers: LayerNumbers,
    *,
    name=lambda base: base,
):
    """The layer's four systems at one force point (``numbers.contact``), named by `name`
    (base name -> name), and wired among themselves, to the plant's state and to the
    PID's torques. `model` is the law's model of the arm (the plant, or the plant without
    a payload it does not know).

    Returns:
        (observer, detector, estimator, law); the reading, Fr, Xd, dXd/dt and the law's
        Xr are the caller's to wire.
    """
    contact = numbers.contact
    observer = builder.AddSystem(
        ContactForceObserver(
            plant, contact=contact, gain=OBSERVER_GAIN, period=numbers.observer_period
        )
    )
    observer.set_name(name("contact_force_observer"))
    estimator = builder.AddSystem(
        StiffnessEstimator(plant, contact=contact, params=estimator_params(numbers))
    )
    estimator.set_name(name("stiffness_estimator"))
    detector = builder.AddSystem(
        SensorFaultDetector(plant, contact=contact, params=detector_params(numbers))
    )
    detector.set_name(name("sensor_fault_detector"))
    law = builder.AddSystem(SafeAdmittance(model, contact=contact, params=numbers.law))
    law.set_name(name("safe_admittance"))
    _ConnectLayer(builder, plant, pid, observer, detector, estimator, law)
    return observer, detector, estimator, law


def _ConnectLayer(builder, plant, pid, observer, detector, estimator, law) -> None:
    """The layer's systems to one another, to the plant's state and the PID's torques."""
    state = plant.get_state_output_port()
    builder.Connect(state, observer.estimated_state_input)
    builder.Connect(pid.actuation_output, observer.actuation_input)
    builder.Connect(state, estimator.estimated_state_input)
    builder.Connect(detector.trusted_force_output, estimator.measured_force_input)
    builder.Connect(detector.sensor_fault_output, estimator.sensor_fault_input)
    builder.Connect(observer.contact_force_output, detector.observed_force_input)
    builder.Connect(estimator.stiffness_estimate_output, detector.stiffness_estimate_input)
    builder.Connect(state, detector.estimated_state_input)
    builder.Connect(detector.trusted_force_output, law.measured_force_input)
    builder.Connect(detector.sensor_fault_output, law.sensor_fault_input)
    builder.Connect(estimator.stiffness_estimate_output, law.stiffness_estimate_input)
    builder.Connect(state, law.estimated_state_input)
    # The collision reflex: the observer's residual that no contact force at the point
    # explains.
    builder.Connect(observer.external_torque_output, detector.external_torque_input)
    builder.Connect(detector.collision_output, law.collision_input)
