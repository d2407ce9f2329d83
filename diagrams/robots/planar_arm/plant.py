"""The paper's planar arm: its MultibodyPlant from a URDF, its one force-controlled point
(the fingertip against the wall), and inverse kinematics.

Any planar URDF works: the kinematics come from the plant, not from hand-written formulas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.robots.description import ForcePoint, force_law, sensor_chain
from admittance.diagrams.robots.planar_arm.scenario import ArmConfig, Scenario
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.planar_kinematics import PLANAR_COORDINATES

__all__ = [
    "WALL_NORMAL_AXIS",
    "AddPlanarArm",
    "AddScenarioArm",
    "ArmModel",
    "baseline_gains",
    "fingertip_point",
]

GRAVITY_W = np.array([0.0, -9.81, 0.0])
# The wall-normal axis of X = (x, y, theta), the only force-controlled axis in the paper.
WALL_NORMAL_AXIS = 0


def AddPlanarArm(
    builder: DiagramBuilder,
    urdf: str | Path,
    *,
    fingertip_frame: str = "fingertip",
    reflected_inertia: bool = False,
    payload_mass: float = 0.0,
    motor_damping: float = 0.0,
):
    """Adds the arm of the URDF file `urdf` as a continuous MultibodyPlant, gravity along -y.

    Args:
        urdf: the URDF file (a path; ``ArmConfig.urdf_path()`` resolves a scenario's).
        fingertip_frame: the frame at the contact point, which the URDF must have.
        reflected_inertia: keep the motors' reflected inertia (``drake:rotor_inertia`` and
            ``drake:gear_ratio``); False zeroes it, the paper's rigid-body model.
        payload_mass: a point mass welded at the fingertip frame, kg (0 = none): a tool or
            a grasped part the URDF does not carry.
        motor_damping: viscous friction at each motor shaft, N m s/rad: joint i gets
            N_i^2 times it as its damping (N_i the actuator's gear ratio in the URDF).

    Returns:
        (plant, scene_graph), the plant finalized.

    Raises:
        ScenarioError: (arm.fingertip_frame) the URDF has no such frame.
    """
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    _load_arm(plant, urdf, fingertip_frame, reflected_inertia, payload_mass, motor_damping)
    return plant, scene_graph


def _load_arm(
    plant,
    urdf,
    fingertip_frame: str,
    reflected_inertia: bool,
    payload_mass: float,
    motor_damping: float = 0.0,
):
    (model,) = Parser(plant).AddModels(str(urdf))
    plant.mutable_gravity_field().set_gravity_vector(GRAVITY_W)
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_mutable_joint_actuator(index)
        if not reflected_inertia:
            actuator.set_default_rotor_inertia(0.0)
        if motor_damping > 0.0:
            # The motor's viscous friction seen at the joint through the gearhead.
            ratio = actuator.default_gear_ratio()
            actuator.joint().set_default_damping(ratio**2 * motor_damping)
    if not plant.HasFrameNamed(fingertip_frame):
        raise ScenarioError(f"arm.fingertip_frame: the URDF has no frame named '{fingertip_frame}'")
    if payload_mass > 0.0:
        payload = plant.AddRigidBody(
            "payload",
            model,
            SpatialInertia(payload_mass, np.zeros(3), UnitInertia(0.0, 0.0, 0.0)),
        )
        plant.WeldFrames(plant.GetFrameByName(fingertip_frame), payload.body_frame())
    plant.Finalize()


def ArmModel(arm: ArmConfig) -> MultibodyPlant:
    """The arm as its URDF describes it (reflected inertia per `arm`), without the payload
    of ``arm.payload_mass``: a plant of its own, in no diagram, for a controller's model."""
    plant = MultibodyPlant(time_step=0.0)
    _load_arm(plant, arm.urdf_path(), arm.fingertip_frame, arm.reflected_inertia, 0.0)
    return plant


def AddScenarioArm(builder: DiagramBuilder, arm: ArmConfig):
    """:func:`AddPlanarArm` with the settings of a scenario's `arm` section."""
    return AddPlanarArm(
        builder,
        arm.urdf_path(),
        fingertip_frame=arm.fingertip_frame,
        reflected_inertia=arm.reflected_inertia,
        payload_mass=arm.payload_mass,
        motor_damping=arm.motor_damping,
    )


def baseline_gains(scenario: Scenario) -> dict[str, float]:
    """The gains the baselines run with (matched to the paper's law, or manual).

    Matched: the paper's law, with the PID's stiffness Kp, is an integrator of gain
    Gamma Kp from force error to Xr, whose force loop crosses over at Kp Gamma Kp; the
    classical admittance's damper 1 / (Gamma Kp) has the same crossover, critically damped
    by its mass, and the adaptive impedance adapts five times slower (docs/evidence/comparison.md).
    """
    controller = scenario.controller
    if controller.tuning == "manual":
        return {
            "mass": controller.mass,
            "damping": controller.damping,
            "stiffness": controller.stiffness,
            "adaptation_rate": controller.adaptation_rate,
        }
    kp = scenario.pid.kp[WALL_NORMAL_AXIS]
    integral_gain = scenario.admittance.gamma * kp  # Gamma K, m/(N s)
    crossover = kp * integral_gain  # rad/s
    damping = 1.0 / integral_gain
    return {
        "mass": damping**2 / (4.0 * kp),
        "damping": damping,
        "stiffness": 0.0,
        "adaptation_rate": crossover / 5.0,
    }


def fingertip_point(scenario: Scenario) -> ForcePoint:
    """The arm's one force-controlled point: the fingertip, X = (x, y, theta) in world,
    force along the wall's normal (+x), with the scenario's sensor, law and PID."""
    admittance, controller, wall = scenario.admittance, scenario.controller, scenario.wall
    return ForcePoint(
        name="",
        frame=scenario.arm.fingertip_frame,
        coordinates=PLANAR_COORDINATES,
        force_axes=(WALL_NORMAL_AXIS,),
        sensor=sensor_chain(
            scenario.sensor,
            noise_period=scenario.sensor.noise_period,
            hysteresis=scenario.sensor.hysteresis,
            drift=scenario.sensor.drift,
            faults=scenario.faults,
        ),
        law=force_law(
            scenario.controller_kind,
            admittance,
            period=admittance.period,
            max_force=admittance.max_force,
            force_bound_gain=admittance.force_bound_gain,
            baseline=baseline_gains(scenario),
            surface_estimate=(
                wall.position + controller.wall_position_error,
                wall.stiffness * (1.0 + controller.stiffness_error),
            ),
        ),
        kp=list(scenario.pid.kp),
        kd=list(scenario.pid.kd),
        ki=list(scenario.pid.ki),
        pid_period=scenario.pid.period,
    )
