"""The safety layer's four systems at one force point, built and wired alike on every
robot (docs/safety.md): the momentum observer, the sensor monitor, the stiffness
estimator and the safe law. Each robot's layer (robots.planar_arm.safety_layer for the planar arm,
robots.spatial_arm.safety_layer for a spatial arm's tool tip) says what is its own through
``LayerNumbers`` and wires the reading, Fr, Xd and the law's Xr.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.systems.framework import DiagramBuilder

from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.fault_detector import SensorFaultDetector
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.stiffness_estimator import StiffnessEstimator

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
    "law_arguments",
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
# A contact stiffer than stated (docs/safety.md, section 7): the estimate above this
# factor times Ke_max. It starts at the prior Ke_max and rises only on a stiffer secant:
# 1.07e6 N/m at most on the 1e6 N/m walls measured; 2 leaves room for the secant's noise.
STIFFER_FACTOR = 2.0


@dataclass(frozen=True)
class LayerNumbers:
    """What one force point's layer is built from, beyond its plant and its task.

    `law` holds SafeAdmittance's keyword arguments that the robot sets (Gamma, alpha, the
    PID's gains, Fmax and its penalty, max_push, the damping ratio, the stability margin,
    the filter's time constant, the payload, the periods, num_axes, ...); the rest the
    layer derives here the same way on every robot."""

    force_reference: float
    noise: float  # sigma, the sensor's force noise, N
    contact_force: float  # F_c, N
    reading_period: float  # s
    saturation_force: float  # N
    max_stiffness: float  # Ke_max, N/m
    law: dict
    frozen: bool = False  # an analysis diagram: the detector passes the reading on
    frozen_estimate: float | None = None  # an analysis diagram: the estimate, N/m
    observer_period: float = 0.0  # 0: the observer integrates continuously; > 0: its tick, s
    # The task axes whose forces a contact at the point can make (the collision check's
    # explained torques; None: the normal alone).
    contact_axes: tuple[int, ...] | None = None


def law_arguments(admittance, safety, *, kp: float, kd: float, **robot) -> dict:
    """SafeAdmittance's keyword arguments from a scenario's `admittance` and `safety`
    sections and the PID's gains along the normal (K of eq. 10 is Kp), with what the
    robot adds (Fmax and its penalty, the filter, the periods, num_axes, ...)."""
    return dict(
        gamma=admittance.gamma,
        alpha=admittance.alpha,
        stiffness=kp,
        pid_kp=kp,
        pid_kd=kd,
        max_push=admittance.max_push,
        damping_ratio=safety.damping_ratio,
        stability_margin=safety.stability_margin,
        payload_mass=safety.payload_mass,
        **robot,
    )


def AddLayerSystems(
    builder: DiagramBuilder,
    plant,
    model,
    pid,
    tip: dict,
    numbers: LayerNumbers,
    *,
    name=lambda base: base,
):
    """The layer's four systems at one force point (`tip`: frame_name, normal_axis and the
    task's coordinates / expressed_in), named by `name` (base name -> name), and wired
    among themselves, to the plant's state and to the PID's torques. `model` is the
    law's model of the arm (the plant, or the plant without a payload it does not know).

    Returns:
        (observer, detector, estimator, law); the reading, Fr, Xd, dXd/dt and the law's
        Xr are the caller's to wire.
    """
    reference, noise, contact = numbers.force_reference, numbers.noise, numbers.contact_force
    observer = builder.AddSystem(
        ContactForceObserver(plant, gain=OBSERVER_GAIN, period=numbers.observer_period, **tip)
    )
    observer.set_name(name("contact_force_observer"))
    estimator = builder.AddSystem(
        StiffnessEstimator(
            plant,
            period=numbers.reading_period,
            prior_stiffness=numbers.max_stiffness,
            contact_force=contact,
            informative_force=INFORMATIVE_SHARE * reference,
            frozen_estimate=numbers.frozen_estimate,
            latch_stiffness=STIFFER_FACTOR * numbers.max_stiffness,
            **tip,
        )
    )
    estimator.set_name(name("stiffness_estimator"))
    detector = builder.AddSystem(
        SensorFaultDetector(
            plant,
            period=numbers.reading_period,
            noise_std=noise,
            saturation_force=numbers.saturation_force,
            contact_force=contact,
            force_tolerance=TOLERANCE_SHARE * reference + TOLERANCE_NOISE_DEVIATIONS * noise,
            observer_gain=OBSERVER_GAIN,
            frozen=numbers.frozen,
            contact_axes=numbers.contact_axes,
            **tip,
        )
    )
    detector.set_name(name("sensor_fault_detector"))
    law = builder.AddSystem(
        SafeAdmittance(
            model,
            max_stiffness=numbers.max_stiffness,
            contact_force=contact,
            detection_delay=detector.detection_delay,
            backoff_stiffness=STIFFER_FACTOR * numbers.max_stiffness,
            **numbers.law,
            **tip,
        )
    )
    law.set_name(name("safe_admittance"))

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
    return observer, detector, estimator, law
