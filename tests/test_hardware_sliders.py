"""The station's Meshcat sliders for Fr, Gamma, alpha and Fmax reach the running law as
the parameter message (diagrams/hardware/sliders.py; Meshcat on localhost, LCM memq://)."""

from __future__ import annotations

import math

import pytest
from pydrake.lcm import DrakeLcm

from admittance.diagrams.hardware.config import load_hardware_config
from admittance.diagrams.hardware.controller import AdmittanceController
from admittance.diagrams.hardware.sliders import ParameterSliders, station_meshcat
from admittance.diagrams.hardware.station import run_station
from admittance.diagrams.robots.spatial_arm.plant import example_robot_data_packages

pytestmark = pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason='example-robot-data is not installed: pip install "optimal-admittance[robots]"',
)


def test_a_slider_moved_on_the_station_reaches_the_running_law():
    """Fr to 5 N and Gamma to 4e-6 on the sliders: the station's first poll publishes one
    message and the controller's law runs with both; a slider that did not move sends
    nothing; Fmax below Fr is refused by the controller with an event line."""
    lcm = DrakeLcm("memq://")
    config = load_hardware_config(
        "panda_surface_press", ["command_wait=0", "realtime_rate=0", "duration=0.03"]
    )
    controller = AdmittanceController(config, lcm)
    meshcat = station_meshcat()
    assert meshcat.web_url().startswith("http://localhost:")
    sliders = ParameterSliders(
        meshcat, lcm, force_reference=10.0, gamma=6e-6, alpha=0.0, max_force=math.inf
    )
    assert sliders.poll() == {}
    meshcat.SetSliderValue(sliders.label("force_reference"), 5.0)
    meshcat.SetSliderValue(sliders.label("gamma"), 4e-6)
    run_station(config, lcm, sliders=sliders)
    assert sliders.published == [{"force_reference": 5.0, "gamma": pytest.approx(4e-6)}]
    assert controller.law.force_reference == 5.0
    assert controller.law.gamma == pytest.approx(4e-6)
    assert controller.law.desired_force(3.0) == pytest.approx(5.0)
    meshcat.SetSliderValue(sliders.label("max_force"), 3.0)
    sliders.poll()
    lcm.HandleSubscriptions(0)
    assert controller.law.max_force == math.inf
    assert controller.events[-1].what.startswith("parameters rejected: max_force")
