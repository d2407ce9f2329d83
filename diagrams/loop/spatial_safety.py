"""The safety layer on a spatial arm's tool tip (safety.enabled; docs/safety.md, section 10).

In place of the paper's admittance block at the tool tip, as on the planar arm
(loop.safety_layer):

    reading --> SensorFaultDetector --trusted force, fault--> SafeAdmittance --Xr--> (+ Xd) PID
                  ^ observed force          |                 (z of E, 6-D Xr) ^ k_hat
    ContactForceObserver (state, torques)   +--> StiffnessEstimator (trusted force, state)

The law (systems/safe_admittance.py) takes the spatial task, X = (x, y, z, rx, ry, rz) of
the tool tip in E, the force along z, and derives online from the plant the apparent mass
along z with the PID's other axes held (Lambda_zz, the cautious choice for the impact:
systems/safety_numbers.py), its damper along z and its approach bound v_max from Fmax
(safety.max_force) and Ke_max (safety.max_stiffness). The monitor checks the wrist
sensor's reading against the momentum observer's force along z (with C(q, v)^T v) with
the planar arm's tolerance, F_tol = 0.2 Fr + 6 sigma, sigma the wrist sensor's force
noise, at the reading's period. What the planar arm's layer has and this one does not:
the collision check (the observer's residual off the normal's direction: on a tool that
slides, friction is such a residual) and the moving-wall monitor; the wrist sensor model
has no full scale, so no saturation flag either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydrake.systems.framework import Context, DiagramBuilder

from admittance.diagrams.loop.point import AddCommandedPosition, AddForceLoop
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.spatial_arm import NORMAL_AXIS
from admittance.diagrams.scenario.spatial_arm import SpatialScenario
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.fault_detector import SensorFaultDetector
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.stiffness_estimator import StiffnessEstimator

__all__ = [
    "AddSpatialForceLoop",
    "CONTACT_NOISE_DEVIATIONS",
    "CONTACT_SHARE",
    "FORCE_BOUND_GAIN",
    "OBSERVER_GAIN",
    "SpatialSafetyLayer",
    "spatial_contact_force_threshold",
]

# The observer's bandwidth, 1/s (the planar arm's layer's).
OBSERVER_GAIN = 100.0
# Contact: the reading above this share of Fr, or 5 noise deviations if more (as the
# planar arm's layer).
CONTACT_SHARE = 0.1
CONTACT_NOISE_DEVIATIONS = 5.0
# mu of the force-bound penalty above (Fr + Fmax) / 2 (the planar scenario's default).
FORCE_BOUND_GAIN = 4.0
# The plausibility check's base tolerance: this share of Fr plus 6 noise deviations, and
# the stiffness estimate's informative share of Fr (the planar arm's layer's).
TOLERANCE_SHARE = 0.2
TOLERANCE_NOISE_DEVIATIONS = 6.0
INFORMATIVE_SHARE = 0.2
# The estimate latches above this factor times Ke_max (a table stiffer than stated), and
# the command then approaches at v_max (Fmax - Fr) / Fmax (docs/safety.md, section 7).
STIFFER_FACTOR = 2.0
# The wrist sensor model has no full scale: a saturation the monitor never reaches, N.
NO_SATURATION = 1e9


def _noise(scenario: SpatialScenario) -> float:
    """sigma, the wrist sensor's force noise (0 for the ideal sensor), N."""
    return scenario.sensor.noise_std if scenario.sensor.kind == "wrench" else 0.0


def spatial_contact_force_threshold(scenario: SpatialScenario) -> float:
    """F_c = max(0.1 Fr, 5 sigma), N (sigma the wrist sensor's force noise)."""
    noise = _noise(scenario)
    return max(CONTACT_SHARE * scenario.force_reference, CONTACT_NOISE_DEVIATIONS * noise)


@dataclass
class SpatialSafetyLayer:
    """The layer's systems at the tool tip."""

    law: SafeAdmittance
    observer: ContactForceObserver
    detector: SensorFaultDetector
    estimator: StiffnessEstimator

    @property
    def reference_offset_output(self):
        return self.law.reference_offset_output

    def log_ports(self) -> dict:
        """The layer's signals worth logging, by name."""
        return {
            "observed_force": self.observer.contact_force_output,
            "trusted_force": self.detector.trusted_force_output,
            "fault_flags": self.detector.fault_flags_output,
            "stiffness_estimate": self.estimator.stiffness_estimate_output,
            "gain_scale": self.law.gain_scale_output,
        }

    def initialize(self, root_context: Context) -> None:
        """At a run's start: the monitor holds the first reading, the reference is at the
        tip (where the plan starts it, at rest), Gamma_s at its target."""
        detector_context = self.detector.GetMyMutableContextFromRoot(root_context)
        reading = self.detector.measured_force_input.Eval(detector_context)[0]
        self.detector.set_reading(detector_context, float(reading))
        self.law.start_at_tip(self.law.GetMyMutableContextFromRoot(root_context))

    def numbers(self, root_context: Context) -> dict:
        """The layer's derived numbers at `root_context` (apparent mass, c, v_max, ...)."""
        numbers = dict(self.law.numbers(self.law.GetMyContextFromRoot(root_context)))
        numbers["contact_force_threshold"] = self.estimator.contact_force
        numbers["detection_delay"] = self.detector.detection_delay
        return numbers


