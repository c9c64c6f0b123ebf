"""SafeArm refuses out-of-limit targets without moving and passes in-limit ones through."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.errors import SafetyLimitError
from tactile_manip.robot.base import Arm, ArmState
from tactile_manip.robot.frames import rotation_about, transform
from tactile_manip.robot.safety import SafeArm, SafetyLimits, pose_error

Q_MIN = np.array([-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159])
Q_MAX = np.array([2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159])
HOME = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4])
HAND_DOWN = np.diag([1.0, -1.0, -1.0])


class RecordingArm(Arm):
    """An arm that records every call and 'moves' instantly; enough to see what SafeArm lets through."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.q = HOME.copy()
        self.pose = transform(HAND_DOWN, [0.45, 0.0, 0.4])
        self.connected = False
        self.extra = "backend extra"

    def connect(self) -> None:
        self.calls.append(("connect",))
        self.connected = True

    def disconnect(self) -> None:
        self.calls.append(("disconnect",))
        self.connected = False

    @property
    def is_connected(self) -> bool:
        return self.connected

    q_min_rad = property(lambda self: Q_MIN.copy())
    q_max_rad = property(lambda self: Q_MAX.copy())
    dq_max_rad_s = property(lambda self: np.full(7, 2.62))
    home_q_rad = property(lambda self: HOME.copy())

    def state(self) -> ArmState:
        return ArmState(self.q.copy(), self.pose.copy())

    def move_joints(self, q_rad, *, speed_factor=None) -> None:
        self.calls.append(("move_joints", np.array(q_rad), speed_factor))
        self.q = np.array(q_rad)

    def move_cartesian(self, base_T_hand, *, speed_factor=None) -> None:
        self.calls.append(("move_cartesian", np.array(base_T_hand), speed_factor))
        self.pose = np.array(base_T_hand)

    def recover(self) -> None:
        self.calls.append(("recover",))


@pytest.fixture
def inner() -> RecordingArm:
    return RecordingArm()


@pytest.fixture
def safe(inner) -> SafeArm:
    return SafeArm(inner)


def _moves(arm: RecordingArm) -> list[tuple]:
    return [c for c in arm.calls if c[0].startswith("move")]


def _at(position_m, rotation=HAND_DOWN) -> np.ndarray:
    return transform(rotation, np.asarray(position_m, dtype=float))


@pytest.mark.parametrize("joint, value", [(0, Q_MAX[0] - 0.01), (3, Q_MAX[3] - 0.02), (5, Q_MIN[5] + 0.03),
                                          (6, Q_MIN[6] - 1.0)])
def test_joint_target_within_the_margin_of_a_limit_is_refused(safe, inner, joint, value):
    q = HOME.copy()
    q[joint] = value
    with pytest.raises(SafetyLimitError, match=rf"joint {joint + 1} target .* joint_margin_rad 0.05"):
        safe.move_joints(q)
    assert _moves(inner) == []


@pytest.mark.parametrize("axis, position_m", [("x", (0.85, 0.0, 0.4)), ("x", (0.1, 0.0, 0.4)),
                                              ("y", (0.45, -0.6, 0.4)), ("z", (0.45, 0.0, 0.02)),
                                              ("z", (0.45, 0.0, 0.95))])
def test_tcp_target_outside_the_workspace_is_refused(safe, inner, axis, position_m):
    with pytest.raises(SafetyLimitError, match=rf"{axis} = .* outside the workspace"):
        safe.move_cartesian(_at(position_m))
    assert _moves(inner) == []


def test_speed_factor_above_the_limit_is_refused(safe, inner):
    with pytest.raises(SafetyLimitError, match="max_speed_factor 0.3"):
        safe.move_joints(HOME, speed_factor=0.5)
    with pytest.raises(SafetyLimitError, match="max_speed_factor"):
        safe.move_cartesian(_at((0.45, 0.0, 0.35)), speed_factor=0.31)
    assert _moves(inner) == []


def test_long_cartesian_move_is_refused(safe, inner):
    inner.pose = _at((0.3, -0.4, 0.4))
    with pytest.raises(SafetyLimitError, match="max_cartesian_step_m 0.5"):
        safe.move_cartesian(_at((0.7, 0.4, 0.4)))
    assert _moves(inner) == []


def test_large_turn_is_refused(inner):
    safe = SafeArm(inner, SafetyLimits(max_rotation_rad=math.pi / 2))
    turned = _at((0.45, 0.0, 0.4), rotation_about([0, 1, 0], math.radians(100)) @ HAND_DOWN)
    with pytest.raises(SafetyLimitError, match="turning 100.00 deg exceeds max_rotation_rad"):
        safe.move_cartesian(turned)
    assert _moves(inner) == []


def test_in_limit_moves_pass_through_unchanged(safe, inner):
    q = HOME + 0.1
    safe.move_joints(q, speed_factor=0.2)
    goal = _at((0.5, 0.1, 0.3), rotation_about([0, 1, 0], 0.5) @ HAND_DOWN)
    safe.move_cartesian(goal)
    safe.home()
    (_, q_sent, sf), (_, goal_sent, sf_default), (_, home_sent, _) = _moves(inner)
    np.testing.assert_array_equal(q_sent, q)
    assert sf == 0.2 and sf_default is None
    np.testing.assert_array_equal(goal_sent, goal)
    np.testing.assert_array_equal(home_sent, HOME)


def test_everything_else_is_delegated(safe, inner):
    with safe:
        assert safe.is_connected
        safe.recover()
        assert safe.state().q_rad.tolist() == HOME.tolist()
        np.testing.assert_array_equal(safe.q_min_rad, Q_MIN)
        assert safe.extra == "backend extra" and safe.arm is inner
    assert [c[0] for c in inner.calls] == ["connect", "recover", "disconnect"]
    with pytest.raises(AttributeError):
        safe.no_such_attribute  # noqa: B018


def test_malformed_target_is_refused_before_the_arm(safe, inner):
    skewed = _at((0.45, 0.0, 0.4))
    skewed[0, 1] = 0.3
    with pytest.raises(ValueError, match="orthonormal"):
        safe.move_cartesian(skewed)
    assert _moves(inner) == []


@pytest.mark.parametrize("field, value", [("joint_margin_rad", -0.1), ("workspace_min_m", (0.9, -0.5, 0.05)),
                                          ("max_speed_factor", 1.5), ("max_cartesian_step_m", 0.0),
                                          ("max_rotation_rad", 4.0), ("workspace_max_m", (0.8, 0.5))])
def test_limits_are_validated_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        SafetyLimits(**{field: value})


def test_safe_twin_is_untouched_by_a_refused_target(twin, arm):
    safe = SafeArm(arm)
    before = arm.state().q_rad
    goal = arm.state().base_T_hand.copy()
    goal[1, 3] = 0.7
    with pytest.raises(SafetyLimitError, match="y = 0.7000 m"):
        safe.move_cartesian(goal)
    np.testing.assert_array_equal(arm.state().q_rad, before)
    goal[1, 3] = 0.05
    safe.move_cartesian(goal)
    assert pose_error(arm.state().base_T_hand, goal)[0] < 1e-4
    assert safe.last_move_duration_s > 0  # twin extras reach through the wrapper
