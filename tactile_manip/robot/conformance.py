"""A backend-agnostic behaviour check every ``Arm`` / ``Gripper`` pair must pass (docs/design.md, Robot side).

:func:`run_conformance` drives the arm only through the :class:`~tactile_manip.robot.base.Arm` interface
(and a :class:`~tactile_manip.robot.safety.SafeArm` around it), so the kinematic twin and the franky backend
(against franky-sim or, carefully, a real FR3 in a clear workspace) go through the very same moves: connect,
home, a small joint move, 5 cm up and back, and the trials' reorientation about the pad normal. Each check
records a :class:`CheckResult`; a check that raises is a failed check, and the run goes on.

The moves stay within a few centimetres and ``rotation_rad`` of home; speeds are the backend's defaults.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tactile_manip.errors import SafetyLimitError
from tactile_manip.robot.base import N_JOINTS, Arm, Gripper
from tactile_manip.robot.frames import angle_in_plane, hand_T_pad, rotate_pose_about
from tactile_manip.robot.safety import SafeArm, SafetyLimits, check_rigid_transform, pose_error

JOINT_NUDGE_RAD = 0.1  # size of the joint-move check, rad (away from the nearer limit)
LIFT_M = 0.05  # Cartesian translation check along base z, m
GRIPPER_WIDTH_TOLERANCE_M = 0.002  # an opened hand must report within this of max_width_m, m
LIMIT_SLACK_RAD = 1e-6  # measured joints may sit this far past a limit (encoder round-off), rad


@dataclass(frozen=True)
class CheckResult:
    """One behaviour check: its name, whether it passed, and what was seen."""

    name: str
    passed: bool
    detail: str


@dataclass
class ConformanceReport:
    """The checks of one :func:`run_conformance` run, in order."""

    checks: list[CheckResult] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[CheckResult]:
        return [c for c in self.checks if not c.passed]

    def result(self, name: str) -> CheckResult:
        """The check called ``name`` (KeyError if it did not run)."""
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(f"no check named {name!r}; ran: {[c.name for c in self.checks]}")

    def summary(self) -> str:
        lines = [f"{'PASS' if c.passed else 'FAIL'}  {c.name}: {c.detail}" for c in self.checks]
        lines.append(f"{len(self.checks) - len(self.failed)}/{len(self.checks)} checks passed")
        return "\n".join(lines)

    def raise_if_failed(self) -> None:
        """Raise AssertionError listing every failed check (no-op when all passed)."""
        if not self.ok:
            raise AssertionError("conformance failed:\n" + "\n".join(f"{c.name}: {c.detail}" for c in self.failed))


class _Run:
    """State shared by the checks of one run: the backends, tolerances, and q after every move."""

    def __init__(self, arm: Arm, gripper: Gripper | None, position_tolerance_m: float, angle_tolerance_rad: float,
                 rotation_rad: float) -> None:
        self.arm, self.gripper = arm, gripper
        self.tol_m, self.tol_rad, self.rotation_rad = position_tolerance_m, angle_tolerance_rad, rotation_rad
        self.limit_violations: list[str] = []
        self.moves = 0

    def after_move(self, label: str) -> np.ndarray:
        """Record whether the joints are inside the arm's limits after the move ``label``; return q."""
        q = np.asarray(self.arm.state().q_rad, dtype=np.float64)
        self.moves += 1
        lo, hi = np.asarray(self.arm.q_min_rad), np.asarray(self.arm.q_max_rad)
        for j in np.flatnonzero((q < lo - LIMIT_SLACK_RAD) | (q > hi + LIMIT_SLACK_RAD)):
            self.limit_violations.append(f"after {label}: joint {j + 1} = {q[j]:.4f} rad not in "
                                         f"[{lo[j]:.4f}, {hi[j]:.4f}]")
        return q

    def move_to_pose(self, base_T_target: np.ndarray, label: str) -> str:
        """Cartesian move, then assert the reached TCP pose is within tolerance; return the error as text."""
        self.arm.move_cartesian(base_T_target)
        self.after_move(label)
        position_m, angle_rad = pose_error(self.arm.state().base_T_hand, base_T_target)
        assert position_m <= self.tol_m and angle_rad <= self.tol_rad, (
            f"{label}: reached pose is {position_m * 1e3:.3f} mm / {math.degrees(angle_rad):.3f} deg from the "
            f"target (tolerance {self.tol_m * 1e3:.3f} mm / {math.degrees(self.tol_rad):.3f} deg)")
        return f"{label} {position_m * 1e3:.3f} mm / {math.degrees(angle_rad):.3f} deg"

    def move_to_joints(self, q_target: np.ndarray, label: str) -> float:
        """Joint move, then assert every joint is within the angle tolerance; return the worst error, rad."""
        self.arm.move_joints(q_target)
        q = self.after_move(label)
        err = float(np.abs(q - q_target).max())
        assert err <= self.tol_rad, (f"{label}: joints off by up to {math.degrees(err):.3f} deg "
                                     f"(tolerance {math.degrees(self.tol_rad):.3f} deg)")
        return err