def _filter_time_constant(scenario: SpatialScenario) -> float:
    sensor = scenario.sensor
    if sensor.kind != "wrench" or sensor.filter_cutoff <= 0:
        return 0.0
    return 1.0 / (2.0 * math.pi * sensor.filter_cutoff)


def AddSpatialForceLoop(
    builder: DiagramBuilder,
    scenario: SpatialScenario,
    point: ForcePoint,
    pid,
    *,
    plant,
    desired_position_output,
    desired_velocity_output,
    desired_force_output,
    measured_force_output,
):
    """The tool tip's force controller between its sensor and its PID: the safety layer
    with safety.enabled, the scenario's controller otherwise (loop.point.AddForceLoop).

    Returns:
        (the force controller or None for pid_only, the SpatialSafetyLayer or None).
    """
    if not scenario.safety.enabled:
        controller = AddForceLoop(
            builder,
            point,
            pid,
            desired_position_output=desired_position_output,
            desired_force_output=desired_force_output,
            measured_force_output=measured_force_output,
        )
        return controller, None
    safety, admittance = scenario.safety, scenario.admittance
    # The tool tip's task, the normal z of E: every system of the layer is at it.
    tip = dict(
        frame_name=point.frame,
        normal_axis=NORMAL_AXIS,
        coordinates=point.coordinates,
        expressed_in=point.expressed_in,
    )
    reference, noise = scenario.force_reference, _noise(scenario)
    contact = spatial_contact_force_threshold(scenario)
    reading_period = point.sensor.period or scenario.time_step
    observer = builder.AddSystem(ContactForceObserver(plant, gain=OBSERVER_GAIN, **tip))
    observer.set_name(point.system_name("contact_force_observer"))
    detector = builder.AddSystem(
        SensorFaultDetector(
            plant,
            period=reading_period,
            noise_std=noise,
            saturation_force=NO_SATURATION,
            contact_force=contact,
            force_tolerance=TOLERANCE_SHARE * reference + TOLERANCE_NOISE_DEVIATIONS * noise,
            observer_gain=OBSERVER_GAIN,
            **tip,
        )
    )
    detector.set_name(point.system_name("sensor_fault_detector"))
    estimator = builder.AddSystem(
        StiffnessEstimator(
            plant,
            period=reading_period,
            prior_stiffness=safety.max_stiffness,
            contact_force=contact,
            informative_force=INFORMATIVE_SHARE * reference,
            latch_stiffness=STIFFER_FACTOR * safety.max_stiffness,
            **tip,
        )
    )
    estimator.set_name(point.system_name("stiffness_estimator"))
    law = builder.AddSystem(
        SafeAdmittance(
            plant,
            gamma=admittance.gamma,
            alpha=admittance.alpha,
            stiffness=point.kp[NORMAL_AXIS],
            pid_kp=point.kp[NORMAL_AXIS],
            pid_kd=point.kd[NORMAL_AXIS],
            max_force=safety.max_force,
            force_bound_gain=FORCE_BOUND_GAIN,
            max_push=admittance.max_push,
            max_stiffness=safety.max_stiffness,
            damping_ratio=safety.damping_ratio,
            stability_margin=safety.stability_margin,
            filter_time_constant=_filter_time_constant(scenario),
            contact_force=contact,
            detection_delay=detector.detection_delay,
            payload_mass=safety.payload_mass,
            period=point.law.period,
            latency=point.sensor.latency,
            num_axes=point.num_axes,
            backoff_stiffness=STIFFER_FACTOR * safety.max_stiffness,
            held_axes=True,
            **tip,
        )
    )
    law.set_name(point.system_name("safe_admittance"))

    state = plant.get_state_output_port()
    builder.Connect(state, observer.estimated_state_input)
    builder.Connect(pid.actuation_output, observer.actuation_input)
    builder.Connect(measured_force_output, detector.measured_force_input)
    builder.Connect(observer.contact_force_output, detector.observed_force_input)
    builder.Connect(estimator.stiffness_estimate_output, detector.stiffness_estimate_input)
    builder.Connect(state, detector.estimated_state_input)
    builder.Connect(state, estimator.estimated_state_input)
    builder.Connect(detector.trusted_force_output, estimator.measured_force_input)
    builder.Connect(detector.sensor_fault_output, estimator.sensor_fault_input)
    builder.Connect(state, law.estimated_state_input)
    builder.Connect(detector.trusted_force_output, law.measured_force_input)
    builder.Connect(detector.sensor_fault_output, law.sensor_fault_input)
    builder.Connect(estimator.stiffness_estimate_output, law.stiffness_estimate_input)
    builder.Connect(desired_force_output, law.desired_force_input)
    builder.Connect(desired_position_output, law.desired_position_input)
    builder.Connect(desired_velocity_output, law.desired_velocity_input)
    commanded = AddCommandedPosition(builder, point, desired_position_output, pid)
    builder.Connect(law.reference_offset_output, commanded.get_input_port(1))
    layer = SpatialSafetyLayer(law=law, observer=observer, detector=detector, estimator=estimator)
    return law, layer
