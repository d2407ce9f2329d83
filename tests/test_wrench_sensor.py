"""Tests of the wrist force/torque sensor (systems/wrench_sensor.py) on the Franka Panda.

The rig: example-robot-data's Panda with every joint made fixed (the arm held still at
q = 0, so the weld's reaction is static and exact), its base welded to the world at a
chosen pose, and a tool welded to the flange ``panda_link8`` through a weld ``ft_weld``:
a solid sphere of m = 0.5 kg, radius 0.03 m, centred at c_B = (0.01, -0.02, 0.05) m in
the tool's body frame B. The sensor frame S is the weld's frame on the tool, a frame
fixed in B at X_BS = (rpy (0.1, 0.2, 0.3), p (0.01, 0, -0.02) m), welded to the flange
at X_8S = (rpy (0, 0, -pi/4), p 0). Gravity is (0, 0, -9.81) m/s^2.

Hand derivation of the expected values (independent of the sensor's code):

* At q = 0 the URDF's six joint origins turn about x by -90, +90, +90, -90, +90, +90
  degrees: a half turn, so R_08 = Rx(pi) (the flange points down) and
  R_WS = R_W0 Rx(pi) Rz(-pi/4).
* The tool hangs still on the weld: the sensor feels the tool's weight, f_S = m R_WS^T g
  and tau_S = c_S x f_S about S, with c_S = X_BS^-1 c_B. With the base upright,
  R_WS^T (0, 0, -9.81) = Rz(pi/4) Rx(pi) (0, 0, -9.81) = (0, 0, 9.81): f_S = (0, 0, 4.905) N.
* A wrench (tau_W, f_W) applied by the surface to the tool at its contact point P
  (r_SP = (0, 0, 0.08) m in S) adds, after the weight is removed, f_S = R_WS^T f_W and
  tau_S = R_WS^T tau_W + r_SP x f_S. In the control frame E (X_WE = rpy (pi, 0, 0),
  z down: a table's inward normal), the tool's push on the surface about P is
  -R_EW [f_W; tau_W]; with f_W = (2, -1, 10) N (the table pushing up) and
  tau_W = (0.3, -0.2, 0.1) N m, Rx(pi) (x, y, z) = (x, -y, -z) gives
  [-2, -1, 10, -0.3, -0.2, 0.1]: a 10 N push along the normal, positive.
"""

from __future__ import annotations

import importlib.metadata
import math
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.common.cpp_param import List
from pydrake.common.value import Value
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, SpatialInertia, WeldJoint
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import (
    ConstantValueSource,
    ConstantVectorSource,
    Linearize,
    RandomSource,
)

from admittance.diagrams.loop.point import AddSensorChain
from admittance.diagrams.robots.description import ForcePoint, SensorChain
from admittance.systems.wrench_in_control_frame import WrenchInControlFrame
from admittance.systems.wrench_sensor import WrenchSensor, carried_mass_and_com


