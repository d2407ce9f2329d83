"""One description of a force-controlled robot: its plant and its force-controlled points.

The paper writes its loop (Fig. 1) for any serial arm with n joints whose task vector X
has m coordinates. A robot here is its plant (model files, gravity, time step, built by
the robot's module) and one or more force-controlled points. A :class:`ForcePoint` holds
everything the loop needs at one point: the frame at the contact, its task coordinates
and the frame they are expressed in, the axes under force control, the sensor chain
(ideal or FlexiForce, with its noise and faults), the force law, and the PID's gains. The
paper's arm has one point (its fingertip: x, y, theta in world, force along x); Drake's
planar gripper has three (each fingertip: x, y in a frame at its planned face, force
along the face's normal). The contact (the analytic wall of eq. 4, or Drake's contact
engine) and the plan (Xd and Fr over time) are the robot's own, wired by its builder.

``loop.point`` wires the loop of Fig. 1 at a point from this description alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from admittance.diagrams.scenario.sections import AdmittanceSection, SensorSection
from admittance.systems.posture_task import PostureTask

__all__ = ["ForceLaw", "ForcePoint", "SensorChain", "force_law", "sensor_chain"]


@dataclass
class SensorChain:
    """The force sensor at a point: what it reads, its filter, noise, readout and faults."""

    # "ideal" (the true contact force: a wire, no system), "flexiforce" (A201 + op-amp
    # + analog low-pass + ADC noise) or "wrench" (a 6-axis force/torque sensor at a weld
    # between the flange and the tool, systems/wrench_sensor.py).
    kind: str = "ideal"
    # Cut-off of the analog low-pass filter after the op-amp (the wrench sensor's
    # low-pass, 0 = none), Hz.
    filter_cutoff: float = 5000.0
    # Standard deviation of the measured-force noise at the ADC (the wrench sensor's on
    # each force axis), N (0 = none).
    noise_std: float = 0.0
    # Sample period of the noise (the ADC's period; the wrench sensor's period if set), s.
    noise_period: float = 0.005
    # Readout period of the sensor, s (0 = a continuous output).
    period: float = 0.0
    # Latency of the reading, s (0 = none): each sample reaches the controller this late.
    latency: float = 0.0
    # Loading-unloading band of the FlexiForce, a fraction of the force (0 = none).
    hysteresis: float = 0.0
    # Rise of the FlexiForce's reading per decade of time under load, a fraction (0 = none).
    drift: float = 0.0
    # Injected sensor faults, (kind, start s, end s, value, noisy), kinds sensor_*.
    faults: list[tuple[str, float, float, float, bool]] = field(default_factory=list)
    # The wrench sensor's: its constant bias [N x3, N m x3], and the noise std on each
    # torque axis, N m (0 = none).
    bias: tuple[float, ...] = (0.0,) * 6
    torque_noise_std: float = 0.0
    # The weld joint between the flange (parent) and the tool (child): its frame on the
    # tool is the sensor frame S.
    weld_joint: str = ""
    # The mass the weld carries, kg, and its centre of mass in S, m, for the weight
    # compensation (None = the plant's own: a perfectly calibrated tool).
    tool_mass: float | None = None
    tool_com: tuple[float, float, float] | None = None
    # The tool's contact point in S, m: the moments are taken about it.
    contact_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # Indices into [fx, fy, fz, tx, ty, tz] in the point's frame (`expressed_in`) that the
    # force law reads; empty = the point's force axes (coordinates x, y, z, then the
    # rotation's three).
    wrench_axes: tuple[int, ...] = ()


@dataclass
class ForceLaw:
    """The force controller in front of the PID at a point, and its gains."""

    # optimal_admittance (the paper's eq. 10), pid_only (none), fixed_reference (eq. 6),
    # classical_admittance or adaptive_impedance (the baselines).
    kind: str = "optimal_admittance"
    # Gamma and alpha of eq. 10 on each force axis.
    gamma: float = 1e-5
    alpha: float = 0.0
    # Sample period of the law, s (0 = continuous).
    period: float = 0.0
    # Travel bounds of Xr into and away from the surface, m (with anti-windup).
    max_push: float = 0.01
    max_retract: float = 0.1
    # Fmax, an explicit upper bound on the force, N (.inf = none), and the weight mu of
    # its penalty (docs/evidence/force-bound.md).
    max_force: float = math.inf
    force_bound_gain: float = 4.0
    # The baselines' gains: mass, damping, stiffness, adaptation_rate.
    baseline: dict[str, float] = field(default_factory=dict)
    # fixed_reference's estimate of the surface: (position m, stiffness N/m).
    surface_estimate: tuple[float, float] | None = None


@dataclass
class ForcePoint:
    """One force-controlled point of a robot (see the module's docstring)."""

    # What its systems' names start with ("" for a robot with one point).
    name: str
    # The frame at the contact point (a fingertip frame of the plant).
    frame: str
    # Task coordinates X of the frame: x, y, z, theta (planar), or x, y, z, rx, ry, rz
    # (rotation vector).
    coordinates: tuple[str, ...]
    # The axes of X under force control (the others follow Xd under the PID alone).
    force_axes: tuple[int, ...]
    # The frame X is measured and expressed in.
    expressed_in: str = "world"
    sensor: SensorChain = field(default_factory=SensorChain)
    law: ForceLaw = field(default_factory=ForceLaw)
    # The Cartesian PID's gains on each coordinate of X (eq. 14-16) and its period, s.
    kp: list[float] = field(default_factory=list)
    kd: list[float] = field(default_factory=list)
    ki: list[float] = field(default_factory=list)
    pid_period: float = 0.0
    # The torque interface's gravity compensation, tau += g(q) from the plant (a real
    # arm's; the paper's arm has none: its integral term carries the weight).
    gravity_compensation: bool = False
    # A joint-space posture in the null space of J, for a redundant arm (None = none).
    posture: PostureTask | None = None

    @property
    def num_axes(self) -> int:
        return len(self.coordinates)

    @property
    def stiffness(self) -> float:
        """K of eq. 10: the PID's stiffness on the (first) force axis (docs/evidence/paper-notes.md,
        section 4)."""
        return float(self.kp[self.force_axes[0]])

    @property
    def force_axis_stiffness(self) -> list[float]:
        """K of eq. 10 on each force axis: the PID's Kp there (N/m on a position, N m/rad
        on a rotation: one force law may hold both, e.g. a normal force and two tilts)."""
        return [float(self.kp[axis]) for axis in self.force_axes]

    def system_name(self, role: str) -> str:
        """The name of this point's system that plays `role` (``finger1_cartesian_pid``)."""
        return f"{self.name}_{role}" if self.name else role


def sensor_chain(section: SensorSection, *, faults=(), **robot_keys) -> SensorChain:
    """A point's sensor chain from a scenario's shared `sensor` section (kind, filter
    cut-off, noise) and its `faults` section's entries (the reading's kinds, sensor_*;
    the others act elsewhere), with what the robot adds (its readout period, noise
    period, the arm's hysteresis and drift) as keyword arguments."""
    return SensorChain(
        kind=section.kind,
        filter_cutoff=section.filter_cutoff,
        noise_std=section.noise_std,
        latency=section.latency,
        faults=[
            (f.kind, f.start, f.end, f.value, f.noisy)
            for f in faults
            if f.kind.startswith("sensor_")
        ],
        **robot_keys,
    )


def force_law(kind: str, section: AdmittanceSection, **robot_keys) -> ForceLaw:
    """A point's force law of `kind` from a scenario's shared `admittance` section (Gamma,
    alpha, the travel bounds), with what the robot adds as keyword arguments."""
    return ForceLaw(
        kind=kind,
        gamma=section.gamma,
        alpha=section.alpha,
        max_push=section.max_push,
        max_retract=section.max_retract,
        **robot_keys,
    )
