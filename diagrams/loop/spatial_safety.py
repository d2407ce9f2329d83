"""The safety layer on a spatial arm's tool tip (safety.enabled; docs/safety.md, section 10).

In place of the paper's admittance block at the tool tip:

    reading --> SafeAdmittance (z of the control frame E, 6-D Xr) --Xr--> (+ Xd) PID
                  ^ Ke_max (a fixed estimate), no fault
    ContactForceObserver (state, torques; logged: the force along E's z)

The law (systems/safe_admittance.py) takes the spatial task, X = (x, y, z, rx, ry, rz) of
the tool tip in E, the force along z, and derives online from the plant the apparent mass
along z with the PID's other axes held (Lambda_zz, the cautious choice for the impact:
systems/safety_numbers.py), its damper along z and its approach bound v_max from Fmax
(safety.max_force) and Ke_max (safety.max_stiffness). What the planar arm's layer has and
this one does not yet: the sensor monitor (systems/fault_detector.py) and the stiffness
estimator; the law runs on the reading itself, with its estimate fixed at Ke_max and no
fault, and its advance bound in contact takes one reading period as the detection delay.
The momentum observer (with C(q, v)^T v) is wired and logged, for the monitor to come.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from admittance.diagrams.loop.point import AddCommandedPosition, AddForceLoop
from admittance.diagrams.robots.description import ForcePoint
from admittance.diagrams.robots.spatial_arm import NORMAL_AXIS
from admittance.diagrams.scenario.spatial_arm import SpatialScenario
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.safe_admittance import SafeAdmittance

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


def spatial_contact_force_threshold(scenario: SpatialScenario) -> float:
    """F_c = max(0.1 Fr, 5 sigma), N (sigma the wrist sensor's force noise)."""
    noise = scenario.sensor.noise_std if scenario.sensor.kind == "wrench" else 0.0
    return max(CONTACT_SHARE * scenario.force_reference, CONTACT_NOISE_DEVIATIONS * noise)


@dataclass
class SpatialSafetyLayer:
    """The layer's systems at the tool tip."""

    law: SafeAdmittance
    observer: ContactForceObserver

    @property
    def reference_offset_output(self):
        return self.law.reference_offset_output

    def log_ports(self) -> dict:
        """The layer's signals worth logging, by name."""
        return {
            "observed_force": self.observer.contact_force_output,
            "gain_scale": self.law.gain_scale_output,
        }

    def initialize(self, root_context: Context) -> None:
        """At a run's start: the reference at the tip (where the plan starts it, at rest),
        Gamma_s at its target."""
        self.law.start_at_tip(self.law.GetMyMutableContextFromRoot(root_context))

    def numbers(self, root_context: Context) -> dict:
        """The law's derived numbers at `root_context` (apparent mass, c, v_max, ...)."""
        return dict(self.law.numbers(self.law.GetMyContextFromRoot(root_context)))


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
    task = dict(coordinates=point.coordinates, expressed_in=point.expressed_in)
    period = point.law.period
    law = builder.AddSystem(
        SafeAdmittance(
            plant,
            frame_name=point.frame,
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
            contact_force=spatial_contact_force_threshold(scenario),
            # No monitor yet: a reading is acted on one reading period after it is taken.
            detection_delay=point.sensor.period or scenario.time_step,
            payload_mass=safety.payload_mass,
            period=period,
            latency=point.sensor.latency,
            normal_axis=NORMAL_AXIS,
            num_axes=point.num_axes,
            held_axes=True,
            **task,
        )
    )
    law.set_name(point.system_name("safe_admittance"))
    estimate = builder.AddSystem(ConstantVectorSource([safety.max_stiffness]))
    estimate.set_name(point.system_name("stiffness_bound"))
    no_fault = builder.AddSystem(ConstantVectorSource([0.0]))
    no_fault.set_name(point.system_name("no_sensor_fault"))
    observer = builder.AddSystem(
        ContactForceObserver(
            plant, frame_name=point.frame, gain=OBSERVER_GAIN, normal_axis=NORMAL_AXIS, **task
        )
    )
    observer.set_name(point.system_name("contact_force_observer"))

    state = plant.get_state_output_port()
    builder.Connect(state, observer.estimated_state_input)
    builder.Connect(pid.actuation_output, observer.actuation_input)
    builder.Connect(state, law.estimated_state_input)
    builder.Connect(measured_force_output, law.measured_force_input)
    builder.Connect(desired_force_output, law.desired_force_input)
    builder.Connect(desired_position_output, law.desired_position_input)
    builder.Connect(desired_velocity_output, law.desired_velocity_input)
    builder.Connect(estimate.get_output_port(), law.stiffness_estimate_input)
    builder.Connect(no_fault.get_output_port(), law.sensor_fault_input)
    commanded = AddCommandedPosition(builder, point, desired_position_output, pid)
    builder.Connect(law.reference_offset_output, commanded.get_input_port(1))
    return law, SpatialSafetyLayer(law=law, observer=observer)