def _panda_folder() -> Path | None:
    """example-robot-data's panda_description folder, or None when it is not installed."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    folder = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    return folder / "panda_description" if folder.is_dir() else None


PANDA = _panda_folder()
pytestmark = pytest.mark.skipif(
    PANDA is None, reason="example-robot-data is not installed (pip install example-robot-data)"
)

MASS = 0.5  # kg
RADIUS = 0.03  # m
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2, the plant's default
C_B = np.array([0.01, -0.02, 0.05])  # m, the tool's centre of mass in B
X_BS = RigidTransform(RollPitchYaw(0.1, 0.2, 0.3), [0.01, 0.0, -0.02])
X_8S = RigidTransform(RollPitchYaw(0.0, 0.0, -math.pi / 4), [0.0, 0.0, 0.0])
R_08 = RotationMatrix.MakeXRotation(math.pi)  # the flange at q = 0 (module docstring)
X_WE = RigidTransform(RollPitchYaw(math.pi, 0.0, 0.0), [0.5, 0.0, 0.2])
R_SP = np.array([0.0, 0.0, 0.08])  # m, the contact point in S
C_S = X_BS.inverse().multiply(C_B)  # m, the centre of mass in S
# The surface's wrench on the tool at P, in W (N m, N), and the push it reads as.
TAU_W = np.array([0.3, -0.2, 0.1])
F_W = np.array([2.0, -1.0, 10.0])
PUSH_E = np.array([-2.0, -1.0, 10.0, -0.3, -0.2, 0.1])
BASES = {
    "upright": RigidTransform(),
    "tilted": RigidTransform(RollPitchYaw(0.4, -0.3, 1.1), [0.1, -0.2, 0.0]),
}


def _add_panda_with_tool(builder, X_W0, *, held=True, remove=None):
    """The Panda welded at X_W0 with the tool on ``ft_weld``, and the frame E; `held`
    makes every joint fixed (the arm held still at q = 0); `remove` names a joint removed
    before the weld is added (its index is then a gap)."""
    text = (PANDA / "urdf" / "panda.urdf").read_text()
    if held:
        text = re.sub(r'type="(revolute|prismatic)"', 'type="fixed"', text)
    text = re.sub(r"<(safety_controller|mimic)[^>]*/>", "", text)
    plant = builder.AddSystem(MultibodyPlant(0.0))  # no SceneGraph: no meshes needed
    parser = Parser(plant)
    parser.package_map().Add("example-robot-data", str(PANDA.parent.parent))
    (model,) = parser.AddModelsFromString(text, "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"), X_W0)
    if remove is not None:  # replaced by a weld, as a description may do
        joint = plant.GetJointByName(remove)
        parent, child = joint.frame_on_parent(), joint.frame_on_child()
        plant.RemoveJoint(joint)
        plant.WeldFrames(parent, child, RigidTransform())
    tool = plant.AddRigidBody(
        "tool", model, SpatialInertia.SolidSphereWithMass(MASS, RADIUS).Shift(-C_B)
    )
    sensor_frame = plant.AddFrame(FixedOffsetFrame("ft_sensor", tool.body_frame(), X_BS))
    plant.AddJoint(WeldJoint("ft_weld", plant.GetFrameByName("panda_link8"), sensor_frame, X_8S))
    plant.AddFrame(FixedOffsetFrame("surface", plant.world_frame(), X_WE))
    plant.Finalize()
    return plant, tool


def _apply_surface_wrench(builder, plant, tool):
    """(tau_W, f_W) on the tool at P, through the plant's applied spatial force input."""
    force = ExternallyAppliedSpatialForce()
    force.body_index = tool.index()
    force.p_BoBq_B = X_BS.multiply(R_SP)
    force.F_Bq_W = SpatialForce(TAU_W, F_W)
    source = builder.AddSystem(
        ConstantValueSource(Value[List[ExternallyAppliedSpatialForce]]([force]))
    )
    builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())


def _add_sensor(builder, plant, **sensor_args):
    """A WrenchSensor on ``ft_weld`` (the rig's tool by default) reading the plant."""
    sensor_args.setdefault("tool_mass", MASS)
    sensor_args.setdefault("tool_com", C_S)
    sensor = builder.AddSystem(WrenchSensor(plant, "ft_weld", **sensor_args))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.reaction_forces_input)
    builder.Connect(plant.get_body_poses_output_port(), sensor.body_poses_input)
    return sensor


