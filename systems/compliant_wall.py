"""The compliant wall of the paper's environment model (eq. 4)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import max as scalar_max
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import Demultiplexer
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.task_kinematics import kinematics_size, task_coordinates

__all__ = ["CompliantWall", "CompliantWallLaw", "CompliantWallLaw_"]


class _CompliantWallLaw:
    """The law of the compliant wall (paper eq. 4); see ``CompliantWall``.

        F = Ke(t) * max(x_tip - Xe(t), 0)
        tau = -F J_x^T

    with x_tip and J_x (the row of x in J) read from the ``kinematics`` input. The one
    output ``contact_force_and_generalized_force`` = [F; tau] (1 + nv) is computed in
    one calc.

    .. pydrake_system::

        name: CompliantWallLaw
        input_ports:
        - kinematics
        output_ports:
        - contact_force_and_generalized_force
    """

    def _construct(
        self,
        plant,
        *,
        frame_name: str,
        coordinates: Sequence[str],
        position: float,
        stiffness: float,
        stiffness_steps: Sequence[tuple[float, float]],
        velocity: float,
        motion_start: float,
        motion_end: float,
        position_offsets: Sequence[tuple[float, float, float]],
        converter=None,
    ) -> None:
        """The arguments of ``CompliantWall``, every one given."""
        LeafSystem_[self._T].__init__(self, converter=converter)
        if not plant.HasFrameNamed(frame_name):
            raise ValueError(f"the plant has no frame named '{frame_name}'")
        coordinates = task_coordinates(coordinates)
        if "x" not in coordinates:
            raise ValueError(f"coordinates must hold x, the wall's normal, got {coordinates}")
        if not (math.isfinite(position)):
            raise ValueError(f"position must be finite, got {position}")
        if not (math.isfinite(stiffness) and stiffness > 0):
            raise ValueError(f"stiffness must be > 0 N/m, got {stiffness}")
        steps = [(float(t), float(k)) for t, k in stiffness_steps]
        times = [t for t, _ in steps]
        if any(not (math.isfinite(k) and k > 0) for _, k in steps):
            raise ValueError(f"stiffness_steps values must be > 0 N/m, got {steps}")
        if any(not math.isfinite(t) for t in times) or times != sorted(times):
            raise ValueError(f"stiffness_steps times must be finite and increasing: {times}")
        if not math.isfinite(velocity):
            raise ValueError(f"velocity must be finite, got {velocity}")
        if not (math.isfinite(motion_start) and motion_end >= motion_start):
            raise ValueError(f"motion_end ({motion_end}) must be >= motion_start ({motion_start})")
        offsets = [(float(a), float(b), float(d)) for a, b, d in position_offsets]
        if any(not (math.isfinite(a) and b > a and math.isfinite(d)) for a, b, d in offsets):
            raise ValueError(f"position_offsets need start < end and finite offsets: {offsets}")
        self._offsets = offsets
        self._plant = plant
        self._frame_name = frame_name
        self._coordinates = coordinates
        self._position = float(position)
        self._stiffness = float(stiffness)
        self._steps = steps
        self._velocity = float(velocity)
        self._motion_start = float(motion_start)
        self._motion_end = float(motion_end)
        self._static = self._velocity == 0.0 and not self._offsets
        num_velocities = plant.num_velocities()
        self._num_velocities = num_velocities
        # x in X, and J_x, the row of x in J, in the kinematics vector [X; dX/dt; J row
        # by row].
        size = len(coordinates)
        self._x_index = coordinates.index("x")
        first = 2 * size + self._x_index * num_velocities
        self._jacobian_x = slice(first, first + num_velocities)

        self.kinematics_input = self.DeclareVectorInputPort(
            "kinematics", kinematics_size(num_velocities, size)
        )
        self.contact_force_and_generalized_force_output = self.DeclareVectorOutputPort(
            "contact_force_and_generalized_force",
            1 + num_velocities,
            self._CalcLaw,
            prerequisites_of_calc={self.time_ticket(), self.kinematics_input.ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _CompliantWallLaw._construct(
            self,
            other._plant.ToScalarType[self._T](),
            frame_name=other._frame_name,
            coordinates=other._coordinates,
            position=other._position,
            stiffness=other._stiffness,
            stiffness_steps=other._steps,
            velocity=other._velocity,
            motion_start=other._motion_start,
            motion_end=other._motion_end,
            position_offsets=other._offsets,
            converter=converter,
        )

    # --- schedules (plain floats: time is not differentiated) -------------------------
    def stiffness_at(self, time: float) -> float:
        """Ke(t), N/m."""
        stiffness = self._stiffness
        for step_time, step_stiffness in self._steps:
            if time >= step_time:
                stiffness = step_stiffness
        return stiffness

    def position_at(self, time: float) -> float:
        """Xe(t), m."""
        if self._static:
            return self._position
        moving = min(max(time - self._motion_start, 0.0), self._motion_end - self._motion_start)
        offset = sum(d for start, end, d in self._offsets if start <= time < end)
        return self._position + self._velocity * moving + offset

    def discontinuity_times(self) -> list[float]:
        """Times at which Ke jumps or the wall starts or stops (for the integrator)."""
        times = [t for t, _ in self._steps]
        times += [t for start, end, _ in self._offsets for t in (start, end)]
        if self._velocity != 0.0:
            times += [self._motion_start]
            if math.isfinite(self._motion_end):
                times += [self._motion_end]
        return sorted(times)

    # --- the law ----------------------------------------------------------------------
    def _CalcLaw(self, context, output) -> None:
        T = self._T
        kinematics = self.kinematics_input.Eval(context).tolist()  # floats or AutoDiffXd
        time = context.get_time()
        if T is not float:
            time = time.value() if hasattr(time, "value") else float(time)
        penetration = kinematics[self._x_index] - self.position_at(time)  # x of X
        if T is float:
            force = self.stiffness_at(time) * max(penetration, 0.0)
        else:
            force = self.stiffness_at(time) * scalar_max(penetration, T(0.0))
        # The force (-F, 0, 0) at the frame's origin, as generalized forces: -F J_x^T.
        push = -force
        output.SetFromVector([force] + [push * j for j in kinematics[self._jacobian_x]])


@TemplateSystem.define("CompliantWallLaw_", T_list=[float, AutoDiffXd])
def CompliantWallLaw_(T):
    class Impl(_CompliantWallLaw, LeafSystem_[T]):
        __doc__ = _CompliantWallLaw.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _CompliantWallLaw._construct
        _construct_copy = _CompliantWallLaw._construct_copy

    return Impl


CompliantWallLaw = CompliantWallLaw_[None]


class CompliantWall(Diagram):
    """A unilateral linear-spring wall normal to world +x (paper eq. 4).

        F = Ke(t) * max(x_tip - Xe(t), 0)      (compressive, >= 0; the wall never pulls)

    is applied to the frame's origin as the world force (-F, 0, 0), and output as the
    true contact force. x_tip is the x entry of the ``kinematics`` input, the output of a
    ``PlanarKinematics`` of the same plant, frame and ``coordinates``, measured in world
    (systems/planar_kinematics.py). Ke steps at given times; Xe moves along +x at a
    given velocity between a start and an end time:

        Ke(t) = stiffness_i for the last step time t_i <= t (initial value before any)
        Xe(t) = position + velocity * clamp(t - motion_start, 0, motion_end - motion_start)
                + sum of the offsets whose interval holds t

    There is no damping and no friction: the wall is the pure spring of eq. 4, and Ke is
    the equivalent stiffness of the wall, the silicone fingertip and the sensor together.

    The force reaches the plant as generalized forces, ``generalized_force`` = -F J_x^T
    with J_x the row of x in the frame's Jacobian (from the ``kinematics`` input):
    connect it to the plant's ``applied_generalized_force`` input. That is the force
    (-F, 0, 0) applied at the frame's origin, in one Python calc with the contact force:
    inside, the law (``CompliantWallLaw``, named ``law``) computes [F; tau] and ``split``
    (a ``Demultiplexer``) gives the two outputs.

    .. pydrake_system::

        name: CompliantWall
        input_ports:
        - kinematics
        output_ports:
        - contact_force
        - generalized_force
    """

    def __init__(
        self,
        plant,
        *,
        frame_name: str,
        coordinates: Sequence[str],
        position: float,
        stiffness: float,
        stiffness_steps: Sequence[tuple[float, float]] = (),
        velocity: float = 0.0,
        motion_start: float = 0.0,
        motion_end: float = math.inf,
        position_offsets: Sequence[tuple[float, float, float]] = (),
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant of the arm.
            frame_name: the frame whose origin touches the wall (the contact point's).
            coordinates: the task vector X of the ``kinematics`` input (in world), which
                holds x.
            position: Xe at t = 0, m along world x.
            stiffness: Ke at t = 0, N/m (> 0).
            stiffness_steps: (time s, Ke N/m) pairs, times increasing, Ke > 0.
            velocity: wall speed along +x while it moves, m/s (0 = static).
            motion_start, motion_end: when the wall moves, s (end >= start).
            position_offsets: (start s, end s, offset m) jumps of Xe along +x during
                [start, end), e.g. a wall that retracts faster than any arm follows.
        """
        Diagram.__init__(self)
        builder = DiagramBuilder()
        law = builder.AddNamedSystem(
            "law",
            CompliantWallLaw(
                plant,
                frame_name=frame_name,
                coordinates=coordinates,
                position=position,
                stiffness=stiffness,
                stiffness_steps=stiffness_steps,
                velocity=velocity,
                motion_start=motion_start,
                motion_end=motion_end,
                position_offsets=position_offsets,
            ),
        )
        self._law = law
        split = builder.AddNamedSystem("split", Demultiplexer([1, plant.num_velocities()]))
        builder.Connect(law.contact_force_and_generalized_force_output, split.get_input_port())
        builder.ExportInput(law.kinematics_input, "kinematics")
        builder.ExportOutput(split.get_output_port(0), "contact_force")
        builder.ExportOutput(split.get_output_port(1), "generalized_force")
        builder.BuildInto(self)
        self.kinematics_input = self.GetInputPort("kinematics")
        self.contact_force_output = self.GetOutputPort("contact_force")
        self.generalized_force_output = self.GetOutputPort("generalized_force")

    @property
    def law(self) -> CompliantWallLaw:
        return self._law

    def stiffness_at(self, time: float) -> float:
        """Ke(t), N/m."""
        return self._law.stiffness_at(time)

    def position_at(self, time: float) -> float:
        """Xe(t), m."""
        return self._law.position_at(time)

    def discontinuity_times(self) -> list[float]:
        """Times at which Ke jumps or the wall starts or stops (for the integrator)."""
        return self._law.discontinuity_times()
