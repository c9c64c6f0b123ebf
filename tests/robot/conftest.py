"""Shared fixtures: a connected kinematic FR3 twin, its world and gripper (skipped without roboticstoolbox)."""

from __future__ import annotations

import pytest


@pytest.fixture
def twin():
    """The twin module (roboticstoolbox-python must be installed: the `robot` extra)."""
    pytest.importorskip("roboticstoolbox", reason="the kinematic twin needs roboticstoolbox-python")
    from tactile_manip.robot import twin as twin_module

    return twin_module


@pytest.fixture
def arm(twin):
    """A connected KinematicArm at home."""
    arm = twin.KinematicArm()
    arm.connect()
    yield arm
    arm.disconnect()


@pytest.fixture
def world(twin, arm):
    return twin.TwinWorld(arm)


@pytest.fixture
def gripper(twin, arm, world):
    """A connected TwinGripper, fully open."""
    gripper = twin.TwinGripper(arm, world)
    gripper.connect()
    yield gripper
    gripper.disconnect()