def _check_connect(run: _Run) -> str:
    for part in (run.arm, run.gripper):
        if part is not None:
            part.connect()
            part.connect()  # idempotent
            assert part.is_connected, f"{type(part).__name__}.is_connected is False after connect()"
    return "connect() twice; is_connected"


def _check_home(run: _Run) -> str:
    run.arm.home()
    run.after_move("home")
    err = float(np.abs(run.arm.state().q_rad - run.arm.home_q_rad).max())
    assert err <= run.tol_rad, f"home: joints off by {math.degrees(err):.3f} deg"
    return f"at home within {math.degrees(err):.4f} deg"


def _check_state_sane(run: _Run) -> str:
    s = run.arm.state()
    q = np.asarray(s.q_rad, dtype=np.float64)
    assert q.shape == (N_JOINTS,) and np.isfinite(q).all(), f"q_rad must be 7 finite values, got {q!r}"
    lo, hi = np.asarray(run.arm.q_min_rad), np.asarray(run.arm.q_max_rad)
    assert (q >= lo - LIMIT_SLACK_RAD).all() and (q <= hi + LIMIT_SLACK_RAD).all(), f"q_rad {q} outside the limits"
    check_rigid_transform("state().base_T_hand", s.base_T_hand, tolerance=1e-5)
    assert not s.faulted, f"arm reports a fault after home: {s.fault!r}"
    return "q inside limits, base_T_hand rigid, not faulted"


def _check_joint_move(run: _Run) -> str:
    home = np.asarray(run.arm.home_q_rad, dtype=np.float64)
    lo, hi = np.asarray(run.arm.q_min_rad), np.asarray(run.arm.q_max_rad)
    direction = np.where(hi - home > home - lo, 1.0, -1.0)  # towards the farther limit
    target = home + JOINT_NUDGE_RAD * direction
    e1 = run.move_to_joints(target, "joint move")
    e2 = run.move_to_joints(home, "joint move back")
    return f"{JOINT_NUDGE_RAD} rad on every joint and back, worst {math.degrees(max(e1, e2)):.4f} deg"


def _check_cartesian_translation(run: _Run) -> str:
    start = run.arm.state().base_T_hand
    up = start.copy()
    up[2, 3] += LIFT_M
    return "; ".join([run.move_to_pose(up, f"+{LIFT_M} m along base z"), run.move_to_pose(start, "back")])


def _check_reorientation(run: _Run) -> str:
    start = run.arm.state().base_T_hand
    base_T_pad = start @ hand_T_pad()
    normal, centre = base_T_pad[:3, 2], base_T_pad[:3, 3]
    turned = rotate_pose_about(start, normal, centre, run.rotation_rad)
    details = [run.move_to_pose(turned, f"+{math.degrees(run.rotation_rad):.1f} deg about the pad normal")]
    reached = run.arm.state().base_T_hand
    in_plane_rad = angle_in_plane(reached[:3, 0], base_T_pad)  # hand x seen in the original pad plane
    assert abs(in_plane_rad - run.rotation_rad) <= run.tol_rad, (
        f"hand x turned {math.degrees(in_plane_rad):.3f} deg in the pad plane, expected "
        f"{math.degrees(run.rotation_rad):.3f} deg")
    back = rotate_pose_about(turned, normal, centre, -run.rotation_rad)
    details.append(run.move_to_pose(back, "back"))
    return "; ".join(details)


