"""The franky backend without a robot or a server: a fake ``franky`` module stands in for franky-control.

Covers the error mapping (franky's exceptions -> ArmFault / RobotError / GripperError, with franky's text),
the frames (base_T_hand is the Franka Hand TCP whatever end effector Desk has configured), the config, and the
clear error when franky is missing. The Affine <-> 4x4 round trip uses the real franky (skipped without it).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import types

import numpy as np
import pytest

from tactile_manip.errors import ArmFault, GripperError, RobotError, SafetyLimitError
from tactile_manip.robot.franky_arm import (FrankyArm, FrankyConfig, FrankyGripper, FrankyMissingError,
                                            affine_from_matrix, import_franky, matrix_from_affine)
from tactile_manip.errors import RobotNotConnectedError

HOST = "172.16.0.2"
HAND_TCP = np.array([[math.cos(-math.pi / 4), -math.sin(-math.pi / 4), 0.0, 0.0],
                     [math.sin(-math.pi / 4), math.cos(-math.pi / 4), 0.0, 0.0],
                     [0.0, 0.0, 1.0, 0.1034],
                     [0.0, 0.0, 0.0, 1.0]])


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    x, y, z, w = q / np.linalg.norm(q)
    t = np.eye(4)
    t[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    t[:3, 3] = rng.uniform(-0.8, 0.8, 3)
    return t


# --- a fake franky ------------------------------------------------------------------------------------------

def _fake_franky() -> types.ModuleType:
    m = types.ModuleType("franky")

    class Exception_(Exception):
        pass

    for name in ("ControlException", "CommandException", "NetworkException", "InvalidOperationException",
                 "RealtimeException"):
        setattr(m, name, type(name, (Exception_,), {}))
    m.Exception = Exception_
    m.GripperException = type("GripperException", (Exception,), {})  # not a franky.Exception, as in franky 2.0
    m.RealtimeConfig = types.SimpleNamespace(Enforce="enforce", Ignore="ignore")
    m.ReferenceType = types.SimpleNamespace(Absolute="absolute", Relative="relative")
    m.RobotMode = types.SimpleNamespace(Idle="idle", Move="move", Reflex="reflex", UserStopped="user_stopped")

    class Affine:
        def __init__(self, matrix=None):
            self.matrix = np.eye(4) if matrix is None else np.array(matrix, dtype=float)

    class JointMotion:
        def __init__(self, target, relative_dynamics_factor=1.0):
            self.target, self.relative_dynamics_factor = np.asarray(target), relative_dynamics_factor

    class CartesianMotion:
        def __init__(self, target, reference_type, relative_dynamics_factor=1.0):
            self.target, self.reference_type = target, reference_type
            self.relative_dynamics_factor = relative_dynamics_factor

    class Robot:
        connect_error: Exception | None = None
        instances: list = []

        def __init__(self, host, relative_dynamics_factor=1.0, realtime_config="enforce"):
            if Robot.connect_error is not None:
                raise Robot.connect_error
            self.host, self.realtime_config = host, realtime_config
            self.relative_dynamics_factor = relative_dynamics_factor
            self.q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4])
            self.O_T_EE, self.F_T_EE = np.eye(4), HAND_TCP.copy()
            self.robot_mode = "idle"
            self.moves, self.move_error, self.recover_result, self.recover_calls = [], None, True, 0
            self.collision = None
            self.trail, self.state_reads = [], 0
            Robot.instances.append(self)

        def set_collision_behavior(self, torque, force):
            self.collision = (torque, force)

        @property
        def state(self):
            self.state_reads += 1
            lag_rad, dq_rad_s = self.trail.pop(0) if self.trail else (0.0, 0.0)  # joint controller lag after a move
            return types.SimpleNamespace(q=self.q - lag_rad, q_d=self.q.copy(), dq=np.full(7, dq_rad_s),
                                         O_T_EE=Affine(self.O_T_EE), F_T_EE=Affine(self.F_T_EE),
                                         robot_mode=self.robot_mode, current_errors=[])

        def move(self, motion):
            self.moves.append(motion)
            if self.move_error is not None:
                raise self.move_error

        def recover_from_errors(self):
            self.recover_calls += 1
            return self.recover_result

    class Gripper:
        connect_error: Exception | None = None
        instances: list = []

        def __init__(self, host):
            if Gripper.connect_error is not None:
                raise Gripper.connect_error
            self.host, self.width, self.max_width, self.is_grasped = host, 0.04, 0.08, False
            self.error, self.result, self.calls = None, True, []
            Gripper.instances.append(self)

        @property
        def state(self):
            return types.SimpleNamespace(width=self.width, is_grasped=self.is_grasped, max_width=self.max_width)

        def _do(self, name, *args, **kwargs):
            self.calls.append((name, args, kwargs))
            if self.error is not None:
                raise self.error
            return self.result

        def open(self, speed):
            return self._do("open", speed)

        def move(self, width, speed):
            return self._do("move", width, speed)

        def grasp(self, width, speed, force, epsilon_inner=0.005, epsilon_outer=0.005):
            return self._do("grasp", width, speed, force, epsilon_inner=epsilon_inner, epsilon_outer=epsilon_outer)

        def homing(self):
            return self._do("homing")

    m.Affine, m.JointMotion, m.CartesianMotion = Affine, JointMotion, CartesianMotion
    m.Robot, m.Gripper = Robot, Gripper
    return m


@pytest.fixture
def fake_franky(monkeypatch):
    module = _fake_franky()
    monkeypatch.setitem(sys.modules, "franky", module)
    return module


@pytest.fixture
def franky_arm(fake_franky):
    arm = FrankyArm(FrankyConfig(host=HOST))
    arm.connect()
    return arm


@pytest.fixture
def franky_gripper(fake_franky):
    gripper = FrankyGripper(FrankyConfig(host=HOST))
    gripper.connect()
    return gripper


def _robot(arm: FrankyArm):
    return arm._robot  # the fake franky.Robot behind the arm


# --- Affine <-> 4x4 with the real franky --------------------------------------------------------------------

def test_affine_round_trip_and_conventions_match_franky():
    franky = pytest.importorskip("franky", reason='franky-control is not installed: '
                                 'pip install -e ".[franky]"')
    rng = np.random.default_rng(0)
    for _ in range(20):
        a_T_b, b_T_c = _random_pose(rng), _random_pose(rng)
        a = affine_from_matrix(franky, a_T_b)
        np.testing.assert_allclose(matrix_from_affine(a), a_T_b, atol=1e-12)
        np.testing.assert_allclose(np.asarray(a.translation).ravel(), a_T_b[:3, 3], atol=1e-12)
        # franky's product is the matrix product, and its inverse the matrix inverse
        np.testing.assert_allclose(matrix_from_affine(a * affine_from_matrix(franky, b_T_c)), a_T_b @ b_T_c, atol=1e-12)
        np.testing.assert_allclose(matrix_from_affine(a.inverse), np.linalg.inv(a_T_b), atol=1e-12)
    # franky's quaternion is (x, y, z, w): 90 deg about z
    rz = np.eye(4)
    rz[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    q = np.asarray(affine_from_matrix(franky, rz).quaternion).ravel()
    np.testing.assert_allclose(q * np.sign(q[3]), [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)


def test_affine_from_matrix_refuses_a_non_rigid_matrix(fake_franky):
    scaled = np.diag([2.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="not orthonormal"):
        affine_from_matrix(fake_franky, scaled)


# --- missing franky -----------------------------------------------------------------------------------------

def test_missing_franky_is_a_clear_robot_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "franky", None)  # `import franky` now raises ImportError
    with pytest.raises(FrankyMissingError, match=r'pip install -e "\.\[franky\]"') as info:
        import_franky()
    assert isinstance(info.value, RobotError) and isinstance(info.value, ImportError)
    arm = FrankyArm(FrankyConfig(host=HOST))  # constructing does no I/O and needs no franky
    with pytest.raises(RobotError, match="franky-control"):
        arm.connect()
    assert not arm.is_connected
    with pytest.raises(RobotError, match="franky-control"):
        FrankyGripper(FrankyConfig(host=HOST)).connect()


def test_importing_the_backend_does_not_import_franky():
    code = ("import sys, json, tactile_manip.robot.franky_arm; "
            "print(json.dumps('franky' in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) is False


# --- connection and configuration ---------------------------------------------------------------------------

def test_connect_passes_host_dynamics_realtime_and_collision_thresholds(fake_franky):
    cfg = FrankyConfig(host=HOST, relative_dynamics_factor=0.1, enforce_realtime=False,
                       collision_torque_threshold_nm=(25.0,) * 7, collision_force_threshold_n=40.0)
    arm = FrankyArm(cfg)
    assert not arm.is_connected and not fake_franky.Robot.instances  # the constructor does no I/O
    arm.connect()
    arm.connect()  # idempotent
    assert len(fake_franky.Robot.instances) == 1
    robot = _robot(arm)
    assert (robot.host, robot.relative_dynamics_factor, robot.realtime_config) == (HOST, 0.1, "ignore")
    assert robot.collision == ([25.0] * 7, 40.0)
    arm.disconnect()
    arm.disconnect()
    assert not arm.is_connected


def test_connect_failure_names_the_host_and_what_to_check(fake_franky):
    fake_franky.Robot.connect_error = fake_franky.NetworkException("libfranka: Connection to FCI refused.")
    arm = FrankyArm(FrankyConfig(host=HOST))
    with pytest.raises(RobotError, match=r"172\.16\.0\.2.*Connection to FCI refused.*FCI activated in Desk") as info:
        arm.connect()
    assert isinstance(info.value.__cause__, fake_franky.NetworkException)
    assert not arm.is_connected


def test_not_connected_raises(fake_franky):
    arm, gripper = FrankyArm(FrankyConfig(host=HOST)), FrankyGripper(FrankyConfig(host=HOST))
    for call in (arm.state, arm.recover, lambda: arm.move_joints(arm.home_q_rad), gripper.state, gripper.open):
        with pytest.raises(RobotNotConnectedError, match="connect"):
            call()


@pytest.mark.parametrize("kwargs, field", [
    ({"host": ""}, "host"),
    ({"host": "172.16.0.2 "}, "host"),
    ({"host": HOST, "relative_dynamics_factor": 0.0}, "relative_dynamics_factor"),
    ({"host": HOST, "relative_dynamics_factor": 1.5}, "relative_dynamics_factor"),
    ({"host": HOST, "collision_torque_threshold_nm": (20.0, 20.0)}, "collision_torque_threshold_nm"),
    ({"host": HOST, "collision_force_threshold_n": -1.0}, "collision_force_threshold_n"),
    ({"host": HOST, "home_q_rad": (0.0, 0.0, 0.0, 0.0, 0.0, 1.9, 0.0)}, "home_q_rad"),
    ({"host": HOST, "settle_timeout_s": -1.0}, "settle_timeout_s"),
    ({"host": HOST, "settle_velocity_rad_s": 0.0}, "settle_velocity_rad_s"),
    ({"host": HOST, "collision_torque_threshold_nm": True}, "collision_torque_threshold_nm"),
])
def test_config_refuses_bad_values_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        FrankyConfig(**kwargs)


def test_config_has_no_default_host_and_low_dynamics():
    with pytest.raises(TypeError):
        FrankyConfig()  # type: ignore[call-arg]
    assert FrankyConfig(host=HOST).relative_dynamics_factor <= 0.1


# --- frames and commands ------------------------------------------------------------------------------------

def test_base_T_hand_is_the_hand_tcp_whatever_ee_desk_configured(franky_arm):
    robot = _robot(franky_arm)
    rng = np.random.default_rng(0)
    base_T_flange = _random_pose(rng)
    for flange_T_ee in (HAND_TCP, np.eye(4), _random_pose(rng)):  # stock hand, no EE, some other EE
        robot.F_T_EE, robot.O_T_EE = flange_T_ee, base_T_flange @ flange_T_ee
        base_T_hand = franky_arm.state().base_T_hand
        np.testing.assert_allclose(base_T_hand, base_T_flange @ HAND_TCP, atol=1e-12)
        # a Cartesian target is sent to franky in the configured EE frame: here, the EE where it is now
        franky_arm.move_cartesian(base_T_hand, speed_factor=0.5)
        motion = robot.moves[-1]
        np.testing.assert_allclose(motion.target.matrix, robot.O_T_EE, atol=1e-12)
        assert motion.reference_type == "absolute" and motion.relative_dynamics_factor == 0.5


def test_joint_move_sends_a_joint_motion_and_refuses_targets_outside_the_fr3_limits(franky_arm):
    robot = _robot(franky_arm)
    target = franky_arm.home_q_rad + 0.1
    franky_arm.move_joints(target)
    np.testing.assert_array_equal(robot.moves[-1].target, target)
    assert robot.moves[-1].relative_dynamics_factor == 1.0  # times the config's global factor, in franky
    target[5] = franky_arm.q_min_rad[5] - 0.01
    with pytest.raises(SafetyLimitError, match="joint 6"):
        franky_arm.move_joints(target)
    with pytest.raises(ValueError, match="speed_factor"):
        franky_arm.move_joints(franky_arm.home_q_rad, speed_factor=1.5)
    assert len(robot.moves) == 1


def test_a_move_returns_once_the_joints_reach_the_target_or_come_to_rest(franky_arm):
    robot = _robot(franky_arm)
    robot.trail = [(0.02, 0.2), (0.005, 0.05), (1e-3, 0.01), (1e-4, 1e-3), (0.0, 0.0)]  # trailing, converging
    franky_arm.home()
    assert robot.state_reads == 4 and len(robot.trail) == 1
    robot.trail, robot.state_reads = [(0.02, 0.2), (0.01, 1e-4), (0.01, 0.0)], 0  # held 10 mrad off, at rest
    franky_arm.home()
    assert robot.state_reads == 2


# --- arm error mapping --------------------------------------------------------------------------------------

REFLEX_TEXT = 'libfranka: Move command aborted: motion aborted by reflex! ["cartesian_reflex"]'


@pytest.mark.parametrize("exc_name, text, kind", [
    ("ControlException", REFLEX_TEXT, "reflex"),
    ("ControlException", 'motion aborted: ["communication_constraints_violation"]', "communication"),
    ("ControlException", 'motion aborted: ["joint_motion_generator_velocity_discontinuity"]', "control"),
    ("NetworkException", "libfranka: UDP receive: Timeout", "communication"),
])
def test_a_fault_mid_motion_is_an_arm_fault_with_frankys_text(fake_franky, franky_arm, exc_name, text, kind):
    robot = _robot(franky_arm)
    robot.move_error = getattr(fake_franky, exc_name)(text)
    with pytest.raises(ArmFault) as info:
        franky_arm.move_joints(franky_arm.home_q_rad)
    assert info.value.kind == kind and text in str(info.value)
    assert isinstance(info.value.__cause__, getattr(fake_franky, exc_name))
    state = franky_arm.state()
    assert state.faulted and text in state.fault


def test_a_faulted_arm_refuses_to_move_until_recover(fake_franky, franky_arm):
    robot = _robot(franky_arm)
    robot.move_error = fake_franky.ControlException(REFLEX_TEXT)
    with pytest.raises(ArmFault):
        franky_arm.move_cartesian(franky_arm.state().base_T_hand)
    robot.move_error = None
    with pytest.raises(ArmFault, match="recover") as info:
        franky_arm.move_joints(franky_arm.home_q_rad)
    assert info.value.kind == "faulted" and len(robot.moves) == 1  # franky was not asked to move
    robot.recover_result = False
    with pytest.raises(RobotError, match="recovery .* failed"):
        franky_arm.recover()
    assert franky_arm.state().faulted
    robot.recover_result = True
    franky_arm.recover()
    assert robot.recover_calls == 2 and not franky_arm.state().faulted
    franky_arm.home()
    assert len(robot.moves) == 2


def test_reflex_mode_reported_by_the_robot_is_a_fault(franky_arm):
    _robot(franky_arm).robot_mode = "reflex"
    state = franky_arm.state()
    assert state.faulted and "reflex" in state.fault


@pytest.mark.parametrize("exc_name, text, hint", [
    ("CommandException", "libfranka: Move command rejected: command not possible in the current mode", "recover"),
    ("InvalidOperationException", "libfranka: attempted to start multiple motions!", "FCI"),
    ("RealtimeException", "libfranka: unable to set realtime scheduling", "enforce_realtime"),
])
def test_a_refused_command_is_a_robot_error_not_a_fault(fake_franky, franky_arm, exc_name, text, hint):
    _robot(franky_arm).move_error = getattr(fake_franky, exc_name)(text)
    with pytest.raises(RobotError, match=hint) as info:
        franky_arm.move_joints(franky_arm.home_q_rad)
    assert not isinstance(info.value, ArmFault) and text in str(info.value)
    assert not franky_arm.state().faulted


def test_a_planner_failure_is_a_fault_naming_it(franky_arm):
    """franky's motion planner raises a plain RuntimeError (seen on franky-sim for a zero-length Cartesian move)."""
    _robot(franky_arm).move_error = RuntimeError("Motion planner failed with error code -111")
    with pytest.raises(ArmFault, match="Motion planner failed with error code -111") as info:
        franky_arm.move_joints(franky_arm.home_q_rad)
    assert "recover()" in str(info.value) and franky_arm.state().faulted


