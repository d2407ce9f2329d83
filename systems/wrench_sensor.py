"""A 6-axis force/torque sensor at the weld between an arm's flange and its tool.

The wrist sensor of the controllers a user would compare with (ros2_controllers'
admittance_controller, FZI's cartesian_controllers): Drake's weld reaction force, read as
a real sensor reports it, with its bias, noise, low-pass and readout period, and the
tool's weight removed as ros2's admittance_controller removes it. Two systems:
:class:`WrenchSensor` (the sensor and the weight compensation, here) and
``WrenchInControlFrame`` (systems/wrench_in_control_frame.py: the compensated wrench as
the force law reads it, about the tool's contact point, in a control frame E, signed so
that pushing is positive).

Convention (the one of ros2's admittance_controller and of real F/T sensors): the
reading is the wrench that the tool exerts on the sensor's measuring side, about the
origin of the sensor frame S and expressed in S, forces first::

    w_S = [fx, fy, fz, tx, ty, tz]   (N, N m)

S is the weld joint's frame on its child body, the tool (URDF's fixed joints and
``AddWeldJoint(flange, tool)`` make the tool the child). Drake's reaction-force port
gives, for each joint J, ``F_CJc_Jc``: the spatial force *on the child body C* (the tool)
at the origin of the joint's child frame Jc (= S), expressed in Jc. The tool pushes the
sensor with the opposite wrench (Newton's third law), so ``w_S = -F_CJc_Jc`` reordered
forces first. A tool of mass m hanging still reads its weight: f = m g (g the gravity
vector, so -m 9.81 N along world z) and tau = c x (m g), c the centre of mass in S.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.cpp_param import List
from pydrake.common.value import Value
from pydrake.math import RigidTransform_
from pydrake.multibody.math import SpatialForce_
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.vector3 import cross, rotation_rows, unrotate

__all__ = [
    "WRENCH_AXES",
    "WrenchSensor",
    "WrenchSensor_",
    "carried_mass_and_com",
    "finite_vector",
    "frame_in_body",
    "weld_mount",
]

#: The names of the six components of a wrench, in the order of every 6-vector here.
WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


def finite_vector(name: str, value: Sequence[float], size: int) -> list[float]:
    """`value` as `size` finite floats, or ValueError naming `name`."""
    array = np.asarray(value, dtype=float).reshape(-1)
    if array.shape != (size,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be {size} finite numbers; got {value!r}")
    return array.tolist()


def _nonnegative(name: str, value: float, unit: str) -> float:
    """`value` as a finite float >= 0, or ValueError naming `name`."""
    number = float(value)
    if not (math.isfinite(number) and number >= 0.0):
        raise ValueError(f"{name} must be a finite number >= 0 {unit}; got {value!r}")
    return number


def frame_in_body(frame) -> tuple[int, list[list[float]]]:
    """(body index, R_BF rows) of a plant frame F fixed in its body B: what reads F's
    orientation from the plant's body poses."""
    return int(frame.body().index()), frame.GetFixedPoseInBodyFrame().rotation().matrix().tolist()


def _weld(plant, weld_joint: str):
    """The weld joint named `weld_joint`, or ValueError naming the key."""
    if not plant.HasJointNamed(weld_joint):
        raise ValueError(f"weld_joint: the plant has no joint named {weld_joint!r}")
    joint = plant.GetJointByName(weld_joint)
    if joint.type_name() != "weld":
        raise ValueError(
            f"weld_joint: {weld_joint!r} is a {joint.type_name()} joint; a weld is needed"
        )
    return joint


def weld_mount(plant, weld_joint: str) -> dict:
    """What the sensor needs of the plant: the weld's index, S on the tool, gravity."""
    joint = _weld(plant, weld_joint)
    body, R_BS = frame_in_body(joint.frame_on_child())
    return dict(
        # The reaction-force port holds one entry per joint in the order of their indices
        # (Drake's joint ordinals): a plant whose joints were removed (a description's
        # joints replaced by welds) has gaps in its indices, so the entry is the position.
        joint_index=[int(i) for i in plant.GetJointIndices()].index(int(joint.index())),
        body_index=body,
        R_BS=R_BS,
        gravity=plant.gravity_field().gravity_vector().tolist(),
    )


