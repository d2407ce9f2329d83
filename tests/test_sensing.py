"""The hand's sensing: a sampled FlexiForce readout and the contact-results force sensor."""

from __future__ import annotations

import math

import pytest
from pydrake.geometry import AddContactMaterial, Box, ProximityProperties, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    ContactModel,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from admittance.systems.contact_force_sensor import ContactForceSensor
from admittance.systems.flexiforce import FlexiForceSensor

# --- the sampled FlexiForce readout ------------------------------------------------------


def test_sampled_flexiforce_advances_the_rc_filter_exactly():
    """V[k] after a force step F: Vs + (V0 - Vs) exp(-k h / tau), read one sample late."""
    period = 1e-4  # comparable with tau (31.8 us at 5 kHz), so the decay is visible
    sensor = FlexiForceSensor(period=period)
    context = sensor.CreateDefaultContext()
    sensor.contact_force_input.FixValue(context, [10.0])
    sensor.noise_input.FixValue(context, [0.0])
    simulator = Simulator(sensor, context)
    static = sensor.static_output_voltage(10.0)
    start = sensor.unloaded_voltage
    tau = sensor.filter_time_constant
    for samples in (1, 2, 5):
        # Just before sample k's update, the output holds the state after k updates at
        # 0, h, ..., (k - 1) h.
        simulator.AdvanceTo((samples - 0.5) * period)
        voltage = start + (static - start) * (1.0 - math.exp(-samples * period / tau))
        expected = sensor.calibrated_force(voltage)
        reading = sensor.measured_force_output.Eval(context)[0]
        assert reading == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_sampled_flexiforce_has_no_continuous_state_and_converts():
    sensor = FlexiForceSensor(period=1e-3)
    context = sensor.CreateDefaultContext()
    assert context.num_continuous_states() == 0
    assert context.num_discrete_state_groups() == 1
    # An ADC's clock: samples at t = 0, T, 2T, ...
    event = sensor.GetUniquePeriodicDiscreteUpdateAttribute()
    assert (event.period_sec(), event.offset_sec()) == (1e-3, 0.0)
    assert sensor.EvalTimeDerivatives(context).size() == 0
    # Unloaded, the held voltage is the offset: the reading is the noise alone, added.
    assert sensor.measured_force_output.size() == 1
    sensor.contact_force_input.FixValue(context, [0.0])
    sensor.noise_input.FixValue(context, [0.3])
    assert sensor.measured_force_output.Eval(context)[0] == pytest.approx(0.3, abs=1e-12)
    assert sensor.ToAutoDiffXd().period == 1e-3
    with pytest.raises(ValueError, match="period"):
        FlexiForceSensor(period=-1e-3)


# --- the contact force sensor ------------------------------------------------------------


