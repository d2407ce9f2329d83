"""The controller process's law: the project's own systems, the sampled optimal admittance
law (``systems.optimal_admittance``, eq. 10 with the corrected sign) and the 6-D Cartesian
PID (``systems.cartesian_pid``, eq. 14-16), on the controller's own model of the spatial
scenario's arm, with the scenario's numbers (``spatial_point``: pid.kp/kd/ki, Gamma,
alpha, the travel bounds, the posture task), stepped once per status message.

Between the messages and the systems:

* the model is the scenario's plant (``AddSpatialArm``: the arm, its tool, the control
  frame E) in a diagram of its own with the point's kinematics, its PID and the plan Xd(t)
  of ``spatial_plan`` (the approach onto the planned table); the status's q, v are set as
  the model's state and the status's time as the diagram's time;
* the PID runs without gravity compensation: the robot's torque interface (the station's)
  adds it, so the command excludes it;
* the force is the wrist wrench of ``lcmt_force_torque`` (in the sensor frame, the tool's
  frame at ``tool_weld``) read along E's z, into the table: F = -(R_ES f_S) . e_z;
* Fr(t) is the scenario's ramp ``spatial_force_reference`` scaled to the Fr in force;
* each status is one sample of both sampled systems (n samples after a gap of n periods),
  in the order of the simulated loop: both updates are computed from the state before
  either (the PID's Xc = Xd + Xr reads the offset the law held since the previous sample),
  then both applied, then the PID's held torque is the command.

A parameter message changes Fr (an input), or Gamma, alpha, Fmax: the law is rebuilt with
the new values and its state carried over, its integral z rescaled so that Gamma K z, the
offset's integral part, is unchanged (bumpless: with alpha = 0, as the scenario's, Xr does
not move at all).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Demultiplexer, PassThrough, TrajectorySource

from admittance.diagrams.loop.point import (
    AddCommandedPosition,
    AddForceController,
    AddPointKinematics,
    AddPointPid,
)
from admittance.diagrams.robots.spatial_arm.joint_command import DifferentialIk, tool_stiffness
from admittance.diagrams.robots.spatial_arm.loop import (
    BuildSpatialLoop,
    CheckSpatialPlan,
    spatial_force_reference,
    spatial_plan,
)
from admittance.diagrams.robots.spatial_arm.plant import (
    CONTROL_FRAME,
    NORMAL_AXIS,
    TOOL_BODY,
    AddSpatialArm,
    spatial_point,
)
from admittance.diagrams.robots.spatial_arm.sampled_gains import (
    SampledGainCheck,
    check_sampled_gains,
    normal_model_at,
)
from admittance.diagrams.robots.spatial_arm.scenario import SPATIAL_COORDINATES, SpatialScenario
from admittance.systems.spatial_kinematics import SpatialFrameKinematics

__all__ = ["SpatialControlLaw", "start_positions"]

SIZE = len(SPATIAL_COORDINATES)
LAW_PARAMETERS = ("force_reference", "gamma", "alpha", "max_force")


def start_positions(scenario: SpatialScenario) -> np.ndarray:
    """The arm's joints at t = 0, where the simulated loop starts it (``arm.initial_joints``,
    or the inverse kinematics of the plan's start from ``arm.joint_guess``): read from the
    loop that ``simulate`` builds, so both start from the same posture.

    Raises:
        ScenarioError: the start is out of reach, or the plan cannot be reached, followed
            or pressed with (one line; robots.spatial_arm.loop.CheckSpatialPlan, as
            simulate checks).
    """
    loop = BuildSpatialLoop(scenario)
    CheckSpatialPlan(loop)
    return loop.initial_positions


class SpatialControlLaw:
    """The scenario's force law and Cartesian PID on the controller's model (module
    docstring); :meth:`step` is one sample."""

    def __init__(
        self,
        scenario: SpatialScenario,
        *,
        max_force: float = math.inf,
        force_bound_gain=4.0,
        joint_gains=None,
    ) -> None:
        """`joint_gains` (plant, positions) -> the robot's joint controller's gains
        (``joint_stiffness`` and ``joint_damping``, one per joint) selects position mode:
        the law's K is then their stiffness seen at the tool at the start
        (``joint_command.tool_stiffness``) and :meth:`step` returns joint positions from
        the differential inverse kinematics."""
        self.scenario = scenario
        builder = DiagramBuilder()
        plant, _, _ = AddSpatialArm(builder, scenario)
        self.plant = plant
        self.initial_positions = start_positions(scenario)
        point = spatial_point(scenario, plant, self.initial_positions)
        self.point = dataclasses.replace(point, gravity_compensation=False)
        plan = builder.AddNamedSystem("plan", TrajectorySource(spatial_plan(scenario), 1))
        split = builder.AddNamedSystem("plan_split", Demultiplexer([SIZE, SIZE]))
        builder.Connect(plan.get_output_port(), split.get_input_port())
        kinematics = AddPointKinematics(builder, plant, self.point)
        self.pid = AddPointPid(builder, plant, self.point, kinematics, split.get_output_port(1))
        commanded = AddCommandedPosition(builder, self.point, split.get_output_port(0), self.pid)
        self._commanded = commanded
        offset = builder.AddNamedSystem("reference_offset", PassThrough(SIZE))
        builder.Connect(offset.get_output_port(), commanded.get_input_port(1))
        builder.ExportInput(offset.get_input_port(), "reference_offset")
        self.model = builder.Build()
        self.context = self.model.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self._pid_context = self.pid.GetMyMutableContextFromRoot(self.context)
        self._offset_input = self.model.GetInputPort("reference_offset")
        self._offset_input.FixValue(self.context, np.zeros(SIZE))
        self._tool = plant.GetBodyByName(TOOL_BODY).body_frame()
        self._control_frame = plant.GetFrameByName(CONTROL_FRAME)
        self._ramp = spatial_force_reference(scenario)
        self.force_reference = scenario.force_reference
        self.gamma = self.point.law.gamma
        self.alpha = self.point.law.alpha
        self.max_force = float(max_force)
        self.force_bound_gain = float(force_bound_gain)
        self._kinematics = SpatialFrameKinematics(
            plant,
            self.point.frame,
            coordinates=SPATIAL_COORDINATES,
            expressed_in=self.point.expressed_in,
        )
        self._normal_model = None
        self.position_mode = joint_gains is not None
        self._law_point = self.point
        self.ik = None
        if self.position_mode:
            self.ik = DifferentialIk(
                plant, self.point.frame, self.point.expressed_in, self.initial_positions
            )
            _, jacobian = self.ik.pose_and_jacobian(self.initial_positions)
            gains = joint_gains(plant, self.initial_positions)
            self.tool_stiffness = tool_stiffness(jacobian, gains["joint_stiffness"])
            self.tool_damping = tool_stiffness(jacobian, gains["joint_damping"])
            kp = list(self.point.kp)
            kp[NORMAL_AXIS] = self.tool_stiffness
            self._law_point = dataclasses.replace(self.point, kp=kp)
        self._started = False
        self._law = None
        self._build_law()

    def check_gains(self, period: float, delay: int = 1, positions=None) -> SampledGainCheck:
        """The PID's and the law's gains (Gamma as it is now) against the sampled loop at
        `period` with the command `delay` periods late (the package's ``sampled_gains``), the arm
        at `positions` (None: where the model's state is now). The apparent mass along the
        normal is the one at the first check (it moves little over a press)."""
        context = self.plant.CreateDefaultContext()
        if positions is None:
            positions = self.plant.GetPositions(self._plant_context)
        self.plant.SetPositions(context, np.asarray(positions, dtype=float))
        paper_law = self.scenario.controller.kind == "optimal_admittance"
        if self._normal_model is None and paper_law:
            model = normal_model_at(self.scenario, positions, period)
            if self.position_mode:  # the inner loop is the joint controller's
                model = dataclasses.replace(
                    model, kp=self.tool_stiffness, kd=self.tool_damping, ki=0.0
                )
            self._normal_model = model
        self._kinematics.set_state(np.concatenate([positions, np.zeros(len(positions))]))
        return check_sampled_gains(
            self.scenario,
            self.plant,
            context,
            self._kinematics.jacobian(),
            period=period,
            delay=delay,
            gamma=self.gamma,
            model=self._normal_model,
            # In position mode the PID does not run: the joint controller is the robot's.
            kd=np.zeros(SIZE) if self.position_mode else None,
            force_loop=paper_law,
        )

    def _build_law(self) -> None:
        """(Re)builds the force law with the current Gamma, alpha and Fmax, carrying the
        previous law's state (its integral rescaled by the old Gamma over the new)."""
        law = dataclasses.replace(
            self.point.law,
            gamma=self.gamma,
            alpha=self.alpha,
            max_force=self.max_force,
            force_bound_gain=self.force_bound_gain,
        )
        builder = DiagramBuilder()
        system = AddForceController(builder, dataclasses.replace(self._law_point, law=law))
        diagram = builder.Build()
        context = diagram.CreateDefaultContext()
        law_context = system.GetMyMutableContextFromRoot(context)
        system.desired_force_input.FixValue(law_context, [0.0])
        system.measured_force_input.FixValue(law_context, [0.0])
        if self._law is not None:
            old_system, _, old_context = self._law
            law_context.get_mutable_discrete_state().SetFrom(old_context.get_discrete_state())
            integral = self.integral
            system.set_integral(
                law_context, integral * old_system.integral_gain / system.integral_gain
            )
        self._law = (system, diagram, law_context)

    @property
    def integral(self) -> np.ndarray:
        """z, the law's integral of the force error, N s."""
        system, _, context = self._law
        return context.get_discrete_state(0).CopyToVector()

    @property
    def offset(self) -> float:
        """Xr along E's z held by the law (into the table), m."""
        system, _, context = self._law
        return float(system.reference_offset_output.Eval(context)[NORMAL_AXIS])

    def set_parameters(self, **values: float) -> None:
        """Changes Fr, Gamma, alpha or Fmax (bumpless: see the module docstring)."""
        for key, value in values.items():
            if key not in LAW_PARAMETERS:
                raise ValueError(f"unknown law parameter {key!r}")
            setattr(self, key, float(value))
        if set(values) - {"force_reference"}:
            self._build_law()

    def desired_force(self, time: float) -> float:
        """Fr(t): the scenario's ramp, scaled to the Fr in force, N."""
        ramp = float(self._ramp.value(time)[0, 0])
        return ramp * self.force_reference / self.scenario.force_reference

    def set_state(self, time: float, q, v) -> None:
        """The model at the status: its time and the arm's joints."""
        self.context.SetTime(time)
        self.plant.SetPositionsAndVelocities(self._plant_context, np.concatenate([q, v]))

    def force_along_normal(self, force_S) -> float:
        """F = -(R_ES f_S) . e_z: the wrist's force on the tool, in its sensor frame, as the
        tool's force on the table along E's z (the model's state set first), N."""
        R_ES = self.plant.CalcRelativeRotationMatrix(
            self._plant_context, self._control_frame, self._tool
        )
        value = -R_ES.multiply(np.asarray(force_S, dtype=float))[NORMAL_AXIS]
        return float(value) if math.isfinite(value) else math.nan

    def step(self, time: float, q, v, force: float, samples: int = 1) -> np.ndarray:
        """`samples` samples at the status (time, q, v) with the measured force (NaN: a
        failed measurement, the law then holds its offset): one per period since the
        previous status answered (a status lost or skipped leaves its period to the next,
        its inputs held); returns the joint torques, N m, or in position mode the joint
        positions, rad (the inverse kinematics of Xc = Xd + Xr, Xr the offset the law held
        since the previous sample, as the PID reads it)."""
        self.set_state(time, q, v)
        if self.position_mode and not self._started:
            self.ik.reset(q)
        self._started = True
        system, _, law_context = self._law
        system.desired_force_input.FixValue(law_context, [self.desired_force(time)])
        system.measured_force_input.FixValue(law_context, [force])
        for _ in range(max(1, samples)):
            self._sample(system, law_context)
        if self.position_mode:
            adder_context = self._commanded.GetMyContextFromRoot(self.context)
            return self.ik.step(self._commanded.get_output_port().Eval(adder_context))
        return self.pid.actuation_output.Eval(self._pid_context).copy()

    def _sample(self, system, law_context) -> None:
        held = system.reference_offset_output.Eval(law_context)
        self._offset_input.FixValue(self.context, held)
        if self.position_mode:  # the law alone: the joint controller is the robot's
            law_update = system.EvalUniquePeriodicDiscreteUpdate(law_context).Clone()
            law_context.get_mutable_discrete_state().SetFrom(law_update)
            return
        law_update = system.EvalUniquePeriodicDiscreteUpdate(law_context)
        pid_update = self.pid.EvalUniquePeriodicDiscreteUpdate(self._pid_context)
        # (Both are computed before either is applied.)
        law_update, pid_update = law_update.Clone(), pid_update.Clone()
        law_context.get_mutable_discrete_state().SetFrom(law_update)
        self._pid_context.get_mutable_discrete_state().SetFrom(pid_update)
