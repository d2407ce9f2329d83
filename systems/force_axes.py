"""What the force controllers share: their axes, parameter checks and the force error.

Every force controller of the loop (the paper's optimal admittance and the baselines it is
compared with) has the same ports: ``measured_force`` and ``desired_force`` (one value per
force-controlled axis) in, ``reference_offset`` Xr (a full Cartesian vector, zero on the
motion-controlled axes) out. Xr is added to the desired position Xd before the PID.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "check_axes",
    "declare_force_ports",
    "force_error",
    "offset_from_state",
    "per_axis",
    "scatter",
]


def check_axes(force_axes: Sequence[int], num_axes: int) -> list[int]:
    """The force-controlled axes as ints; raises ValueError unless distinct and in range."""
    axes = [int(a) for a in force_axes]
    if not axes:
        raise ValueError("force_axes must name at least one axis")
    if len(set(axes)) != len(axes) or min(axes) < 0 or max(axes) >= num_axes:
        raise ValueError(f"force_axes must be distinct indices in [0, {num_axes - 1}], got {axes}")
    return axes


def per_axis(
    name: str, value: float | Sequence[float], size: int, *, allow_zero: bool
) -> np.ndarray:
    """Broadcasts `value` to `size` finite entries, > 0 (or >= 0 with `allow_zero`)."""
    array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array.tolist()}")
    if allow_zero and np.any(array < 0):
        raise ValueError(f"{name} must be >= 0, got {array.tolist()}")
    if not allow_zero and np.any(array <= 0):
        raise ValueError(f"{name} must be > 0, got {array.tolist()}")
    return array


def force_error(T, desired, measured) -> list:
    """E = desired - measured per axis; 0 where the measurement is not finite.

    A broken sensor (NaN) must not reach the law: E = 0 holds the controller where it is.
    """
    if T is float:  # the simulation's hot path: plain Python floats, one comprehension
        return [
            want - got if math.isfinite(got) else 0.0
            for want, got in zip(desired.tolist(), measured.tolist(), strict=True)
        ]
    return [
        want - got if math.isfinite(got.value()) else T(0.0)
        for want, got in zip(desired, measured, strict=True)
    ]


def scatter(T, axes: Sequence[int], num_axes: int, values) -> list:
    """A num_axes list with `values` on `axes` and zero elsewhere."""
    full = [T(0.0)] * num_axes
    for axis, value in zip(axes, values, strict=True):
        full[axis] = value
    return full


def declare_force_ports(system, size: int, num_axes: int, calc_offset, prerequisites) -> None:
    """Declares the common ports on `system` and keeps them as attributes.

    ``measured_force_input`` and ``desired_force_input`` (`size` each) and
    ``reference_offset_output`` (`num_axes`, computed by `calc_offset` from
    `prerequisites`).
    """
    system.measured_force_input = system.DeclareVectorInputPort("measured_force", size)
    system.desired_force_input = system.DeclareVectorInputPort("desired_force", size)
    system.reference_offset_output = system.DeclareVectorOutputPort(
        "reference_offset", num_axes, calc_offset, prerequisites_of_calc=prerequisites
    )


def offset_from_state(T, axes: Sequence[int], num_axes: int):
    """An output calc for a controller whose first len(axes) continuous states are Xr."""

    def calc(context, output) -> None:
        state = context.get_continuous_state_vector().CopyToVector()
        output.SetFromVector(scatter(T, axes, num_axes, state[: len(axes)]))

    return calc