def _box_on_a_ball(mass: float, stiffness: float, far_on_a_ball: bool = False):
    """A free box resting on a ball welded to the world (point contact, discrete plant), and
    a far box falling freely 1 m to the side, or resting on a ball of its own there."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, contact_model="point"), builder
    )
    box = plant.AddRigidBody("box", SpatialInertia.SolidBoxWithMass(mass, 0.1, 0.1, 0.1))
    far = plant.AddRigidBody("far", SpatialInertia.SolidBoxWithMass(mass, 0.1, 0.1, 0.1))
    properties = ProximityProperties()
    AddContactMaterial(
        dissipation=10.0,
        point_stiffness=2 * stiffness,
        friction=CoulombFriction(1.0, 1.0),
        properties=properties,
    )
    plant.RegisterCollisionGeometry(box, RigidTransform(), Box(0.1, 0.1, 0.1), "box", properties)
    plant.RegisterCollisionGeometry(far, RigidTransform(), Box(0.1, 0.1, 0.1), "far", properties)
    for x in (0.0, 1.0) if far_on_a_ball else (0.0,):
        plant.RegisterCollisionGeometry(
            plant.world_body(), RigidTransform([x, 0, -0.1]), Sphere(0.05), f"ball{x}", properties
        )
    plant.Finalize()
    sensor = builder.AddSystem(
        ContactForceSensor(plant, body_pairs=[("box", "world"), ("far", "world")])
    )
    builder.Connect(plant.get_contact_results_output_port(), sensor.contact_results_input)
    for name in ("box", "far"):  # one pair each: the other box's contact is not theirs
        single = builder.AddNamedSystem(
            name, ContactForceSensor(plant, body_pairs=[(name, "world")])
        )
        builder.Connect(plant.get_contact_results_output_port(), single.contact_results_input)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetFreeBodyPose(plant_context, box, RigidTransform([0, 0, 0.0]))
    # The far box, 1 m to the side: it touches nothing but its own ball, if any.
    plant.SetFreeBodyPose(plant_context, far, RigidTransform([1.0, 0, 0.0]))
    return simulator, sensor, diagram


def test_contact_force_sensor_reads_the_weight_of_a_box_at_rest():
    """Statics: at rest on one contact point, the normal force is m g (Drake's g, 9.81)."""
    mass = 0.5
    simulator, sensor, _ = _box_on_a_ball(mass, 1e5)
    simulator.AdvanceTo(1.5)  # settles in ~0.2 s (dissipation), long before
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    force = sensor.normal_force_output.Eval(context)
    # The box is at rest (its velocity below 1e-6 m/s), so the contact carries its weight
    # to the solver's tolerance: measured 5e-7 relative; 1e-4 allowed.
    assert force[0] == pytest.approx(mass * 9.81, rel=1e-4)
    # The far box is in free fall (it has not reached anything): 0 N between it and the
    # world.
    assert force[1] == 0.0


def test_contact_force_sensors_each_read_their_own_pair_among_others():
    """Two boxes at rest on a ball each: the sensor of both pairs reads both weights, and
    the sensor of one pair reads its own, whatever other contact comes first."""
    mass = 0.5
    simulator, sensor, diagram = _box_on_a_ball(mass, 1e5, far_on_a_ball=True)
    simulator.AdvanceTo(1.5)
    root = simulator.get_context()
    weight = mass * 9.81  # at rest, as above: 5e-7 measured, 1e-4 allowed
    both = sensor.normal_force_output.Eval(sensor.GetMyContextFromRoot(root))
    assert list(both) == pytest.approx([weight, weight], rel=1e-4)
    for name in ("box", "far"):
        single = diagram.GetSubsystemByName(name)
        force = single.normal_force_output.Eval(single.GetMyContextFromRoot(root))
        assert force[0] == pytest.approx(weight, rel=1e-4)


def test_contact_force_sensor_checks_its_pairs():
    simulator, sensor, diagram = _box_on_a_ball(0.5, 1e5)
    plant = diagram.GetSubsystemByName("plant")
    with pytest.raises(ValueError, match="no body named 'nope'"):
        ContactForceSensor(plant, body_pairs=[("box", "nope")])
    with pytest.raises(ValueError, match="watched twice"):
        ContactForceSensor(plant, body_pairs=[("box", "world"), ("world", "box")])
    with pytest.raises(ValueError, match="at least one pair"):
        ContactForceSensor(plant, body_pairs=[])
    twin = "".join(["bo", "x"])  # the same name, built at run time
    with pytest.raises(ValueError, match="two different bodies"):
        ContactForceSensor(plant, body_pairs=[("box", twin)])
    with pytest.raises(TypeError):  # keyword-only
        ContactForceSensor(plant, [("box", "world")])
    hydroelastic = MultibodyPlant(time_step=1e-3)
    hydroelastic.set_contact_model(ContactModel.kHydroelasticWithFallback)
    hydroelastic.Finalize()
    with pytest.raises(ValueError, match="reads point contact"):
        ContactForceSensor(hydroelastic, body_pairs=[("box", "world")])
    assert sensor.ToAutoDiffXd().body_pairs == [("box", "world"), ("far", "world")]
