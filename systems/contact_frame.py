"""A contact point as the safety layer's systems read it: its frame, its task, its normal.

The momentum observer, the sensor monitor, the stiffness estimator, the wall's motion
monitor and the safe law all read one point of the arm the same way: the frame at the
contact, the task vector X of that frame (its ``coordinates``, measured and expressed in
``expressed_in``: systems/task_kinematics.py) and the index in X of the contact normal,
along which the contact pushes the point back and the force is read. ``ContactFrame``
holds the four, built once by the caller and handed whole to each of them.
"""

from __future__ import annotations

from dataclasses import dataclass

from admittance.systems.spatial_kinematics import frame_kinematics
from admittance.systems.task_kinematics import task_coordinates

__all__ = ["ContactFrame"]


@dataclass(frozen=True)
class ContactFrame:
    """The frame at a contact, its task vector X and the contact normal's index in X.

    Attributes:
        frame_name: the plant's frame at the contact point.
        coordinates: X, names among TASK_COORDINATES (a tuple once built).
        normal_axis: the index in X of the contact normal.
        expressed_in: the frame X is measured and expressed in (one that does not move).
    """

    frame_name: str
    coordinates: tuple[str, ...]
    normal_axis: int
    expressed_in: str = "world"

    def __post_init__(self) -> None:
        coordinates = task_coordinates(self.coordinates)
        object.__setattr__(self, "coordinates", coordinates)
        if not 0 <= self.normal_axis < len(coordinates):
            raise ValueError(
                f"normal_axis must index the coordinates {coordinates}, got {self.normal_axis}"
            )
        object.__setattr__(self, "normal_axis", int(self.normal_axis))

    @property
    def num_axes(self) -> int:
        """m, the size of X."""
        return len(self.coordinates)

    def kinematics(self, plant):
        """The frame's kinematics helper on `plant` (any scalar type): spatial if X holds
        the rotation vector, planar otherwise (spatial_kinematics.frame_kinematics)."""
        return frame_kinematics(
            plant, self.frame_name, coordinates=self.coordinates, expressed_in=self.expressed_in
        )