def _rig(base="upright", *, push=False, noise_source=None, **sensor_args):
    """The rig's diagram, its context, the sensor and the control-frame reading."""
    builder = DiagramBuilder()
    plant, tool = _add_panda_with_tool(builder, BASES[base])
    if push:
        _apply_surface_wrench(builder, plant, tool)
    sensor = _add_sensor(builder, plant, **sensor_args)
    if noise_source is not None:
        source = builder.AddSystem(noise_source)
        builder.Connect(source.get_output_port(0), sensor.noise_input)
    else:
        builder.ExportInput(sensor.noise_input, "noise")
    frame = builder.AddSystem(
        WrenchInControlFrame(plant, "ft_weld", "surface", contact_offset=R_SP, axes=range(6))
    )
    builder.Connect(sensor.compensated_wrench_output, frame.wrench_input)
    builder.Connect(plant.get_body_poses_output_port(), frame.body_poses_input)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    if noise_source is None:
        diagram.get_input_port(0).FixValue(context, np.zeros(6))
    return diagram, context, sensor, frame


def _R_WS(base: str) -> RotationMatrix:
    return BASES[base].rotation().multiply(R_08).multiply(X_8S.rotation())


def _weight_in_S(base: str) -> np.ndarray:
    """[m g_S; c_S x m g_S], from the rig's numbers alone."""
    weight_S = _R_WS(base).inverse().multiply(MASS * GRAVITY)
    return np.concatenate([weight_S, np.cross(C_S, weight_S)])


def _eval(system, port, context):
    return port.Eval(system.GetMyContextFromRoot(context))


@pytest.mark.parametrize("base", sorted(BASES))
def test_still_tool_reads_its_weight_and_compensates_to_zero(base):
    diagram, context, sensor, frame = _rig(base)
    weight = _weight_in_S(base)
    if base == "upright":  # the hand-computed force of the module's docstring
        np.testing.assert_allclose(weight[:3], [0.0, 0.0, 4.905], atol=1e-12)
    raw = _eval(sensor, sensor.wrench_output, context)
    np.testing.assert_allclose(raw, weight, rtol=1e-9, atol=1e-9 * MASS * 9.81)
    compensated = _eval(sensor, sensor.compensated_wrench_output, context)
    np.testing.assert_allclose(compensated, 0.0, atol=1e-9)
    np.testing.assert_allclose(_eval(frame, frame.force_output, context), 0.0, atol=1e-9)


