"""Shared fixtures: the arm's plant as the project loads it."""

from __future__ import annotations

import pytest

from admittance.diagrams.robots.planar_arm.plant import AddPlanarArm
from admittance.urdf import PLANAR_ARM_URDF


@pytest.fixture(scope="session")
def arm_plant():
    """The paper's arm (rigid-body model, gravity along -y), finalized, in its own diagram."""
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, _ = AddPlanarArm(builder, PLANAR_ARM_URDF)
    return plant