def _check_joint_limits(run: _Run) -> str:
    assert not run.limit_violations, "; ".join(run.limit_violations)
    return f"inside the limits after all {run.moves} moves"


def _check_safety_refuses(run: _Run) -> str:
    limits = SafetyLimits()
    safe = SafeArm(run.arm, limits)
    before = run.arm.state().base_T_hand
    outside = before.copy()
    outside[0, 3] = limits.workspace_max_m[0] + 0.1
    try:
        safe.move_cartesian(outside)
    except SafetyLimitError as e:
        message = str(e)
    else:
        raise AssertionError(f"SafeArm accepted a target at x = {outside[0, 3]:.3f} m outside the workspace")
    position_m, angle_rad = pose_error(before, run.arm.state().base_T_hand)
    assert position_m <= run.tol_m and angle_rad <= run.tol_rad, f"the arm moved {position_m * 1e3:.3f} mm"
    return f"refused: {message}"


def _check_gripper(run: _Run) -> str:
    g = run.gripper
    if g is None:
        return "skipped: no gripper given"
    g.open()
    s = g.state()
    assert abs(s.width_m - g.max_width_m) <= GRIPPER_WIDTH_TOLERANCE_M, (
        f"open(): width {s.width_m:.4f} m, expected {g.max_width_m:.4f} m")
    assert not s.is_grasped, "open(): state says an object is grasped"
    return f"open: width {s.width_m:.4f} m, not grasped"


def _check_recover(run: _Run) -> str:
    before = run.arm.state().base_T_hand
    run.arm.recover()
    s = run.arm.state()
    assert not s.faulted, f"faulted after recover(): {s.fault!r}"
    position_m, angle_rad = pose_error(before, s.base_T_hand)
    assert position_m <= run.tol_m and angle_rad <= run.tol_rad, f"recover() moved the arm {position_m * 1e3:.3f} mm"
    _check_home(run)
    return "recover() with no fault: not faulted, arm unmoved, home still works"


def _check_disconnect(run: _Run) -> str:
    for part in (run.arm, run.gripper):
        if part is not None:
            part.disconnect()
            part.disconnect()  # idempotent
            assert not part.is_connected, f"{type(part).__name__}.is_connected is True after disconnect()"
    return "disconnect() twice; not connected"


CHECKS: tuple[tuple[str, Callable[[_Run], str]], ...] = (
    ("connect", _check_connect),
    ("home", _check_home),
    ("state_sane", _check_state_sane),
    ("joint_move", _check_joint_move),
    ("cartesian_translation", _check_cartesian_translation),
    ("reorientation", _check_reorientation),
    ("joints_within_limits", _check_joint_limits),
    ("safety_refuses", _check_safety_refuses),
    ("gripper", _check_gripper),
    ("recover", _check_recover),
    ("disconnect", _check_disconnect),
)


def run_conformance(arm: Arm, gripper: Gripper | None, *, position_tolerance_m: float = 1e-3,
                    angle_tolerance_rad: float = math.radians(0.5),
                    rotation_rad: float = math.radians(30)) -> ConformanceReport:
    """Drive ``arm`` (and ``gripper``) through :data:`CHECKS` and report each; never raises for a failed check.

    Args:
        arm: a disconnected or connected arm, at or near a safe start (the first move is ``home()``).
        gripper: the hand, or None to skip the gripper check.
        position_tolerance_m: allowed TCP position error of a reached target, m.
        angle_tolerance_rad: allowed TCP orientation error and joint error of a reached target, rad.
        rotation_rad: reorientation angle about the pad normal, rad.

    If ``connect`` fails, the other checks are not run. The arm is disconnected at the end.
    """
    run = _Run(arm, gripper, position_tolerance_m, angle_tolerance_rad, rotation_rad)
    report = ConformanceReport()
    for name, check in CHECKS:
        try:
            report.checks.append(CheckResult(name, True, check(run)))
        except Exception as e:  # noqa: BLE001 - a failing backend is a failed check, reported, not raised
            detail = str(e) if isinstance(e, AssertionError) else f"{type(e).__name__}: {e}"
            report.checks.append(CheckResult(name, False, detail))
            if name == "connect":
                break
    return report