# --- gripper ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("exc_name", ["GripperException", "CommandException", "NetworkException"])
def test_gripper_failures_are_gripper_errors_with_frankys_text(fake_franky, franky_gripper, exc_name):
    fake = fake_franky.Gripper.instances[-1]
    fake.error = getattr(fake_franky, exc_name)("libfranka gripper: Command failed!")
    for call in (lambda: franky_gripper.grasp(0.03, 20.0), franky_gripper.open, lambda: franky_gripper.open(0.05)):
        with pytest.raises(GripperError, match="Command failed!") as info:
            call()
        assert isinstance(info.value.__cause__, getattr(fake_franky, exc_name))


def test_gripper_connect_failure_is_a_gripper_error(fake_franky):
    fake_franky.Gripper.connect_error = fake_franky.NetworkException("libfranka gripper: connection refused")
    gripper = FrankyGripper(FrankyConfig(host=HOST))
    with pytest.raises(GripperError, match="connection refused"):
        gripper.connect()
    assert not gripper.is_connected


def test_a_missed_grasp_is_a_value(fake_franky, franky_gripper):
    fake = fake_franky.Gripper.instances[-1]
    fake.result, fake.width = False, 0.0
    result = franky_gripper.grasp(0.03, 20.0, epsilon_inner_m=0.004, epsilon_outer_m=0.006)
    assert not result.success and result.force_n == 0.0 and result.width_m == 0.0 and result.duration_s >= 0.0
    assert fake.calls[-1] == ("grasp", (0.03, 0.02, 20.0), {"epsilon_inner": 0.004, "epsilon_outer": 0.006})
    fake.result, fake.width, fake.is_grasped = True, 0.031, True
    result = franky_gripper.grasp(0.03, 20.0)
    assert result.success and result.force_n == 20.0 and result.width_m == 0.031
    assert franky_gripper.state().is_grasped


def test_gripper_open_and_refusals(fake_franky, franky_gripper):
    fake = fake_franky.Gripper.instances[-1]
    franky_gripper.open()
    franky_gripper.open(0.05, speed_m_s=0.1)
    assert [c[0] for c in fake.calls] == ["open", "move"] and fake.calls[-1][1] == (0.05, 0.1)
    assert franky_gripper.max_width_m == 0.08
    fake.result = False
    with pytest.raises(GripperError, match="did not reach 0.0500 m"):
        franky_gripper.open(0.05)
    with pytest.raises(ValueError, match="width_m"):
        franky_gripper.open(0.2)
    with pytest.raises(ValueError, match="force_n"):
        franky_gripper.grasp(0.03, 500.0)
