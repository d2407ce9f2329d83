"""The wrist sensor's compensated wrench as the force law reads it, in a control frame.

``WrenchInControlFrame`` takes the compensated wrench of the wrist sensor
(systems/wrench_sensor.py: the tool's wrench on the sensor, about the sensor frame S's
origin, in S, its weight removed), shifts its moment to the tool's contact point, turns it
into a control frame E and flips its sign, so that a tool pushing along an axis of E reads
a positive force there, as the paper's law has F positive into the wall.
"""

from __future__ import annotations

from collections.abc import Sequence

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.cpp_param import List
from pydrake.common.value import Value
from pydrake.math import RigidTransform_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.vector3 import cross, rotate, rotation_rows, unrotate
from admittance.systems.wrench_sensor import finite_vector, frame_in_body, weld_mount

__all__ = ["WrenchInControlFrame", "WrenchInControlFrame_"]


class _WrenchInControlFrame:
    """The compensated wrench about the tool's contact point P, in a control frame E,
    signed as the force law reads it, on the selected axes.

    With w = [f; tau_S] the compensated wrench of :class:`WrenchSensor` (in S, about
    S's origin), r_SP the contact point's offset in S and R_ES = R_WE^T R_WS::

        tau_P = tau_S - r_SP x f                   (the moment shifted to P)
        force = -[R_ES f; R_ES tau_P][axes]

    Quasi-statically the compensated wrench is what the surface applies to the tool
    (the weld holds the tool against the surface and its weight), so the minus sign
    gives the wrench the tool applies to the surface: the force is positive when the
    tool pushes along the axis, as the paper's law has F and Xr positive into the
    wall, and the moments are those the tool applies about P. With E's z axis along
    the surface's inward normal, ``axes = [2]`` reads the normal force.

    .. pydrake_system::

        name: WrenchInControlFrame
        input_ports:
        - wrench
        - body_poses
        output_ports:
        - force
    """

    def _construct(
        self,
        plant=None,
        weld_joint: str = "",
        control_frame: str = "world",
        *,
        contact_offset: Sequence[float] = (0.0, 0.0, 0.0),
        axes: Sequence[int],
        frames: dict | None = None,
        converter=None,
    ) -> None:
        """Declares the ports.

        Args:
            plant: the MultibodyPlant (only read here).
            weld_joint: the sensor's weld joint (its frame on the tool is S).
            control_frame: name of the plant frame E ("world" for the world frame).
            contact_offset: r_SP, the tool's contact point in S, m.
            axes: indices into [fx, fy, fz, tx, ty, tz] of the outputs, distinct.
            frames: the plant's data this system uses (scalar conversion only).
            converter: scalar converter, supplied by TemplateSystem.
        """
        T = self._T
        LeafSystem_[T].__init__(self, converter=converter)
        if frames is None:
            if plant is None:
                raise ValueError("WrenchInControlFrame needs the plant")
            mount = weld_mount(plant, weld_joint)
            if control_frame != "world" and not plant.HasFrameNamed(control_frame):
                raise ValueError(f"control_frame: the plant has no frame {control_frame!r}")
            frame_E = (
                plant.world_frame()
                if control_frame == "world"
                else plant.GetFrameByName(control_frame)
            )
            frames = dict(S=(mount["body_index"], mount["R_BS"]), E=frame_in_body(frame_E))
        selected = [int(a) for a in axes]
        if (
            not selected
            or len(set(selected)) != len(selected)
            or not all(0 <= a < 6 for a in selected)
        ):
            raise ValueError(f"axes must be distinct indices in [0, 5]; got {list(axes)}")
        self._arguments = dict(
            contact_offset=finite_vector("contact_offset", contact_offset, 3),
            axes=selected,
            frames=frames,
        )
        self._S, self._E = frames["S"], frames["E"]
        self._offset = self._arguments["contact_offset"]
        self._axes = selected
        self.wrench_input = self.DeclareVectorInputPort("wrench", 6)
        self.body_poses_input = self.DeclareAbstractInputPort(
            "body_poses", Value[List[RigidTransform_[T]]]()
        )
        self.force_output = self.DeclareVectorOutputPort(
            "force",
            len(selected),
            self._calc_force,
            prerequisites_of_calc={
                self.wrench_input.ticket(),
                self.body_poses_input.ticket(),
            },
        )

    def _construct_copy(self, other, converter=None) -> None:
        _WrenchInControlFrame._construct(self, **other._arguments, converter=converter)

    def wrench_on_surface(self, context) -> list:
        """All six components, -[R_ES f; R_ES tau_P], before the selection."""
        wrench = self.wrench_input.Eval(context).tolist()
        poses = self.body_poses_input.Eval(context)
        force = wrench[:3]
        moment_P = [t - s for t, s in zip(wrench[3:], cross(self._offset, force), strict=True)]
        (body_S, R_BS), (body_E, R_BE) = self._S, self._E
        R_WBs, R_WBe = rotation_rows(poses[body_S]), rotation_rows(poses[body_E])
        pushed = []
        for vector in (force, moment_P):  # v_E = R_BE^T R_WBe^T R_WBs R_BS v_S
            in_W = rotate(R_WBs, rotate(R_BS, vector))
            pushed += [-x for x in unrotate(R_BE, unrotate(R_WBe, in_W))]
        return pushed

    def _calc_force(self, context, output) -> None:
        wrench = self.wrench_on_surface(context)
        output.SetFromVector([wrench[axis] for axis in self._axes])

    @property
    def axes(self) -> list[int]:
        """The selected indices into [fx, fy, fz, tx, ty, tz]."""
        return list(self._axes)


@TemplateSystem.define("WrenchInControlFrame_", T_list=[float, AutoDiffXd])
def WrenchInControlFrame_(T):
    """Template of the compensated wrench as the force law reads it; see
    ``WrenchInControlFrame``."""

    class Impl(_WrenchInControlFrame, LeafSystem_[T]):
        __doc__ = _WrenchInControlFrame.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _WrenchInControlFrame._construct
        _construct_copy = _WrenchInControlFrame._construct_copy

    return Impl


#: The double-valued control-frame reading (see ``WrenchInControlFrame_``).
WrenchInControlFrame = WrenchInControlFrame_[None]
