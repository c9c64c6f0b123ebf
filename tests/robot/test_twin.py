"""The kinematic FR3 twin: FK/IK, limits, all-or-nothing moves, faults, held objects, the gripper."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.errors import ArmFault, GripperError, IKError, RobotNotConnectedError, SafetyLimitError
from tactile_manip.robot import fr3
from tactile_manip.robot.base import GraspResult, GripperState
from tactile_manip.robot.frames import angle_in_plane, hand_T_pad, rotate_pose_about, rotation_about, transform
from tactile_manip.robot.safety import pose_error


def _about_pad_normal(base_T_hand: np.ndarray, angle_rad: float) -> np.ndarray:
    base_T_pad = base_T_hand @ hand_T_pad()
    return rotate_pose_about(base_T_hand, base_T_pad[:3, 2], base_T_pad[:3, 3], angle_rad)


def _lifted(base_T_hand: np.ndarray, dz_m: float) -> np.ndarray:
    t = base_T_hand.copy()
    t[2, 3] += dz_m
    return t


# --- kinematics --------------------------------------------------------------------------------------

def test_home_is_inside_the_fr3_limits_with_the_hand_pointing_down(twin, arm):
    s = arm.state()
    assert np.all(s.q_rad >= fr3.FR3_Q_MIN_RAD) and np.all(s.q_rad <= fr3.FR3_Q_MAX_RAD)
    np.testing.assert_allclose(s.base_T_hand[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-9)
    np.testing.assert_allclose(s.base_T_hand[:3, 3], [0.4635, 0.0, 0.4028], atol=1e-4)
    assert not s.faulted and s.fault == ""


def test_fk_ik_round_trip(arm):
    rng = np.random.default_rng(0)
    for _ in range(3):
        q_goal = arm.home_q_rad + rng.uniform(-0.15, 0.15, 7)
        goal = arm.fk(q_goal)
        arm.move_cartesian(goal)
        position_m, angle_rad = pose_error(arm.state().base_T_hand, goal)
        assert position_m < 1e-6 and angle_rad < 1e-6


def test_move_cartesian_reaches_a_combined_target_in_small_steps(arm):
    start = arm.state().base_T_hand
    goal = _about_pad_normal(start, math.radians(20))
    goal[:3, 3] += [0.05, -0.03, 0.04]
    arm.move_cartesian(goal)
    position_m, angle_rad = pose_error(arm.state().base_T_hand, goal)
    assert position_m <= arm.config.reach_tolerance_m and angle_rad <= arm.config.reach_tolerance_rad
    path = arm.last_path_q_rad
    assert len(path) > 10  # stepped at step_m / step_rad, not one jump
    assert np.abs(np.diff(path, axis=0)).max() <= arm.config.max_joint_step_rad
    assert arm.last_move_duration_s > 0


@pytest.mark.parametrize("angle_deg", [90.0, -90.0])
def test_quarter_turn_about_the_pad_normal_is_reached_or_refused_cleanly(arm, angle_deg):
    q_before = arm.state().q_rad
    goal = _about_pad_normal(arm.state().base_T_hand, math.radians(angle_deg))
    try:
        arm.move_cartesian(goal)
    except IKError as e:
        assert "step" in str(e) and "did not move" in str(e)
        np.testing.assert_array_equal(arm.state().q_rad, q_before)
    else:
        position_m, angle_rad = pose_error(arm.state().base_T_hand, goal)
        assert position_m <= 1e-4 and angle_rad <= 1e-3


def test_fr3_joint_6_limit_applies_to_cartesian_paths(arm):
    """+90 deg about the pad normal from home needs joint 6 below the FR3 minimum (the Panda would allow it)."""
    goal = _about_pad_normal(arm.state().base_T_hand, math.radians(90))
    with pytest.raises(IKError, match=r"step \d+/\d+ .*joint 6 .* outside the FR3 limits"):
        arm.move_cartesian(goal)


def test_unreachable_target_raises_ikerror_and_the_arm_does_not_move(arm):
    q_before = arm.state().q_rad
    goal = arm.state().base_T_hand.copy()
    goal[0, 3] += 2.0
    with pytest.raises(IKError, match=r"step \d+/\d+.*target position \[2\.46"):
        arm.move_cartesian(goal)
    np.testing.assert_array_equal(arm.state().q_rad, q_before)


def test_joint_target_outside_the_limits_is_refused(arm):
    q_before = arm.state().q_rad
    target = arm.home_q_rad
    target[3] = 0.0  # FR3 joint 4 must stay below -0.1518 rad
    with pytest.raises(SafetyLimitError, match="joint 4"):
        arm.move_joints(target)
    np.testing.assert_array_equal(arm.state().q_rad, q_before)


def test_modelled_duration_follows_the_slowest_joint(twin, arm):
    target = arm.home_q_rad + np.array([0.2, 0.0, 0.0, 0.0, 0.4, 0.0, 0.0])
    arm.move_joints(target, speed_factor=0.5)
    expected_s = max(0.2 / (fr3.FR3_DQ_MAX_RAD_S[0] * 0.5), 0.4 / (fr3.FR3_DQ_MAX_RAD_S[4] * 0.5))
    assert arm.last_move_duration_s == pytest.approx(expected_s)


def test_moves_are_deterministic(twin):
    def run() -> list[np.ndarray]:
        arm = twin.KinematicArm()
        arm.connect()
        paths = []
        for goal in (_lifted(arm.state().base_T_hand, -0.05), None):
            goal = goal if goal is not None else _about_pad_normal(arm.state().base_T_hand, math.radians(-40))
            arm.move_cartesian(goal)
            paths.append(arm.last_path_q_rad)
        return paths

    for a, b in zip(run(), run()):
        np.testing.assert_array_equal(a, b)


def test_use_before_connect_is_refused(twin):
    arm = twin.KinematicArm()
    with pytest.raises(RobotNotConnectedError, match=r"connect\(\)"):
        arm.state()
    with pytest.raises(RobotNotConnectedError):
        arm.home()


def test_config_is_validated(twin):
    with pytest.raises(ValueError, match="speed_factor"):
        twin.TwinArmConfig(speed_factor=0.0)
    with pytest.raises(ValueError, match="home_q_rad: joint 6"):
        twin.TwinArmConfig(home_q_rad=(0.0, -0.3, 0.0, -2.2, 0.0, 0.0, 0.0))


# --- faults ------------------------------------------------------------------------------------------

def test_injected_fault_stops_a_joint_move_part_way(arm):
    home = arm.home_q_rad
    target = home + 0.2
    arm.inject_fault(kind="reflex", at_fraction=0.25)
    with pytest.raises(ArmFault) as caught:
        arm.move_joints(target)
    assert caught.value.kind == "reflex"
    s = arm.state()
    np.testing.assert_allclose(s.q_rad, home + 0.25 * 0.2)
    assert s.faulted and "reflex" in s.fault
    with pytest.raises(ArmFault, match=r"recover\(\)"):
        arm.move_joints(home)
    arm.recover()
    assert not arm.state().faulted
    arm.move_joints(target)  # the fault was one-shot
    np.testing.assert_allclose(arm.state().q_rad, target)


def test_injected_fault_stops_a_cartesian_move_part_way(arm):
    start = arm.state().base_T_hand
    arm.inject_fault(kind="communication", at_fraction=0.5)
    with pytest.raises(ArmFault):
        arm.move_cartesian(_lifted(start, 0.10))
    reached = arm.state().base_T_hand
    assert reached[2, 3] - start[2, 3] == pytest.approx(0.05, abs=arm.config.step_m)
    with pytest.raises(ArmFault):
        arm.move_cartesian(start)


def test_a_refused_move_does_not_use_up_the_injected_fault(arm):
    arm.inject_fault()
    goal = arm.state().base_T_hand.copy()
    goal[0, 3] += 2.0
    with pytest.raises(IKError):
        arm.move_cartesian(goal)
    with pytest.raises(ArmFault):
        arm.home()


def test_recover_also_disarms_an_unused_injected_fault(arm):
    arm.inject_fault()
    arm.recover()  # the trial boundary: nothing left over from the previous trial
    arm.move_joints(arm.home_q_rad + 0.1)
    assert not arm.state().faulted


# --- world and gripper -------------------------------------------------------------------------------

def _presented(twin, world, *, width_m=0.03, angle_rad=0.3, offset_m=(0.004, 0.002, -0.003)):
    obj = twin.WorldObject("key", width_m=width_m, payload={"any": "thing"})
    hand_T_object = transform(rotation_about([0.0, 1.0, 0.0], angle_rad), np.array(offset_m))
    world.present(obj, hand_T_object)
    return obj, hand_T_object


def test_held_object_follows_the_hand_rigidly_through_a_rotation(twin, arm, world, gripper):
    obj, _ = _presented(twin, world)
    assert gripper.grasp(0.03, 20.0).success
    hand_T_object = np.linalg.inv(arm.state().base_T_hand) @ world.object_pose(obj)
    base_T_pad = arm.state().base_T_hand @ hand_T_pad()  # the plane the angle is measured in, fixed
    angle_before = angle_in_plane(world.object_pose(obj)[:3, 0], base_T_pad)
    arm.move_cartesian(_about_pad_normal(arm.state().base_T_hand, math.radians(25)))
    angle_after = angle_in_plane(world.object_pose(obj)[:3, 0], base_T_pad)
    assert angle_after - angle_before == pytest.approx(math.radians(25), abs=1e-9)
    np.testing.assert_allclose(world.object_pose(obj), arm.state().base_T_hand @ hand_T_object, atol=1e-12)


def test_released_object_stays_where_it_was_let_go(twin, arm, world, gripper):
    obj, _ = _presented(twin, world)
    gripper.grasp(0.03, 20.0)
    arm.move_cartesian(_lifted(arm.state().base_T_hand, 0.05))
    released = []
    world.on_release.append(released.append)
    pose_at_release = world.object_pose(obj)
    gripper.open()
    arm.move_cartesian(_lifted(arm.state().base_T_hand, 0.05))
    assert released == [obj] and world.held is None and not gripper.state().is_grasped
    np.testing.assert_array_equal(world.object_pose(obj), pose_at_release)


def test_grasp_within_tolerance_holds_the_object_and_tells_listeners(twin, world, gripper):
    obj, hand_T_object = _presented(twin, world)
    grasps = []
    world.on_grasp.append(lambda *args: grasps.append(args))
    result = gripper.grasp(0.032, 15.0, epsilon_inner_m=0.005, epsilon_outer_m=0.001)
    assert result.success and result.width_m == pytest.approx(0.03) and result.force_n == 15.0
    assert result.duration_s == pytest.approx((0.08 - 0.03) / 0.02)
    assert gripper.state() == GripperState(width_m=0.03, is_grasped=True)
    (seen_obj, seen_hand_T_object, seen_force_n), = grasps
    assert seen_obj is obj and seen_force_n == 15.0
    centred = hand_T_object.copy()
    centred[1, 3] = 0.0  # the fingers centre the object along the closing axis
    np.testing.assert_allclose(seen_hand_T_object, centred, atol=1e-12)


def test_grasp_outside_the_width_tolerance_fails_without_holding(twin, world, gripper):
    _presented(twin, world, width_m=0.03)
    grasps = []
    world.on_grasp.append(lambda *args: grasps.append(args))
    result = gripper.grasp(0.05, 20.0)
    assert not result.success and result.width_m == pytest.approx(0.03)  # stopped on the object
    assert world.held is None and grasps == [] and not gripper.state().is_grasped


def test_grasp_with_nothing_between_the_fingers_closes_fully(twin, arm, world, gripper):
    assert gripper.grasp(0.03, 20.0) == GraspResult(False, 0.0, 0.0, 0.08 / 0.02)
    gripper.open()
    obj, _ = _presented(twin, world)
    arm.move_cartesian(_lifted(arm.state().base_T_hand, 0.05))  # the hand moved away from the object
    assert world.object_between_fingers() is None
    assert not gripper.grasp(0.03, 20.0).success and gripper.state().width_m == 0.0


def test_injected_gripper_fault_raises_once(twin, world, gripper):
    _presented(twin, world)
    gripper.inject_fault("finger blocked")
    with pytest.raises(GripperError, match="finger blocked"):
        gripper.grasp(0.03, 20.0)
    assert gripper.state().width_m == gripper.max_width_m
    assert gripper.grasp(0.03, 20.0).success


def test_world_refuses_unknown_and_duplicate_objects(twin, world):
    obj, hand_T_object = _presented(twin, world)
    with pytest.raises(ValueError, match="already in the world"):
        world.present(obj, hand_T_object)
    world.remove(obj)
    with pytest.raises(ValueError, match="present"):
        world.object_pose(obj)
    with pytest.raises(ValueError, match="width_m"):
        twin.WorldObject("too wide", width_m=0.2)


def test_gripper_needs_connect(twin, arm, world):
    with pytest.raises(RobotNotConnectedError, match=r"connect\(\)"):
        twin.TwinGripper(arm, world).grasp(0.03, 10.0)
