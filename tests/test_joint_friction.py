"""The arm with its motors' viscous friction (arm.motor_damping) and the contact-force
observer that does not model it (docs/evidence/safety-sensor-faults.md, section 3).

The observer takes the commanded torque for the applied one, so the joints' damping torque
-B q' reads as an external torque, and F_hat is off by (J^-T B J^-1 X')_x.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.loop.layer_systems import TOLERANCE_SHARE
from admittance.diagrams.robots.inverse_kinematics import SolvePlanarInverseKinematics
from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.scenario import ArmConfig
from admittance.diagrams.scenario.files import load_scenario
from admittance.systems.contact_force_observer import ContactForceObserver
from admittance.systems.contact_frame import ContactFrame
from admittance.systems.planar_kinematics import PLANAR_COORDINATES, PlanarFrameKinematics

# The stated motor-side viscous friction, N m s/rad (docs/evidence/safety-sensor-faults.md, section
# 3).
MOTOR_DAMPING = 2.4e-6
RATIOS = (288.0, 192.0, 48.0)  # the URDF's gear ratios (urdf/README.md)


def _arm(motor_damping: float):
    builder = DiagramBuilder()
    plant, _ = AddScenarioArm(builder, ArmConfig(motor_damping=motor_damping))
    return plant


def test_each_joint_gets_the_motor_s_friction_times_its_ratio_squared():
    """288^2 x 2.4e-6 = 0.1991, 192^2 x 2.4e-6 = 0.0885, 48^2 x 2.4e-6 = 0.00553 N m s/rad;
    none by default."""
    plant = _arm(MOTOR_DAMPING)
    damping = [plant.GetJointByName(f"joint{i + 1}").default_damping() for i in range(3)]
    assert damping == pytest.approx([0.19907, 0.088474, 0.0055296], rel=1e-4)
    default = _arm(0.0)
    assert [default.GetJointByName(f"joint{i + 1}").default_damping() for i in range(3)] == [
        0.0
    ] * 3


def test_the_observer_reads_the_damping_torque_as_a_force_below_the_tolerance():
    """At safe_contact's contact pose (0.15, -0.25, pi/2), the tip moving along the normal
    at v, the joints' damping torque B q' (q' = J^-1 (v, 0, 0)) shows in F_hat as
    b_m (J^-T N^2 J^-1)_xx v = 2.4e-6 x 1.75e6 v = 4.2 N s/m x v: 0.10 N at v_adv = 24 mm/s,
    a tenth of F_tol = 0.2 Fr = 1.0 N. The observer's residual at steady state equals the
    damping torque (it is the external torque it sees)."""
    plant = _arm(MOTOR_DAMPING)
    pose = [0.15, -0.25, math.pi / 2]
    q = SolvePlanarInverseKinematics(
        plant, "fingertip", pose, [-0.45, 1.66, 0.36], coordinates=PLANAR_COORDINATES
    )
    tip = ContactFrame(frame_name="fingertip", coordinates=PLANAR_COORDINATES, normal_axis=0)
    observer = ContactForceObserver(plant, contact=tip, gain=100.0)
    context = observer.CreateDefaultContext()
    speed = 0.024
    jacobian_rows = _jacobian(plant, q)
    joint_speeds = np.linalg.solve(jacobian_rows, [speed, 0.0, 0.0])
    observer.estimated_state_input.FixValue(context, np.concatenate([q, joint_speeds]))
    observer.actuation_input.FixValue(context, np.zeros(3))
    damping = np.array(RATIOS) ** 2 * MOTOR_DAMPING
    observer.set_external_torque(context, -damping * joint_speeds)
    error = observer.contact_force_output.Eval(context)[0]
    assert error == pytest.approx(4.2 * speed, rel=0.02)
    assert abs(error) < 0.15 * TOLERANCE_SHARE * 5.0


def _jacobian(plant, q):
    kinematics = PlanarFrameKinematics(plant, "fingertip", coordinates=PLANAR_COORDINATES)
    kinematics.set_state(np.concatenate([q, np.zeros(3)]))
    return np.array(kinematics.jacobian(), dtype=float)


def test_with_ten_times_the_stated_friction_nothing_is_flagged_and_a_dropout_is_caught():
    """paper_stiffness_step with the layer, the ideal sensor and 10 x the stated friction:
    no detection before the fault (the observer's error, 10 x 5.0 N s/m at this arm's pose
    (0.2, -0.25) times the approach's 9.3 mm/s, is 0.46 N, under F_tol = 1.0 N), and a
    reading that drops to zero at 0.6 s is caught as implausible within 4 T = 20 ms, as
    without friction (test_safety_closed_loop.py)."""
    scenario = load_scenario(
        "paper_stiffness_step",
        [
            "duration=0.7",
            "wall.stiffness_steps=[]",
            "sensor.kind=ideal",
            "admittance.max_force=10",
            "safety.enabled=true",
            f"arm.motor_damping={10 * MOTOR_DAMPING}",
            "faults=[{kind: sensor_zero, start: 0.6, end: 0.7, value: 0}]",
        ],
    )
    result = run_scenario(scenario)
    detections = result.metrics["safety"]["detections"]
    assert all(d["time"] >= 0.6 for d in detections)
    (fault,) = result.metrics["faults"]
    assert fault["detected_kind"] == "implausible"
    assert 0.0 < fault["detection_delay"] <= 0.02
    assert result.metrics["peak_force"] <= 10.0
