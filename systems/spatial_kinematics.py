"""Spatial task-space kinematics of a frame: position and rotation vector (paper eq. 1-2).

The paper states its loop for a task vector X in R^m of any serial arm. On an arm that
moves in space the task vector of a tool frame F is its pose in a control frame E (world,
or a frame welded at the planned surface):

    X = (x, y, z, rx, ry, rz),   p_EF = (x, y, z),   r = (rx, ry, rz) = log(R_EF)

where r is the rotation vector of F's orientation in E: R_EF = exp([r]x), a rotation by
|r| about r / |r|. Any subset of x, y, z may be picked; the three of r come together (a
rotation is a whole). The Jacobian rows of rx, ry, rz are those of F's angular velocity
omega_EF_E, so the rate output for them is omega, not dr/dt (the two agree to first order
at r = 0; dr/dt = J_l(r)^-1 omega in general). That is what the Cartesian PID needs: its
orientation error is the rotation vector of the relative rotation (``orientation_error``,
systems/cartesian_pid.py), whose rate is omega_d - omega to first order in the error, so
it never differentiates r itself and meets no Euler-angle singularity.

The rotation vector is computed through the unit quaternion of R (Shepperd's method:
the largest of 1 + trace, 1 + 2 R_ii picks the stable formula), taken with w >= 0 so that
|r| = 2 atan2(|v|, w) is in [0, pi]. Near r = 0 the factor |r| / |v| is its series 2 / w,
which keeps the AutoDiffXd derivative exact at the identity (sqrt(|v|^2) has none there).
The functions below run on Python floats and on AutoDiffXd alike; the branch is chosen
on the value, as the derivative of each branch is the function's own.

* ``SpatialFrameKinematics`` asks the plant (any scalar type) through a private context;
* ``SpatialKinematics`` is the LeafSystem with the ``kinematics`` output of every task
  kinematics ([X; dX/dt; J row by row], m x nv; systems/task_kinematics.py), float and
  AutoDiffXd;
* ``frame_kinematics`` picks the planar or the spatial class for a set of coordinates.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import atan2, cos, sin, sqrt
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.planar_kinematics import PlanarFrameKinematics
from admittance.systems.task_kinematics import (
    ROTATION_COORDINATES,
    TaskFrameKinematics,
    TaskKinematics,
    has_rotation_vector,
    task_coordinates,
)

__all__ = [
    "SPATIAL_COORDINATES",
    "SpatialFrameKinematics",
    "SpatialKinematics",
    "SpatialKinematics_",
    "frame_kinematics",
    "orientation_error",
    "rotation_matrix",
    "rotation_vector",
]

#: The 6-D task vector of a tool frame: position and rotation vector in the control frame.
SPATIAL_COORDINATES = ("x", "y", "z", "rx", "ry", "rz")
# Below this |v|^2 (|r| ~ 2e-8 rad) the series of |r| / |v| is exact to rounding.
_SMALL_SQUARED = 1e-16


def _value(scalar) -> float:
    return scalar if isinstance(scalar, float) else scalar.value()


def rotation_vector(matrix) -> list:
    """r = log(R): the rotation vector of a rotation matrix (3 x 3, indexable [i][j]).

    |r| in [0, pi]; at exactly pi either of the two opposite vectors. Float or AutoDiffXd
    entries.
    """
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = (
        (matrix[i][0], matrix[i][1], matrix[i][2]) for i in range(3)
    )
    root = math.sqrt if isinstance(r00, float) else sqrt
    trace = r00 + r11 + r22
    pick = max(range(4), key=lambda k: _value((trace, r00, r11, r22)[k]))
    if pick == 0:
        w = 0.5 * root(1.0 + trace)
        s = 0.25 / w
        x, y, z = (r21 - r12) * s, (r02 - r20) * s, (r10 - r01) * s
    elif pick == 1:
        x = 0.5 * root(1.0 + r00 - r11 - r22)
        s = 0.25 / x
        w, y, z = (r21 - r12) * s, (r01 + r10) * s, (r02 + r20) * s
    elif pick == 2:
        y = 0.5 * root(1.0 - r00 + r11 - r22)
        s = 0.25 / y
        w, x, z = (r02 - r20) * s, (r01 + r10) * s, (r12 + r21) * s
    else:
        z = 0.5 * root(1.0 - r00 - r11 + r22)
        s = 0.25 / z
        w, x, y = (r10 - r01) * s, (r02 + r20) * s, (r12 + r21) * s
    return _quaternion_log(w, x, y, z)


def _quaternion_log(w, x, y, z) -> list:
    """The rotation vector of the unit quaternion (w, x, y, z), angle in [0, pi]."""
    if _value(w) < 0.0:  # q and -q are one rotation: take the angle in [0, pi]
        w, x, y, z = -w, -x, -y, -z
    squared = x * x + y * y + z * z
    if _value(squared) < _SMALL_SQUARED:
        factor = 2.0 / w  # 2 atan2(n, w) / n -> 2 / w as n -> 0
    elif isinstance(squared, float):
        norm = math.sqrt(squared)
        factor = 2.0 * math.atan2(norm, w) / norm
    else:
        norm = sqrt(squared)
        factor = 2.0 * atan2(norm, w) / norm
    return [factor * x, factor * y, factor * z]


def _quaternion(vector) -> tuple:
    """The unit quaternion (w, x, y, z) of exp([r]x): (cos(|r|/2), sin(|r|/2) r / |r|)."""
    rx, ry, rz = vector[0], vector[1], vector[2]
    squared = rx * rx + ry * ry + rz * rz
    if _value(squared) < 1e-12:  # series, exact to rounding there
        w, k = 1.0 - squared / 8.0, 0.5 - squared / 48.0
    elif isinstance(squared, float):
        angle = math.sqrt(squared)
        w, k = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
    else:
        angle = sqrt(squared)
        w, k = cos(0.5 * angle), sin(0.5 * angle) / angle
    return w, k * rx, k * ry, k * rz


def rotation_matrix(vector) -> list:
    """R = exp([r]x) (Rodrigues' formula) as nested lists, for float or AutoDiffXd r."""
    rx, ry, rz = vector[0], vector[1], vector[2]
    squared = rx * rx + ry * ry + rz * rz
    if _value(squared) < 1e-12:  # series, exact to rounding there
        a, b = 1.0 - squared / 6.0, 0.5 - squared / 24.0
    else:
        floats = isinstance(squared, float)
        angle = math.sqrt(squared) if floats else sqrt(squared)
        a = (math.sin(angle) if floats else sin(angle)) / angle
        b = (1.0 - (math.cos(angle) if floats else cos(angle))) / squared
    # R = I + a [r]x + b [r]x^2, with [r]x^2 = r r^T - |r|^2 I.
    return [
        [1.0 + b * (rx * rx - squared), b * rx * ry - a * rz, b * rx * rz + a * ry],
        [b * rx * ry + a * rz, 1.0 + b * (ry * ry - squared), b * ry * rz - a * rx],
        [b * rx * rz - a * ry, b * ry * rz + a * rx, 1.0 + b * (rz * rz - squared)],
    ]


def orientation_error(commanded, measured) -> list:
    """e_R = log(R_d R^T) in E, from the commanded and measured rotation vectors.

    With R_d = exp(commanded) and R = exp(measured) the orientations of F in E, R_d R^T is
    the rotation, applied in E, that carries the measured orientation to the commanded
    one: e_R is its rotation vector in E (angle |e_R| in [0, pi]). Writing R = exp([dr]x) R_d
    for a small deviation dr, e_R = -dr + O(|dr|^2), and d(e_R)/dt = omega_d - omega + O(|e_R|)
    (from d(R_d R^T)/dt = [omega_d - R_d R^T omega]x R_d R^T), the rate the PID uses.
    Computed on unit quaternions: q_d q^-1 = (a, u)(b, -v) = (a b + u.v, b u - a v - u x v).
    """
    a, u0, u1, u2 = _quaternion(commanded)
    b, v0, v1, v2 = _quaternion(measured)
    return _quaternion_log(
        a * b + u0 * v0 + u1 * v1 + u2 * v2,
        b * u0 - a * v0 - (u1 * v2 - u2 * v1),
        b * u1 - a * v1 - (u2 * v0 - u0 * v2),
        b * u2 - a * v2 - (u0 * v1 - u1 * v0),
    )


class SpatialFrameKinematics(TaskFrameKinematics):
    """The task vector X of a frame whose coordinates may hold the rotation vector of R_EF.

    X is read in the order of the coordinates; the rows of J for rx, ry, rz are F's
    angular velocity in E (``TaskFrameKinematics.jacobian``).
    """

    def __init__(self, plant, frame_name: str, *, coordinates, expressed_in: str = "world") -> None:
        super().__init__(plant, frame_name, coordinates=coordinates, expressed_in=expressed_in)
        # Where each coordinate is in (x, y, z, rx, ry, rz).
        self._pose_indices = [SPATIAL_COORDINATES.index(c) for c in self.coordinates]

    def pose(self):
        """X at the last state set: position of F's origin and rotation vector of R_EF."""
        X_EF = self.plant.CalcRelativeTransform(self._context, self._world, self.frame)
        # Drake's quaternion of R_EF (its own Shepperd's method, in C++), then its log.
        w, x, y, z = X_EF.rotation().ToQuaternion().wxyz().tolist()
        values = X_EF.translation().tolist() + _quaternion_log(w, x, y, z)
        return np.array([values[i] for i in self._pose_indices])


def frame_kinematics(plant, frame_name: str, *, coordinates, expressed_in: str = "world"):
    """The frame-kinematics helper for `coordinates`: spatial if they hold rx, ry, rz."""
    kind = SpatialFrameKinematics if has_rotation_vector(coordinates) else PlanarFrameKinematics
    return kind(plant, frame_name, coordinates=coordinates, expressed_in=expressed_in)


class _SpatialKinematics(TaskKinematics):
    """The spatial task-space kinematics of a frame of a plant (paper eq. 1-2).

        X = (p_EF, log(R_EF))         in the order of ``coordinates``
        dX/dt = J(q) v                (its rotation rows: omega_EF_E)
        J = rows of J_EF_E            (m x nv, with respect to the velocities v)

    output as one vector ``kinematics`` = [X; dX/dt; J row by row], of length
    2 m + m nv, the layout of every task kinematics (whose ports, accessors and checks
    it shares: systems/task_kinematics.py; ``split_kinematics`` takes the vector apart).
    Computed from the plant (through its bindings) for double and AutoDiffXd, so that
    linearizing the loop differentiates the plant's own kinematics.

    .. pydrake_system::

        name: SpatialKinematics
        input_ports:
        - estimated_state
        output_ports:
        - kinematics
    """

    def _construct(
        self,
        plant,
        *,
        frame_name: str,
        coordinates,
        expressed_in: str = "world",
        generated: bool = False,
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] (an arm, with anything else in it).
            frame_name: the frame whose motion is output (the tool frame).
            coordinates: the task vector X, names among TASK_COORDINATES (not theta).
            expressed_in: the control frame E X is measured and expressed in (one that
                does not move, e.g. welded to the world at the planned surface).
            generated: False (the plant's bindings; no generated code for a rotation
                vector, whose branches have no single expression).
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        coordinates = task_coordinates(coordinates)
        if "theta" in coordinates:
            raise ValueError(
                "coordinates: theta is the planar arm's angle (PlanarKinematics); a "
                f"spatial task uses {ROTATION_COORDINATES}, got {coordinates}"
            )
        if generated:
            raise ValueError("SpatialKinematics has no generated code: generated=False")
        self._kinematics = SpatialFrameKinematics(
            plant, frame_name, coordinates=coordinates, expressed_in=expressed_in
        )
        self._declare_kinematics(
            plant,
            frame_name=frame_name,
            coordinates=coordinates,
            expressed_in=expressed_in,
            generated=False,
            calc=None,
        )

    def _construct_copy(self, other, converter=None) -> None:
        _SpatialKinematics._construct(
            self,
            other._plant.ToScalarType[self._T](),
            converter=converter,
            **other._copy_arguments(),
        )


@TemplateSystem.define("SpatialKinematics_", T_list=[float, AutoDiffXd])
def SpatialKinematics_(T):
    class Impl(_SpatialKinematics, LeafSystem_[T]):
        __doc__ = _SpatialKinematics.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _SpatialKinematics._construct
        _construct_copy = _SpatialKinematics._construct_copy

    return Impl


SpatialKinematics = SpatialKinematics_[None]
