"""The grasp's held equilibrium: the frozen scenario simulated until its forces settle,
then polished by Newton steps on f(x) = x (f: the map over one period, :mod:`.step_map`).

With the regularized friction of SAP and finger3 pressing with more than the brick's
weight, the brick creeps upwards at a steady speed: there is no exact fixed point, and the
residual |f(x) - x| / h at the returned state is reported with the brick's speed.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context

from admittance.diagrams.robots.planar_gripper.loop import (
    BuildGrasp,
    GraspLoop,
    SetGraspInitialConditions,
)
from admittance.diagrams.robots.planar_gripper.plant import (
    BRICK_JOINTS,
    FINGER_COORDINATES,
    NORMAL_AXIS,
    contact_frame,
    tip_centre_frame,
)
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario
from admittance.diagrams.robots.planar_gripper.step_map import (
    RELATIVE_STEP,
    get_discrete_state,
    resolved_basis,
    set_discrete_state,
    step_jacobian,
    step_once,
    stepped_forces,
)
from admittance.diagrams.scenario.schema import ScenarioError
from admittance.systems.planar_kinematics import PlanarFrameKinematics

__all__ = [
    "FindGraspEquilibrium",
    "GraspEquilibrium",
    "LinearizeGraspStep",
    "static_grasp",
]

# Time held after the force ramp before the state is taken as the equilibrium, s.
SETTLE_TIME = 1.0
# Newton steps on f(x) - x = 0 after settling (each needs one Jacobian, ~0.5 s).
POLISH_STEPS = 3


def static_grasp(scenario: GraspScenario) -> GraspScenario:
    """The grasp with everything that varies frozen: no sensor noise, no disturbance."""
    if scenario.time_step <= 0:
        raise ScenarioError(
            "time_step: the grasp's stability is analysed for the sampled loop that runs "
            "(time_step > 0); Drake cannot linearize the continuous plant's point contact"
        )
    if scenario.controller.kind != "optimal_admittance":
        raise ScenarioError(
            "controller.kind: the grasp's stability is analysed for optimal_admittance fingers"
        )
    frozen = copy.deepcopy(scenario)
    frozen.sensor.noise_std = 0.0
    frozen.disturbance.kind = "none"
    return frozen


@dataclass
class GraspEquilibrium:
    """The held grasp: the analysis diagram, its context at a sample time, the residual."""

    loop: GraspLoop
    context: Context
    # max |f(x) - x| / h at the returned state (the state's rate over one period).
    residual: float
    # The brick's (y, z, theta) rates, from its velocity state (m/s, rad/s).
    brick_velocity: np.ndarray
    # The residual before the Newton polish, and the Jacobian at the returned state.
    settled_residual: float
    jacobian: np.ndarray | None = None

    def describe(self) -> dict:
        """Every finger's tip (its face frame), forces and offset; the brick's pose."""
        loop, context = self.loop, self.context
        plant = loop.plant
        plant_context = plant.GetMyContextFromRoot(context)
        state = plant.GetPositionsAndVelocities(plant_context)
        forces = stepped_forces(loop, context)
        fingers = []
        for index, finger in enumerate(loop.fingers):
            kinematics = PlanarFrameKinematics(
                plant,
                tip_centre_frame(finger.name),
                coordinates=FINGER_COORDINATES,
                expressed_in=contact_frame(finger.name),
            )
            kinematics.set_state(state)
            port = finger.measured_force_output
            measured = port.Eval(port.get_system().GetMyContextFromRoot(context))
            offset = finger.admittance.reference_offset_output.Eval(
                finger.admittance.GetMyContextFromRoot(context)
            )
            reference = loop.scenario.force_reference[index]
            fingers.append(
                {
                    "finger": finger.name,
                    "force_reference": float(reference),
                    "normal_force": float(forces[index]),
                    "force_error": float(forces[index] - reference),
                    "measured_force": float(measured[0]),
                    "tip_position": [float(v) for v in kinematics.pose()],
                    "reference_offset": float(offset[NORMAL_AXIS]),
                }
            )
        q = plant.GetPositions(plant_context)
        brick = [float(q[plant.GetJointByName(name).position_start()]) for name in BRICK_JOINTS]
        return {
            "time": float(context.get_time()),
            "residual": self.residual,
            "settled_residual": self.settled_residual,
            "brick_pose": brick,
            "brick_velocity": [float(v) for v in self.brick_velocity],
            "fingers": fingers,
        }


def _brick_velocity(loop: GraspLoop, context: Context) -> np.ndarray:
    plant = loop.plant
    v = plant.GetVelocities(plant.GetMyContextFromRoot(context))
    return np.array([v[plant.GetJointByName(name).velocity_start()] for name in BRICK_JOINTS])


def FindGraspEquilibrium(
    scenario: GraspScenario,
    *,
    settle_time: float = SETTLE_TIME,
    polish_steps: int = POLISH_STEPS,
    relative_step: float = RELATIVE_STEP,
) -> GraspEquilibrium:
    """The held grasp of the frozen scenario: simulated until `settle_time` after the force
    ramp, then polished by `polish_steps` Newton steps on f(x) = x within the modes that
    have a fixed point (the iterate of least residual is kept). The Jacobian at the
    returned state comes with it.

    Raises:
        ScenarioError: a continuous or position-only grasp, or no finger in contact.
    """
    frozen = static_grasp(scenario)
    loop = BuildGrasp(frozen)
    context = loop.diagram.CreateDefaultContext()
    SetGraspInitialConditions(loop, context)
    simulator = Simulator(loop.diagram, context)
    simulator.Initialize()
    h = frozen.time_step
    steps = int(round((frozen.force_ramp_end + settle_time) / h))
    simulator.AdvanceTo(steps * h)
    context = context.Clone()  # at a sample time, its update pending

    def residual(x: np.ndarray) -> float:
        return float(np.max(np.abs(step_once(loop, context, x) - x))) / h

    x = get_discrete_state(context)
    settled = residual(x)
    best, best_x = settled, x
    for _ in range(polish_steps):
        # Newton on f(x) = x within the modes that have a fixed point: the near-neutral
        # ones (the brick's free directions, where it creeps) are left out.
        jacobian = step_jacobian(loop, context, relative_step)
        basis = resolved_basis(jacobian, h)
        r = step_once(loop, context, x) - x
        reduced = basis.T @ (jacobian - np.eye(x.size)) @ basis
        x = x + basis @ np.linalg.solve(reduced, -basis.T @ r)
        set_discrete_state(context, x)
        value = residual(x)
        if value < best:
            best, best_x = value, x
    set_discrete_state(context, best_x)
    jacobian = step_jacobian(loop, context, relative_step)
    forces = stepped_forces(loop, context)
    if not np.all(forces > 0):
        raise ScenarioError(f"scenario: the grasp does not hold (normal forces {forces} N)")
    return GraspEquilibrium(
        loop=loop,
        context=context,
        residual=best,
        brick_velocity=_brick_velocity(loop, context),
        settled_residual=settled,
        jacobian=jacobian,
    )


def LinearizeGraspStep(
    equilibrium: GraspEquilibrium, *, relative_step: float = RELATIVE_STEP
) -> np.ndarray:
    """A = df/dx over one period at the equilibrium (central differences, step
    relative_step max(|x_j|, 1) on entry j)."""
    return step_jacobian(equilibrium.loop, equilibrium.context, relative_step)