def test_weld_after_a_removed_joint():
    """A description's joint removed and welded again (its index left a gap): the weld's
    entry in the reaction-force port is its position among the joints; it reads the
    weight."""
    builder = DiagramBuilder()
    plant, _ = _add_panda_with_tool(builder, BASES["upright"], remove="panda_hand_tcp_joint")
    indices = [int(i) for i in plant.GetJointIndices()]
    assert indices != list(range(len(indices)))  # the gap is there
    sensor = _add_sensor(builder, plant)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    sensor_context = sensor.GetMyMutableContextFromRoot(context)
    sensor.noise_input.FixValue(sensor_context, np.zeros(6))
    raw = sensor.wrench_output.Eval(sensor_context)
    np.testing.assert_allclose(raw, _weight_in_S("upright"), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("base", sorted(BASES))
def test_surface_wrench_in_sensor_and_control_frame(base):
    diagram, context, sensor, frame = _rig(base, push=True)
    R_SW = _R_WS(base).inverse()
    f_S = R_SW.multiply(F_W)
    tau_S = R_SW.multiply(TAU_W) + np.cross(R_SP, f_S)
    compensated = _eval(sensor, sensor.compensated_wrench_output, context)
    np.testing.assert_allclose(compensated, np.concatenate([f_S, tau_S]), rtol=1e-9, atol=1e-9)
    force = _eval(frame, frame.force_output, context)
    np.testing.assert_allclose(force, PUSH_E, rtol=1e-9, atol=1e-9)
    assert force[2] > 9.99  # pushing the table reads positive along its inward normal


def test_inertial_force_is_not_compensated():
    """The arm let go (no torque, at rest) falls: the tool's centre of mass accelerates at
    a, the weld carries m (a - g), and the compensated reading is the inertial force
    -m a in S (Newton's second law for the tool; a from the plant's forward dynamics)."""
    builder = DiagramBuilder()
    plant, tool = _add_panda_with_tool(builder, BASES["upright"], held=False)
    sensor = _add_sensor(builder, plant)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.get_actuation_input_port().FixValue(plant_context, np.zeros(plant.num_actuators()))
    plant.SetPositions(plant_context, [0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.7, 0.02, 0.02])
    sensor_context = sensor.GetMyMutableContextFromRoot(context)
    sensor.noise_input.FixValue(sensor_context, np.zeros(6))
    A_WB = plant.EvalBodySpatialAccelerationInWorld(plant_context, tool)
    X_WB = plant.EvalBodyPoseInWorld(plant_context, tool)
    a_W = A_WB.translational() + np.cross(A_WB.rotational(), X_WB.rotation().multiply(C_B))
    R_SW = X_WB.rotation().multiply(X_BS.rotation()).inverse()
    compensated = sensor.compensated_wrench_output.Eval(sensor_context)
    assert np.linalg.norm(a_W) > 1.0  # m/s^2: a real fall, not a rounding error
    np.testing.assert_allclose(compensated[:3], -MASS * R_SW.multiply(a_W), rtol=1e-9, atol=1e-9)


def test_bias_adds_exactly():
    bias = np.array([0.1, -0.2, 0.3, 0.01, -0.02, 0.03])
    diagram, context, sensor, _ = _rig("tilted", bias=bias)
    raw = _eval(sensor, sensor.wrench_output, context)
    np.testing.assert_allclose(raw, _weight_in_S("tilted") + bias, rtol=0, atol=1e-12)
    compensated = _eval(sensor, sensor.compensated_wrench_output, context)
    np.testing.assert_allclose(compensated, bias, rtol=0, atol=1e-12)


def test_noise_has_the_stated_std():
    """N = 2000 samples at the 1 ms period: the sample std's relative standard error is
    1 / sqrt(2 (N - 1)) = 1.6 %, so 8 % is five of them; the mean's is std / sqrt(N),
    and 5 std / sqrt(N) = 0.11 std bounds it."""
    period, samples = 1e-3, 2000
    sigma = np.array([0.5] * 3 + [0.02] * 3)
    source = RandomSource(RandomDistribution.kGaussian, 6, period)
    diagram, context, sensor, _ = _rig(
        "tilted", noise_source=source, period=period, force_noise_std=0.5, torque_noise_std=0.02
    )
    diagram.SetRandomContext(context, RandomGenerator(7))
    simulator = Simulator(diagram, context)
    readings = []
    for k in range(samples):
        simulator.AdvanceTo((k + 0.5) * period)
        readings.append(_eval(sensor, sensor.wrench_output, context).copy())
    errors = np.array(readings) - _weight_in_S("tilted")
    np.testing.assert_allclose(errors.std(axis=0, ddof=1), sigma, rtol=0.08)
    assert np.all(np.abs(errors.mean(axis=0)) < 5 * sigma / math.sqrt(samples))
    assert len(np.unique(errors[:, 2])) == samples  # one draw per period


def test_low_pass_step_response_reaches_one_minus_1_over_e_at_tau():
    """The filter starts at zero (switched on with the tool already hanging): a step of
    the weight at t = 0, so x(tau) = (1 - e^-1) w, tau = 1 / (2 pi 10 Hz) = 15.9 ms. The
    integrator's target accuracy of 1e-10 leaves the error well below the 1e-6 asked."""
    cutoff = 10.0
    tau = 1.0 / (2 * math.pi * cutoff)
    diagram, context, sensor, _ = _rig("tilted", filter_cutoff_hz=cutoff)
    assert sensor.filter_time_constant == pytest.approx(tau, rel=1e-15)
    simulator = Simulator(diagram, context)
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)
    simulator.AdvanceTo(tau)
    raw = _eval(sensor, sensor.wrench_output, context)
    expected = (1 - math.exp(-1)) * _weight_in_S("tilted")
    np.testing.assert_allclose(raw, expected, rtol=1e-6, atol=1e-9)


