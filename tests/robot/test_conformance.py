"""The conformance check passes the twin and catches backends that misbehave (so it can fail)."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.robot.conformance import CHECKS, run_conformance
from tactile_manip.robot.safety import SafeArm

ALL_CHECKS = [name for name, _ in CHECKS]


def _parts(twin, arm_class=None, gripper_class=None):
    arm = (arm_class or twin.KinematicArm)()
    world = twin.TwinWorld(arm)
    return arm, (gripper_class or twin.TwinGripper)(arm, world)


def test_the_twin_passes(twin):
    arm, gripper = _parts(twin)
    report = run_conformance(arm, gripper)
    assert report.ok, report.summary()
    assert [c.name for c in report.checks] == ALL_CHECKS
    report.raise_if_failed()
    assert not arm.is_connected and not gripper.is_connected


def test_the_twin_behind_a_safe_arm_passes_without_a_gripper(twin):
    report = run_conformance(SafeArm(twin.KinematicArm()), None)
    assert report.ok, report.summary()
    assert "skipped" in report.result("gripper").detail


def test_an_arm_landing_5_mm_off_fails_the_cartesian_checks(twin):
    class OffBy5mm(twin.KinematicArm):
        def move_cartesian(self, base_T_hand, *, speed_factor=None):
            shifted = np.array(base_T_hand, dtype=float)
            shifted[0, 3] += 0.005
            super().move_cartesian(shifted, speed_factor=speed_factor)

    report = run_conformance(*_parts(twin, arm_class=OffBy5mm))
    assert {c.name for c in report.failed} == {"cartesian_translation", "reorientation"}
    assert "5.000 mm" in report.result("cartesian_translation").detail
    with pytest.raises(AssertionError, match="cartesian_translation: .*\n.*reorientation"):
        report.raise_if_failed()
    assert "FAIL  reorientation" in report.summary()


def test_an_arm_stopping_short_in_joint_space_fails_the_joint_checks(twin):
    class StopsShort(twin.KinematicArm):
        def move_joints(self, q_rad, *, speed_factor=None):
            q_now = self.state().q_rad
            super().move_joints(q_now + 0.9 * (np.asarray(q_rad) - q_now), speed_factor=speed_factor)

    report = run_conformance(StopsShort(), None)
    assert not report.result("joint_move").passed
    assert report.result("cartesian_translation").passed


def test_a_gripper_that_does_not_open_fully_fails_the_gripper_check(twin):
    class HalfOpen(twin.TwinGripper):
        def open(self, width_m=None, *, speed_m_s=0.05):
            super().open(0.04, speed_m_s=speed_m_s)

    report = run_conformance(*_parts(twin, gripper_class=HalfOpen))
    assert [c.name for c in report.failed] == ["gripper"]


def test_an_arm_that_cannot_connect_stops_the_run(twin):
    class Unreachable(twin.KinematicArm):
        def connect(self):
            raise ConnectionError("no route to 172.16.0.2")

    report = run_conformance(Unreachable(), None)
    assert [(c.name, c.passed) for c in report.checks] == [("connect", False)]
    assert "ConnectionError: no route" in report.checks[0].detail