def carried_mass_and_com(plant, weld_joint: str) -> tuple[float, list[float]]:
    """The mass the weld carries (kg) and its centre of mass in S (m), from the plant.

    What the weld carries: its child body and every body joined to it outward (each
    joint's child whose parent is already carried), in the plant's default
    configuration. This is a perfectly calibrated tool; a scenario may give other values.
    """
    joint = _weld(plant, weld_joint)
    carried = {joint.child_body().index()}
    joints = [plant.get_joint(index) for index in plant.GetJointIndices()]
    grew = True
    while grew:
        grew = False
        for other in joints:
            if other.parent_body().index() in carried and (
                other.child_body().index() not in carried
            ):
                carried.add(other.child_body().index())
                grew = True
    context = plant.CreateDefaultContext()
    mass, moment_W = 0.0, np.zeros(3)
    for index in carried:
        body = plant.get_body(index)
        body_mass = body.get_mass(context)
        p_WBcm = plant.EvalBodyPoseInWorld(context, body).multiply(
            body.CalcCenterOfMassInBodyFrame(context)
        )
        mass += body_mass
        moment_W += body_mass * p_WBcm
    X_WS = joint.frame_on_child().CalcPoseInWorld(context)
    com_W = moment_W / mass if mass > 0 else X_WS.translation()
    return mass, X_WS.inverse().multiply(com_W).tolist()


