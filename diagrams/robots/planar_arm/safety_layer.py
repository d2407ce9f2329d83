"""The safety layer in the closed loop (safety.enabled; docs/evidence/safety.md).

Between the sensor and the PID, in place of the paper's admittance block:

    reading --> SensorFaultDetector --trusted force, fault--> SafeAdmittance --Xr--> (+ Xd) PID
                  ^ observed force          |                     ^ k_hat
    ContactForceObserver (state, torques)   +--> StiffnessEstimator (trusted force, state)

The layer's derived numbers (its thresholds and the detector's tolerance) are set here
from the scenario; the law derives the rest (apparent mass, damping, speeds, schedule)
from the plant online. This module also turns the layer's logs into metrics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context, DiagramBuilder

from admittance.diagrams.loop.layer_systems import (
    CONTACT_NOISE_DEVIATIONS,
    CONTACT_SHARE,
    AddLayerSystems,
    LayerNumbers,
    law_params,
)
from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.plant import ArmModel
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.run.safety_metrics import (
    rising_edges,
    stiffer_than_stated,
    wall_approach_detections,
)
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.fault_detector import SensorFaultDetector
from admittance.systems.flexiforce import FlexiForceSensor
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics
from admittance.systems.safe_admittance import SafeAdmittance
from admittance.systems.stiffness_estimator import StiffnessEstimator
from admittance.systems.wall_motion_monitor import WallMotionMonitor

__all__ = [
    "SafetyLayer",
    "AddSafetyLayer",
    "CapStepForSampledMonitor",
    "STOP_SPEED",
    "collision_reaction",
    "contact_force_threshold",
    "expected_noise",
    "first_contact_approach",
    "reach_limit",
    "sampled_damper_gain",
    "safety_metrics",
    "tip_speed",
]

# The wall normal in X = (x, y, theta).
NORMAL_AXIS = 0
# After a collision the arm has stopped once the tip's speed stays below this, m/s, for
# STOP_HOLD s: about half the approach bound v_max of the layer's arms (9.3-9.8 mm/s), a
# speed at which a strike on a wall of Ke_max stays well under Fmax.
STOP_SPEED = 5e-3
STOP_HOLD = 0.05
# A sampled PID's damper alone is stable while h max eig(J M^-1 J^T Kd) stays below this
# (see sampled_damper_gain).
SAMPLED_DAMPER_LIMIT = 2.0


def expected_noise(scenario: Scenario) -> float:
    """sigma, the noise the monitor expects on the reading (the sensor's spec), N."""
    sensor = scenario.sensor
    return sensor.noise_std if sensor.kind != "ideal" else 0.0


def contact_force_threshold(scenario: Scenario) -> float:
    """F_c = max(0.1 Fr, 5 sigma), N: a contact, not the noise."""
    return max(
        CONTACT_SHARE * scenario.force_reference,
        CONTACT_NOISE_DEVIATIONS * expected_noise(scenario),
    )


@dataclass
class SafetyLayer:
    """The layer's systems, with the ports the closed loop wires as a force controller's."""

    law: SafeAdmittance
    detector: SensorFaultDetector
    estimator: StiffnessEstimator
    observer: ContactForceObserver
    # None in an analysis diagram (sampled: an equilibrium has no moving wall).
    wall_monitor: WallMotionMonitor | None = None
    # The sampled PID's period (0 = continuous), its Kd on X and the controlled frame,
    # for the check of its damper at the run's start (sampled_damper_gain).
    pid_period: float = 0.0
    pid_kd: tuple[float, ...] = ()
    frame: str = ""

    # The force controller's ports (diagrams/loop/point.py): the reading goes to
    # the detector, Fr and Xd to the law, Xr comes out of the law.
    @property
    def measured_force_input(self):
        return self.detector.measured_force_input

    @property
    def desired_force_input(self):
        return self.law.desired_force_input

    @property
    def desired_position_input(self):
        return self.law.desired_position_input

    @property
    def reference_offset_output(self):
        return self.law.reference_offset_output

    def log_ports(self) -> dict:
        """The layer's signals worth logging, by name."""
        ports = {
            "fault_flags": self.detector.fault_flags_output,
            "collision": self.detector.collision_output,
            "trusted_force": self.detector.trusted_force_output,
            "observed_force": self.observer.contact_force_output,
            "stiffness_estimate": self.estimator.stiffness_estimate_output,
            "gain_scale": self.law.gain_scale_output,
        }
        if self.wall_monitor is not None:
            ports["wall_approach_speed"] = self.wall_monitor.wall_approach_speed_output
        return ports

    def initialize(self, root_context: Context) -> None:
        """At a run's start: the monitor holds the first reading, the reference is at the
        tip (the arm at rest does not move when the run starts), Gamma_s at its target."""
        detector_context = self.detector.GetMyMutableContextFromRoot(root_context)
        reading = self.detector.measured_force_input.Eval(detector_context)[0]
        self.detector.set_reading(detector_context, float(reading))
        self._check_sampled_damper(root_context)
        try:
            self.law.start_at_tip(self.law.GetMyMutableContextFromRoot(root_context))
        except ValueError as error:
            raise ScenarioError(
                f"arm.initial_position, admittance.max_push: {error} "
                "(with safety.enabled the reference starts at the tip)"
            ) from None

    def _check_sampled_damper(self, root_context: Context) -> None:
        """Refuses a sampled PID whose damper alone is unstable on the arm at the start:
        the layer's bounds assume a stable inner loop, which it cannot restore."""
        if self.pid_period <= 0.0:
            return
        law_context = self.law.GetMyContextFromRoot(root_context)
        state = self.law.estimated_state_input.Eval(law_context)
        gain = sampled_damper_gain(self.law.plant, self.frame, state, self.pid_kd, self.pid_period)
        if gain >= SAMPLED_DAMPER_LIMIT:
            raise ScenarioError(
                f"pid.kd, pid.period: the sampled PID's damping is unstable on this arm: "
                f"h max eig(J M^-1 J^T Kd) = {gain:.3g} at the start, must be below "
                f"{SAMPLED_DAMPER_LIMIT:g} (docs/evidence/safety-sampled.md, section 8); with "
                "safety.enabled the layer cannot bound the force: lower pid.kd, shorten "
                "pid.period, or model the "
                "motors' inertia (arm.reflected_inertia=true), as safe_contact_1khz does"
            )

    def set_equilibrium(self, root_context: Context, offset: float, external_torque) -> None:
        """At an analysis equilibrium: Xr = `offset`, the observer at `external_torque`."""
        self.law.set_equilibrium(self.law.GetMyMutableContextFromRoot(root_context), offset)
        self.observer.set_external_torque(
            self.observer.GetMyMutableContextFromRoot(root_context), external_torque
        )

    def numbers(self, root_context: Context) -> dict:
        """The layer's derived numbers at `root_context` (apparent mass, c, v_max, ...)."""
        numbers = dict(self.law.numbers(self.law.GetMyContextFromRoot(root_context)))
        numbers["contact_force_threshold"] = self.estimator.contact_force
        numbers["detection_delay"] = self.detector.detection_delay
        return numbers


def AddSafetyLayer(
    builder: DiagramBuilder,
    scenario: Scenario,
    *,
    plant,
    pid,
    trajectory,
    analysis: bool = False,
) -> SafetyLayer:
    """Adds the layer's systems and wires them to the plant, the PID and the trajectory.

    The reading, Fr and Xd are wired by the caller, through the returned layer's ports.
    With `analysis`, the estimator is frozen at the wall's stiffness (what it converges
    to on a static wall) and the detector passes the reading on: an equilibrium has no
    fault, and its gain schedule is frozen at the estimate.
    """
    frame = scenario.arm.fingertip_frame
    admittance, pid_config, safety = scenario.admittance, scenario.pid, scenario.safety
    sensor = FlexiForceSensor(
        kind=scenario.sensor.kind, filter_cutoff_hz=scenario.sensor.filter_cutoff
    )
    reading_period = scenario.sensor.noise_period
    numbers = LayerNumbers(
        contact=ContactFrame(
            frame_name=frame, coordinates=PLANAR_COORDINATES, normal_axis=NORMAL_AXIS
        ),
        force_reference=scenario.force_reference,
        noise=expected_noise(scenario),
        reading_period=reading_period,
        saturation_force=sensor.saturation_force,
        frozen=analysis,
        frozen_estimate=scenario.wall.stiffness if analysis else None,
        law=law_params(
            admittance,
            safety,
            kp=pid_config.kp[NORMAL_AXIS],
            kd=pid_config.kd[NORMAL_AXIS],
            max_force=admittance.max_force,
            force_bound_gain=admittance.force_bound_gain,
            filter_time_constant=sensor.filter_time_constant if sensor.kind != "ideal" else 0.0,
            period=admittance.period,
            latency=scenario.sensor.latency,
            contact_force=contact_force_threshold(scenario),
            reading_period=reading_period,
        ),
    )
    # The law's model of the arm: the plant as built (reflected inertia included when the
    # scenario has it), without a payload the simulated arm carries (arm.payload_mass):
    # the layer knows of one only through safety.payload_mass.
    model = plant if scenario.arm.payload_mass == 0.0 else ArmModel(scenario.arm)
    observer, detector, estimator, law = AddLayerSystems(builder, plant, model, pid, numbers)
    builder.Connect(trajectory.desired_velocity_output, law.desired_velocity_input)
    monitor = (
        None
        if analysis
        else _AddWallMotionMonitor(
            builder, scenario, numbers.contact, plant, law, detector, estimator
        )
    )
    return SafetyLayer(
        law=law,
        detector=detector,
        estimator=estimator,
        observer=observer,
        wall_monitor=monitor,
        pid_period=pid_config.period,
        pid_kd=tuple(pid_config.kd),
        frame=frame,
    )


def sampled_damper_gain(plant, frame_name: str, state, kd, period: float) -> float:
    """h max eig(J M^-1 J^T Kd) at `state` (x, y, theta of `frame_name` in world).

    The sampled PID holds its damping force -Kd dX/dt over each period h. On the arm's
    task-space inertia Lambda = (J M^-1 J^T)^-1 that force alone steps the task velocity
    by (I - h Lambda^-1 Kd) per period, whose eigenvalues 1 - h lambda_i lie inside the
    unit circle only while h lambda_i < 2. It is a necessary condition: the stiffness and
    the contact take some of that room.
    """
    kinematics = PlanarFrameKinematics(plant, frame_name, coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.asarray(state, dtype=float))
    jacobian = np.asarray(kinematics.jacobian(), dtype=float)
    mass = plant.CalcMassMatrix(kinematics.context)
    mobility = jacobian @ np.linalg.solve(mass, jacobian.T)
    return float(period * np.max(np.linalg.eigvals(mobility @ np.diag(kd)).real))


def _AddWallMotionMonitor(
    builder, scenario, contact: ContactFrame, plant, law, detector, estimator
) -> WallMotionMonitor:
    """The approaching wall's monitor at the layer's contact, wired from the trusted
    reading and the estimate to the law (docs/evidence/safety-beyond-bounds.md, section 7)."""
    monitor = builder.AddSystem(
        WallMotionMonitor(
            plant,
            contact=contact,
            period=scenario.sensor.noise_period,
            noise_std=expected_noise(scenario),
            contact_force=contact_force_threshold(scenario),
        )
    )
    monitor.set_name("wall_motion_monitor")
    builder.Connect(detector.trusted_force_output, monitor.measured_force_input)
    builder.Connect(detector.sensor_fault_output, monitor.sensor_fault_input)
    builder.Connect(plant.get_state_output_port(), monitor.estimated_state_input)
    builder.Connect(estimator.stiffness_estimate_output, monitor.stiffness_estimate_input)
    builder.Connect(monitor.wall_approach_speed_output, law.wall_approach_speed_input)
    return monitor


def CapStepForSampledMonitor(scenario: Scenario, simulator) -> None:
    """Caps the integrator's step at half the sensor's sample period.

    The layer's monitor and estimator are sampled (periodic events every T). Measured with
    Drake 1.51: radau3 stepping next to periodic events T apart, with a step that may reach
    T, shrinks its steps geometrically on paper_stiffness_step's sliding trajectory (3,036
    steps for 0.1 s with a no-op 5 ms event, 61 without; 74 with the step capped at 2.5 ms;
    docs/evidence/safety.md). A step of at most T / 2 avoids it.
    """
    integrator = simulator.get_mutable_integrator()
    cap = 0.5 * scenario.sensor.noise_period
    if integrator.get_maximum_step_size() > cap:
        integrator.set_maximum_step_size(cap)


# --- metrics ----------------------------------------------------------------------------


def reach_limit(result, plant, effort_limits) -> float | None:
    """The first time the force was above Fmax while the arm could not follow the layer's
    command Xc = Xd + Xr: an actuator at its effort limit, or Xc out of the arm's reach
    (no inverse kinematics from the logged joints). None if there is no such time.

    The layer bounds neither how far Xr retracts nor the command's retreat
    (docs/evidence/safety.md):
    past Fmax only the arm itself can have stopped it, and this says when.
    """
    scenario = result.scenario
    over = np.nonzero(result.force > scenario.admittance.max_force)[0]
    limits = np.asarray(effort_limits, dtype=float)
    command = result.desired_position + result.reference_offset
    for row in over:
        if np.any(np.abs(result.actuation[row]) >= limits * (1.0 - 1e-9)):
            return float(result.time[row])
        try:
            SolvePlanarInverseKinematics(
                plant,
                scenario.arm.fingertip_frame,
                command[row],
                result.joint_positions[row],
                coordinates=PLANAR_COORDINATES,
            )
        except ValueError:
            return float(result.time[row])
    return None


def first_contact_approach(result, law: SafeAdmittance) -> dict:
    """The tip's speed along the normal at the last sample before the first contact (the
    true force still zero), and the approach bound v_max the layer derives at that state.
    Empty if the run never touches the wall."""
    touching = np.nonzero(result.force > 0.0)[0]
    if touching.size == 0 or touching[0] == 0:
        return {}
    row = touching[0] - 1
    state = np.concatenate([result.joint_positions[row], result.joint_velocities[row]])
    numbers = law.numbers_at(state, result.scenario.force_reference)
    kinematics = PlanarFrameKinematics(
        law.plant, result.scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    kinematics.set_state(state)
    speed = float(kinematics.jacobian()[NORMAL_AXIS] @ result.joint_velocities[row])
    return {
        "first_contact_speed": speed,
        "first_contact_approach_bound": float(numbers["approach_speed"]),
        "first_contact_apparent_mass": float(numbers["apparent_mass"]),
    }


def safety_metrics(result) -> dict:
    """metrics.json's ``safety`` section: the layer's numbers at the start, each
    detection (time, kind), the final stiffness estimate and gain scale, and whether the
    arm's reach stopped the layer (``reach_limited``, ``reach_limited_time``)."""
    logs = result.safety
    time = logs["time"]
    metrics = {key: value for key, value in logs["numbers"].items() if key != "in_contact"}
    metrics["detections"] = rising_edges(time, np.hstack([logs["fault_flags"], logs["collision"]]))
    if "wall_approach_speed" in logs:
        metrics["detections"] = sorted(
            metrics["detections"] + wall_approach_detections(time, logs, result.scenario),
            key=lambda d: d["time"],
        )
    metrics["final_stiffness_estimate"] = float(logs["stiffness_estimate"][-1, 0])
    metrics["stiffer_than_stated"] = stiffer_than_stated(
        time, logs["stiffness_estimate"][:, 0], result.scenario.safety.max_stiffness
    )
    metrics["final_gain_scale"] = float(logs["gain_scale"][-1, 0])
    metrics.update(logs.get("first_contact", {}))
    metrics["reach_limited_time"] = logs.get("reach_limited_time")
    metrics["reach_limited"] = metrics["reach_limited_time"] is not None
    return metrics


def tip_speed(result, plant) -> np.ndarray:
    """The fingertip's speed along its path at each logged sample, m/s: |J_t(q) v|, J_t the
    translational rows of the fingertip's Jacobian."""
    kinematics = PlanarFrameKinematics(
        plant, result.scenario.arm.fingertip_frame, coordinates=PLANAR_COORDINATES
    )
    speeds = np.empty(len(result.time))
    for row, (q, v) in enumerate(zip(result.joint_positions, result.joint_velocities, strict=True)):
        kinematics.set_state(np.concatenate([q, v]))
        speeds[row] = np.linalg.norm((kinematics.jacobian() @ v)[:2])
    return speeds


def collision_reaction(result, start: float, detected_time: float | None) -> dict:
    """How the arm reacted to a joint_torque fault starting at `start`, detected at
    `detected_time`: when it stopped (the first logged time after the detection from which
    the tip's speed stays below STOP_SPEED for STOP_HOLD), the times from the fault's start
    to the detection and to the stop, and the peak contact force and joint torque (the
    actuators', absolute) from the fault's start to the end of the run."""
    time = result.time
    after = time >= start
    reaction = {
        "stop_speed_threshold": STOP_SPEED,
        "stop_time": None,
        "time_to_stop": None,
        "peak_force_after_collision": float(np.max(result.force[after])) if after.any() else None,
        "peak_joint_torque_after_collision": (
            float(np.max(np.abs(result.actuation[after]))) if after.any() else None
        ),
    }
    speed = result.safety.get("tip_speed")
    if detected_time is None or speed is None:
        return reaction
    slow = speed < STOP_SPEED
    for row in np.nonzero((time >= detected_time) & slow)[0]:
        window = (time >= time[row]) & (time <= time[row] + STOP_HOLD)
        if time[-1] >= time[row] + STOP_HOLD and np.all(slow[window]):
            reaction["stop_time"] = float(time[row])
            reaction["time_to_stop"] = float(time[row] - start)
            break
    return reaction
