"""The Cartesian PID motion controller of the paper (eq. 14-16).

``CartesianPid`` is a small Diagram. Its law, ``CartesianPidLaw``
(systems/cartesian_pid_law.py), is a Python LeafSystem that computes the torque and the
rate of the integral term in one calc per evaluation. The continuous controller keeps that
integral in Drake's ``Integrator`` (a C++ primitive) and splits the law's output with a
``Demultiplexer``, so that each derivative evaluation of a closed loop calls the PID's
Python once (a LeafSystem with its own continuous state needs three: the law, its output
and its derivatives). The sampled controller keeps the integral and the held torque as
the law's discrete states, and outputs the held torque directly. In six dimensions the
rotational error is the rotation vector of R_d R^T (systems/cartesian_pid_law.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Multiplexer

from admittance.systems.cartesian_pid_law import CartesianPidLaw
from admittance.systems.law_integral import AddLawIntegral
from admittance.systems.posture_task import PostureTask
from admittance.systems.spatial_kinematics import frame_kinematics

__all__ = ["CartesianPid", "PostureTask"]


def _check_frame_actuated(plant, frame_name: str) -> None:
    """Raises ValueError unless every joint that moves `frame_name` has an actuator."""
    body_index = plant.GetFrameByName(frame_name).body().index()
    actuated = {
        plant.get_joint_actuator(index).joint().index() for index in plant.GetJointActuatorIndices()
    }
    for joint_index in plant.GetJointIndices():
        joint = plant.get_joint(joint_index)
        # (A weld moves no body: Drake's GetBodiesKinematicallyAffectedBy gives none for it.)
        if joint_index in actuated:
            continue
        if body_index in plant.GetBodiesKinematicallyAffectedBy([joint_index]):
            raise ValueError(
                f"the Cartesian PID needs a fully actuated arm: joint '{joint.name()}' moves "
                f"'{frame_name}' but has no actuator"
            )


class CartesianPid(Diagram):
    """Cartesian PID with joint torques through the Jacobian transpose (paper eq. 14-16).

        ec = Xc - h(q),  dec/dt = dXc/dt - J(q) v                        (eq. 15)
        F_PID = Kp ec + Kd dec/dt + Ki integral(ec)                      (eq. 14)
        tau = clip(J(q)^T F_PID, -effort_limit, effort_limit)            (eq. 16)

    X of the controlled frame, its rate J v and J come from the ``kinematics`` input: the
    output of a ``PlanarKinematics`` (or ``SpatialKinematics``, for rx, ry, rz) of the
    same plant, frame and task space. The task space is given at construction: which
    coordinates of the frame (TASK_COORDINATES: its origin's x, y, z, its rotation theta
    about z, or its rotation vector rx, ry, rz) measured in which frame: (x, y, theta)
    in world for a planar arm. A finger of a hand is controlled on (x, y) of
    its tip in a frame fixed at the face it touches, and drives only its own joints. The
    angle error is wrapped to [-pi, pi]; the rotation error is log(R_d R^T) (see the
    module). The commanded velocity is whatever the caller wires in; the project feeds
    dXd/dt only, so the admittance offset Xr is never differentiated. Torques are clipped
    to the actuators' effort limits read from the plant, and mapped to the actuation
    vector through the plant's actuation matrix. By default there is no gravity
    compensation, as in the paper (the integral term carries the arm's weight); a real
    arm's adds g(q), and a redundant arm's a posture in the null space of J
    (``gravity_compensation``, ``posture``; the ``state`` input then reads [q; v]). While
    an actuator saturates, back-calculation anti-windup pulls the integral back (see
    ``CartesianPidLaw._integral_rate``), so a blocked arm does not wind it up.

    Inside: the law (``CartesianPidLaw``, named ``law``) and, for the continuous
    controller, ``integral`` (Drake's ``Integrator``, state z = integral(ec)) fed with dz/dt
    through ``split`` (a ``Demultiplexer`` of the law's [tau; dz/dt]). With ``period > 0``
    the controller is sampled: at each sample the torque is computed and held (zero-order
    hold) and the integral advances by period * ec; nothing runs between samples.

    .. pydrake_system::

        name: CartesianPid
        input_ports:
        - commanded_position
        - commanded_velocity
        - kinematics
        - state (with gravity compensation or a posture task)
        output_ports:
        - actuation
    """

    def __init__(
        self,
        plant,
        *,
        frame_name: str,
        coordinates: Sequence[str],
        kp: float | Sequence[float],
        kd: float | Sequence[float],
        ki: float | Sequence[float],
        period: float = 0.0,
        expressed_in: str = "world",
        gravity_compensation: bool = False,
        posture: PostureTask | None = None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant (the arm, or a hand with its object).
            frame_name: the controlled frame (the contact point's).
            coordinates: the task vector X, names among TASK_COORDINATES.
            kp, kd, ki: diagonal gains on X: N/m, N s/m, N/(m s) and the rotational
                equivalents (N m/rad, N m s/rad, N m/(rad s)). kp > 0, kd >= 0, ki >= 0.
            period: 0 for a continuous controller, otherwise its sampling period in s.
            expressed_in: the frame X is measured and expressed in (fixed in world).
            gravity_compensation: add g(q) = -tau_g(q) from the plant (the ``state``
                input is then declared).
            posture: a joint-space posture task in the null space of J (systems/
                posture_task.py), or None (with one, the ``state`` input is declared).
        """
        Diagram.__init__(self)
        self._kinematics = frame_kinematics(
            plant, frame_name, coordinates=coordinates, expressed_in=expressed_in
        )
        _check_frame_actuated(plant, frame_name)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem(
            "law",
            CartesianPidLaw(
                plant,
                kp=kp,
                kd=kd,
                ki=ki,
                period=period,
                coordinates=coordinates,
                gravity_compensation=gravity_compensation,
                posture=posture,
            ),
        )
        self._law = law
        self._actuation_from_generalized = law._actuation_from_generalized
        self._integrator = None
        inputs = builder.AddNamedSystem("inputs", Multiplexer(law.input_sizes))
        builder.Connect(inputs.get_output_port(), law.law_input)
        names = ["commanded_position", "commanded_velocity", "kinematics"]
        if law.uses_state:
            names.append("state")
        for index, name in enumerate(names):
            builder.ExportInput(inputs.get_input_port(index), name)
        if law.period == 0.0:
            self._integrator = AddLawIntegral(
                builder,
                law.actuation_and_integral_rate_output,
                inputs.get_input_port(len(names)),
                "actuation",
            )
        else:
            builder.ExportOutput(law.actuation_output, "actuation")
        builder.BuildInto(self)
        self.commanded_position_input = self.GetInputPort("commanded_position")
        self.commanded_velocity_input = self.GetInputPort("commanded_velocity")
        self.kinematics_input = self.GetInputPort("kinematics")
        #: The plant's state [q; v] (None unless gravity compensation or a posture is on).
        self.state_input = self.GetInputPort("state") if law.uses_state else None
        self.actuation_output = self.GetOutputPort("actuation")

    # --- accessors -----------------------------------------------------------------------
    @property
    def law(self) -> CartesianPidLaw:
        return self._law

    @property
    def gains(self) -> dict[str, np.ndarray]:
        return self._law.gains

    @property
    def period(self) -> float:
        return self._law.period

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The task coordinates, in the order of X and of the gains."""
        return self._law.coordinates

    @property
    def effort_limits(self) -> np.ndarray:
        return self._law.effort_limits

    def set_integral(self, context, integral) -> None:
        """Sets the integral of the Cartesian error (e.g. to hold the arm at t = 0).

        Args:
            context: this PID's context (``GetMyMutableContextFromRoot`` in a diagram).
            integral: z, one value per task coordinate.
        """
        integral = np.asarray(integral, dtype=float)
        if self._integrator is not None:
            self._integrator.set_integral_value(
                self.GetMutableSubsystemContext(self._integrator, context), integral
            )
        else:
            self._law.set_integral(self.GetMutableSubsystemContext(self._law, context), integral)

    def cartesian_error(self, context) -> np.ndarray:
        """ec = Xc - h(q) (angle wrapped) at the inputs of this PID's context."""
        return self._law.cartesian_error(self.GetSubsystemContext(self._law, context))

    def holding_integral(self, state, generalized_force) -> np.ndarray:
        """The integral at which, with zero error, the PID applies `generalized_force`.

        Used to start the arm at rest held against gravity: solves J^T Ki z = tau. When J
        is not square (a finger of a hand, whose J has a column per joint of the plant),
        over the actuated joints in the least-squares sense: exact for the joints that
        move the frame, the others being other PIDs' to hold.
        """
        kinematics = self._kinematics
        kinematics.set_state(state)
        jacobian = kinematics.jacobian()
        if jacobian.shape[0] == jacobian.shape[1] == len(self._actuation_from_generalized):
            wrench = np.linalg.solve(jacobian.T, generalized_force)
        else:
            selection = self._actuation_from_generalized
            wrench = np.linalg.lstsq(
                selection @ jacobian.T, selection @ np.asarray(generalized_force), rcond=None
            )[0]
        ki = self._law.gains["ki"]
        if np.any(ki == 0):
            raise ValueError("holding the arm through the integral needs ki > 0 on all axes")
        return wrench / ki
