"""The safety layer on a spatial arm's tool tip (safety.enabled; docs/evidence/safety-spatial.md,
section 10).

In place of the paper's admittance block at the tool tip, as on the planar arm
(robots.planar_arm.safety_layer):

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
noise, at the reading's period. The collision check reads the observer's residual off
the tool tip's three force rows (the normal and the friction across it, which the planar
arm's frictionless rule would read as a collision), and the reflex backs the tool off.
What the planar arm's layer has and this one does not: the moving-wall monitor; the wrist
sensor model has no full scale, so no saturation flag either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydrake.systems.framework import Context, DiagramBuilder

from admittance.diagrams.loop.layer_systems import (
    CONTACT_NOISE_DEVIATIONS,
    CONTACT_SHARE,
    AddLayerSystems,
    LayerNumbers,
    law_params,
)
from admittance.diagrams.loop.point import AddCommandedPosition, AddForceLoop
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.spatial_arm.plant import NORMAL_AXIS
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import SensorFaultDetector
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.stiffness_estimator import StiffnessEstimator

__all__ = [
    "AddSpatialForceLoop",
    "FORCE_BOUND_GAIN",
    "SpatialSafetyLayer",
    "spatial_contact_force_threshold",
]

# mu of the force-bound penalty above (Fr + Fmax) / 2 (the planar scenario's default).
FORCE_BOUND_GAIN = 4.0
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
            "collision": self.detector.collision_output,
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
    reading_period = point.sensor.period or scenario.time_step
    numbers = LayerNumbers(
        # The tool tip's task, the normal z of E: every system of the layer is at it.
        contact=ContactFrame(
            frame_name=point.frame,
            coordinates=point.coordinates,
            normal_axis=NORMAL_AXIS,
            expressed_in=point.expressed_in,
        ),
        force_reference=scenario.force_reference,
        noise=_noise(scenario),
        reading_period=reading_period,
        saturation_force=NO_SATURATION,
        # The observer steps with the plant: the loop is sampled at time_step.
        observer_period=scenario.time_step,
        # A tool on a table loads x, y (friction) and z: the collision check explains them.
        contact_axes=(0, 1, 2),
        law=law_params(
            admittance,
            safety,
            kp=point.kp[NORMAL_AXIS],
            kd=point.kd[NORMAL_AXIS],
            max_force=safety.max_force,
            force_bound_gain=FORCE_BOUND_GAIN,
            filter_time_constant=_filter_time_constant(scenario),
            period=point.law.period,
            latency=point.sensor.latency,
            contact_force=spatial_contact_force_threshold(scenario),
            reading_period=reading_period,
            held_axes=True,
        ),
    )
    observer, detector, estimator, law = AddLayerSystems(
        builder, plant, plant, pid, numbers, name=point.system_name
    )
    builder.Connect(measured_force_output, detector.measured_force_input)
    builder.Connect(desired_force_output, law.desired_force_input)
    builder.Connect(desired_position_output, law.desired_position_input)
    builder.Connect(desired_velocity_output, law.desired_velocity_input)
    commanded = AddCommandedPosition(builder, point, desired_position_output, pid)
    builder.Connect(law.reference_offset_output, commanded.get_input_port(1))
    layer = SpatialSafetyLayer(law=law, observer=observer, detector=detector, estimator=estimator)
    return law, layer