def test_period_holds_the_reading_between_samples():
    """A 10 ms readout behind the 10 Hz low-pass, from zero: after the samples at 0, h,
    ..., k h the state is w (1 - d^(k+1)), d = exp(-h / tau), and the reading holds that
    value over (k h, (k + 1) h) while the continuous filter would move by 47 % of it."""
    period, cutoff = 0.01, 10.0
    decay = math.exp(-period * 2 * math.pi * cutoff)
    diagram, context, sensor, _ = _rig("tilted", filter_cutoff_hz=cutoff, period=period)
    weight = _weight_in_S("tilted")
    simulator = Simulator(diagram, context)
    for k in range(5):
        held = (1 - decay ** (k + 1)) * weight
        for fraction in (0.1, 0.5, 0.9):
            simulator.AdvanceTo((k + fraction) * period)
            raw = _eval(sensor, sensor.wrench_output, context)
            np.testing.assert_allclose(raw, held, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("period", [0.0, 0.01])
def test_initialize_reading_starts_settled(period):
    diagram, context, sensor, _ = _rig("tilted", filter_cutoff_hz=10.0, period=period)
    sensor.InitializeReading(sensor.GetMyMutableContextFromRoot(context))
    raw = _eval(sensor, sensor.wrench_output, context)
    np.testing.assert_allclose(raw, _weight_in_S("tilted"), rtol=1e-9, atol=1e-12)
    compensated = _eval(sensor, sensor.compensated_wrench_output, context)
    np.testing.assert_allclose(compensated, 0.0, atol=1e-9)


def test_autodiff_reads_as_float():
    """The rig converts to AutoDiffXd (sensor, plant and control frame) and reads alike."""
    diagram, context, sensor, frame = _rig("tilted", push=True, filter_cutoff_hz=10.0)
    sensor.InitializeReading(sensor.GetMyMutableContextFromRoot(context))
    autodiff = diagram.ToAutoDiffXd()
    ad_context = autodiff.CreateDefaultContext()
    ad_context.SetTimeStateAndParametersFrom(context)
    autodiff.get_input_port(0).FixValue(ad_context, np.zeros(6))
    ad_frame = autodiff.GetSubsystemByName(frame.get_name())
    values = [v.value() for v in _eval(ad_frame, ad_frame.force_output, ad_context)]
    np.testing.assert_allclose(values, PUSH_E, rtol=1e-9, atol=1e-9)


def test_linearizes_with_the_arm():
    """Drake's Linearize through the plant's reaction forces (AutoDiffXd), the Panda held
    by its gravity torques at rest: the filter's block of A is -2 pi f_c I; its coupling
    to the arm's state x = (q, v) is (1 / tau) dw/dx, against central differences of the
    float reading (step 1e-6, error O(1e-12) on terms of order 1: 1e-6 is ample). The
    URDF's joint damping makes w depend on v even at rest."""
    cutoff = 10.0
    builder = DiagramBuilder()
    plant, _ = _add_panda_with_tool(builder, BASES["tilted"], held=False)
    sensor = _add_sensor(builder, plant, filter_cutoff_hz=cutoff)
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    builder.Connect(zero.get_output_port(), sensor.noise_input)
    q = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.7, 0.02, 0.02])
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    holding = builder.AddSystem(
        ConstantVectorSource(-plant.CalcGravityGeneralizedForces(plant_context))
    )
    builder.Connect(holding.get_output_port(), plant.get_applied_generalized_force_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), q)
    sensor.InitializeReading(sensor.GetMyMutableContextFromRoot(context))
    A = Linearize(
        diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
        equilibrium_check_tolerance=1e-9,
    ).A()
    n, nq = plant.num_multibody_states(), plant.num_positions()
    np.testing.assert_allclose(A[n:, n:], -2 * math.pi * cutoff * np.eye(6), rtol=1e-12)
    state = np.concatenate([q, np.zeros(n - nq)])

    def reading(x):
        plant.SetPositionsAndVelocities(plant.GetMyMutableContextFromRoot(context), x)
        return np.array(sensor.true_wrench(sensor.GetMyContextFromRoot(context)))

    step = 1e-6
    columns = [
        (reading(state + step * e) - reading(state - step * e)) / (2 * step) for e in np.eye(n)
    ]
    expected = 2 * math.pi * cutoff * np.array(columns).T
    assert np.abs(expected).max() > 1.0  # the coupling is there to be checked
    np.testing.assert_allclose(A[n:, :n], expected, rtol=1e-6, atol=1e-6)