class _WrenchSensor:
    """A 6-axis F/T sensor at a weld joint, and its tool-weight compensation.

    Law, with w the true wrench of the tool on the sensor in S (see the module's
    docstring), b the bias, sigma the noise std (force axes sigma_f, torque axes
    sigma_t) and n the ``noise`` input (standard normal, one value per axis)::

        w       = -[F_CJc_Jc.translational(); F_CJc_Jc.rotational()]
        dx/dt   = (w - x) / tau,  tau = 1 / (2 pi f_c)         (f_c > 0, period 0)
        x[k+1]  = w[k] + (x[k] - w[k]) exp(-h / tau)           (period h > 0)
        wrench  = x + b + sigma n      (x = w without filter and period)
        compensated_wrench = wrench - [m g_S; c x m g_S],  g_S = R_WS^T g_W

    The low-pass is the sensor's own (its electronics), so bias and noise enter after
    it and the compensation (a controller's step, as in ros2's admittance_controller)
    acts on the reading. The readout period h holds x between samples (one discrete
    group of 6; Drake caches the raw reading until the next sample or noise draw, the
    compensated one follows the sensor's orientation); with f_c = 0 it is a
    zero-order hold, ``x[k+1] = w[k]``. With neither filter nor period
    the reading feeds through from ``reaction_forces``: on a continuous plant those
    depend on the actuation, so a loop closed through them is algebraic (Drake says
    so at Build); give it a filter or a period, or use a discrete plant.

    The compensation removes the weight of a tool at rest. It does not remove the
    tool's inertial forces: the tool, accelerating at a, reads m (g - a), so -m a
    stays in the compensated reading (and its moment -c x m a, and the rotational
    inertia's). A slide at 2 cm/s reached in 0.2 s accelerates at 0.1 m/s^2: 0.05 N
    for a 0.5 kg tool, 0.5 % of a 10 N press; at constant speed it is zero
    (docs/evidence/wrist-sensor.md). ``tool_mass`` and ``tool_com`` are those of everything
    the weld carries (None: taken from the plant, a perfectly calibrated tool).

    ``noise`` is standard normal (a RandomSource of kGaussian, sampled at the
    sensor's period), scaled here, so a zero input is a noise-free sensor. The
    filter's state starts at zero (a sensor switched on unloaded); call
    :meth:`InitializeReading` after setting the plant's state to start settled.

    Scalar types: float and AutoDiffXd (the abstract inputs are the plant's
    ``List[SpatialForce_[T]]`` and ``List[RigidTransform_[T]]``), not symbolic.

    .. pydrake_system::

        name: WrenchSensor
        input_ports:
        - reaction_forces
        - body_poses
        - noise
        output_ports:
        - wrench
        - compensated_wrench
    """

    def _construct(
        self,
        plant=None,
        weld_joint: str = "",
        *,
        bias: Sequence[float] = (0.0,) * 6,
        force_noise_std: float = 0.0,
        torque_noise_std: float = 0.0,
        filter_cutoff_hz: float = 0.0,
        period: float = 0.0,
        tool_mass: float | None = None,
        tool_com: Sequence[float] | None = None,
        mount: dict | None = None,
        converter=None,
    ) -> None:
        """Declares the ports and the filter's state.

        Args:
            plant: the MultibodyPlant holding the weld (only read here).
            weld_joint: name of the weld joint between the flange (parent) and the
                tool (child); its frame on the tool is the sensor frame S.
            bias: constant offset of the reading, [N x3, N m x3].
            force_noise_std: std of the white noise on fx, fy, fz, N (>= 0).
            torque_noise_std: std of the white noise on tx, ty, tz, N m (>= 0).
            filter_cutoff_hz: cut-off of the first-order low-pass, Hz (0 = none).
            period: readout period, s (0 = continuous).
            tool_mass: the mass the weld carries, kg (>= 0), for the compensation
                (None: the plant's, see :func:`carried_mass_and_com`).
            tool_com: its centre of mass in S, m (None: the plant's).
            mount: the plant's data this system uses (scalar conversion only).
            converter: scalar converter, supplied by TemplateSystem.

        Raises:
            ValueError: an argument is out of range (the message names it).
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        if mount is None:
            if plant is None:
                raise ValueError("WrenchSensor needs the plant and its weld_joint")
            mount = weld_mount(plant, weld_joint)
        if tool_mass is None or tool_com is None:  # a perfectly calibrated tool
            if plant is None:
                raise ValueError("WrenchSensor needs the plant for the tool's inertia")
            carried = carried_mass_and_com(plant, weld_joint)
            tool_mass = carried[0] if tool_mass is None else tool_mass
            tool_com = carried[1] if tool_com is None else tool_com
        cutoff = _nonnegative("filter_cutoff_hz", filter_cutoff_hz, "Hz (0 = none)")
        h = _nonnegative("period", period, "s (0 = continuous)")
        self._arguments = dict(
            bias=finite_vector("bias", bias, 6),
            force_noise_std=_nonnegative("force_noise_std", force_noise_std, "N"),
            torque_noise_std=_nonnegative("torque_noise_std", torque_noise_std, "N m"),
            filter_cutoff_hz=cutoff,
            period=h,
            tool_mass=_nonnegative("tool_mass", tool_mass, "kg"),
            tool_com=finite_vector("tool_com", tool_com, 3),
            mount=mount,
        )
        self._set_constants(self._arguments)
        self._declare_ports()

    def _set_constants(self, arguments: dict) -> None:
        """The mount's indices, the tool's weight, the bias, noise, filter and period."""
        mount, cutoff, h = arguments["mount"], arguments["filter_cutoff_hz"], arguments["period"]
        self._joint = mount["joint_index"]
        self._body = mount["body_index"]
        self._R_BS = mount["R_BS"]
        # The tool's weight m g_W (N) and its centre of mass c (m, in S).
        self._weight_W = [arguments["tool_mass"] * g for g in mount["gravity"]]
        self._com = arguments["tool_com"]
        self._bias = arguments["bias"]
        self._sigma = [arguments["force_noise_std"]] * 3 + [arguments["torque_noise_std"]] * 3
        self._tau = 1.0 / (2.0 * math.pi * cutoff) if cutoff > 0 else 0.0
        self._period = h
        # Fraction of the state left after one period (0: a plain zero-order hold).
        self._decay = math.exp(-h / self._tau) if (h > 0 and cutoff > 0) else 0.0

    def _declare_ports(self) -> None:
        """The inputs, the reading's state (a hold with a period, a filter with a
        cut-off, none without either) and the two outputs."""
        T = self._T
        self.reaction_forces_input = self.DeclareAbstractInputPort(
            "reaction_forces", Value[List[SpatialForce_[T]]]()
        )
        self.body_poses_input = self.DeclareAbstractInputPort(
            "body_poses", Value[List[RigidTransform_[T]]]()
        )
        self.noise_input = self.DeclareVectorInputPort("noise", 6)
        if self._period > 0:
            # One group, x: a context's SetDiscreteState(x) sets the sensor's reading.
            self._state = self.DeclareDiscreteState(6)
            self.DeclarePeriodicDiscreteUpdateEvent(
                period_sec=self._period, offset_sec=0.0, update=self._sample
            )
            reading = {self.xd_ticket()}
        elif self._arguments["filter_cutoff_hz"] > 0:
            self.DeclareContinuousState(BasicVector_[T]([0.0] * 6))
            reading = {self.xc_ticket()}
        else:
            reading = {self.reaction_forces_input.ticket()}
        reading.add(self.noise_input.ticket())
        self.wrench_output = self.DeclareVectorOutputPort(
            "wrench", 6, self._calc_wrench, prerequisites_of_calc=reading
        )
        self.compensated_wrench_output = self.DeclareVectorOutputPort(
            "compensated_wrench",
            6,
            self._calc_compensated,
            prerequisites_of_calc=reading | {self.body_poses_input.ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _WrenchSensor._construct(self, **other._arguments, converter=converter)

    # ----------------------------------------------------------------- calcs
    def true_wrench(self, context) -> list:
        """w: the wrench of the tool on the sensor, about S, in S (no bias, noise,
        filter), from the plant's reaction force at the weld."""
        F = self.reaction_forces_input.Eval(context)[self._joint]
        return [-x for x in F.translational().tolist() + F.rotational().tolist()]

    def weight_wrench(self, context) -> list:
        """[m g_S; c x m g_S]: the tool's weight and its moment about S, in S."""
        pose = self.body_poses_input.Eval(context)[self._body]
        weight_S = unrotate(self._R_BS, unrotate(rotation_rows(pose), self._weight_W))
        return weight_S + cross(self._com, weight_S)

    def _filtered(self, context) -> list:
        """x: the filter's (or the hold's) state, or w when there is neither."""
        if self._period > 0:
            return context.get_discrete_state(self._state).value().tolist()
        if self._tau > 0:
            return context.get_continuous_state_vector().CopyToVector().tolist()
        return self.true_wrench(context)

    def _reading(self, context) -> list:
        """x + b + sigma n."""
        noise = self.noise_input.Eval(context).tolist()
        return [
            x + b + s * n
            for x, b, s, n in zip(
                self._filtered(context), self._bias, self._sigma, noise, strict=True
            )
        ]

    def _calc_wrench(self, context, output) -> None:
        output.SetFromVector(self._reading(context))

    def _calc_compensated(self, context, output) -> None:
        weight = self.weight_wrench(context)
        output.SetFromVector([x - w for x, w in zip(self._reading(context), weight, strict=True)])

    def DoCalcTimeDerivatives(self, context, derivatives) -> None:
        """dx/dt = (w - x) / tau (only the continuous filter has a state)."""
        if self._period > 0 or self._tau == 0:
            return
        state = context.get_continuous_state_vector().CopyToVector().tolist()
        rate = 1.0 / self._tau
        derivatives.get_mutable_vector().SetFromVector(
            [(w - x) * rate for w, x in zip(self.true_wrench(context), state, strict=True)]
        )

    def _sample(self, context, discrete_state) -> None:
        """x[k+1] = w[k] + (x[k] - w[k]) exp(-h / tau)."""
        state = context.get_discrete_state(self._state).value().tolist()
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [
                w + (x - w) * self._decay
                for w, x in zip(self.true_wrench(context), state, strict=True)
            ]
        )

    def InitializeReading(self, context) -> None:
        """Sets the filter's (or hold's) state to the true wrench now: a sensor that
        has settled on the initial load (the plant's state must be set first). Any
        other start: ``SetDiscreteState`` or ``SetContinuousState`` of x."""
        if self._period > 0:
            context.SetDiscreteState(self._state, self.true_wrench(context))
        elif self._tau > 0:
            context.SetContinuousState(self.true_wrench(context))

    # ---------------------------------------------------------- accessors
    @property
    def period(self) -> float:
        """Readout period, s (0 = continuous)."""
        return self._period

    @property
    def filter_time_constant(self) -> float:
        """tau = 1 / (2 pi f_c) of the low-pass, s (0 = no filter)."""
        return self._tau

    @property
    def noise_std(self) -> np.ndarray:
        """The noise std on each axis, [N x3, N m x3]."""
        return np.array(self._sigma)


@TemplateSystem.define("WrenchSensor_", T_list=[float, AutoDiffXd])
def WrenchSensor_(T):
    """Template of the wrist force/torque sensor; see ``WrenchSensor``."""

    class Impl(_WrenchSensor, LeafSystem_[T]):
        __doc__ = _WrenchSensor.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _WrenchSensor._construct
        _construct_copy = _WrenchSensor._construct_copy

    return Impl


#: The double-valued wrist force/torque sensor (see ``WrenchSensor_``).
WrenchSensor = WrenchSensor_[None]