def test_add_sensor_chain_wires_the_wrist_sensor():
    """The point's chain of kind "wrench": the normal force in the point's frame, 10 N."""
    builder = DiagramBuilder()
    plant, tool = _add_panda_with_tool(builder, BASES["tilted"])
    _apply_surface_wrench(builder, plant, tool)
    chain = SensorChain(
        kind="wrench",
        filter_cutoff=0.0,
        weld_joint="ft_weld",
        contact_offset=tuple(R_SP),  # tool_mass and tool_com: the plant's
    )
    point = ForcePoint(
        name="tool",
        frame="ft_sensor",
        coordinates=("x", "y", "z", "rx", "ry", "rz"),
        expressed_in="surface",
        force_axes=(2, 3),
        sensor=chain,
    )
    reading = AddSensorChain(builder, point, None, plant=plant)
    assert reading.random_sources == []  # no noise std: a zero source
    noisy = ForcePoint(
        name="noisy",
        frame="ft_sensor",
        coordinates=point.coordinates,
        expressed_in="surface",
        force_axes=(2,),
        sensor=SensorChain(kind="wrench", weld_joint="ft_weld", noise_std=0.1, period=0.002),
    )
    (source,) = AddSensorChain(builder, noisy, None, plant=plant).random_sources
    assert source.get_output_port(0).size() == 6
    noisy.name = "quiet"
    quiet = AddSensorChain(builder, noisy, None, plant=plant, noise=False)  # for analysis
    assert quiet.random_sources == []
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    force = reading.measured_force_output.Eval(reading.control_frame.GetMyContextFromRoot(context))
    np.testing.assert_allclose(force, PUSH_E[[2, 3]], rtol=1e-9, atol=1e-9)


def test_carried_mass_and_com_is_the_tool():
    """The weld carries the sphere alone: 0.5 kg at c_S = X_BS^-1 c_B."""
    plant, _ = _add_panda_with_tool(DiagramBuilder(), BASES["tilted"])
    mass, com = carried_mass_and_com(plant, "ft_weld")
    assert mass == pytest.approx(MASS, rel=1e-12)
    np.testing.assert_allclose(com, C_S, rtol=0, atol=1e-12)
    # Without tool_mass and tool_com the sensor takes these: the still tool reads zero.
    diagram, context, sensor, _ = _rig("tilted", tool_mass=None, tool_com=None)
    compensated = _eval(sensor, sensor.compensated_wrench_output, context)
    np.testing.assert_allclose(compensated, 0.0, atol=1e-9)
    # panda_joint8 (link7 to the flange) carries the flange, the hand and its fingers,
    # and the tool: more than the tool.
    assert carried_mass_and_com(plant, "panda_joint8")[0] > MASS + 0.5


def test_bad_arguments_name_themselves():
    builder = DiagramBuilder()
    plant, _ = _add_panda_with_tool(builder, BASES["upright"])
    with pytest.raises(ValueError, match="weld_joint: the plant has no joint named 'ft'"):
        WrenchSensor(plant, "ft")
    with pytest.raises(ValueError, match="filter_cutoff_hz"):
        WrenchSensor(plant, "ft_weld", filter_cutoff_hz=-1.0)
    with pytest.raises(ValueError, match="axes"):
        WrenchInControlFrame(plant, "ft_weld", "surface", axes=(2, 6))
