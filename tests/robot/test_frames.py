"""Rigid-transform helpers and the pad frame on the Franka Hand (numpy only, no robot needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.robot.frames import (
    HAND_R_PAD,
    angle_in_plane,
    hand_T_pad,
    rotate_pose_about,
    rotation_about,
    transform,
)


def _random_axes(n: int) -> np.ndarray:
    return np.random.default_rng(0).normal(size=(n, 3))


@pytest.mark.parametrize("axis", _random_axes(5))
def test_rotation_about_is_a_proper_rotation_fixing_its_axis(axis):
    r = rotation_about(axis, 0.7)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r @ axis, axis, atol=1e-12)
    assert math.acos((np.trace(r) - 1) / 2) == pytest.approx(0.7)


@pytest.mark.parametrize("axis", _random_axes(3))
def test_rotation_about_composes_and_inverts(axis):
    np.testing.assert_allclose(rotation_about(axis, 0.3) @ rotation_about(axis, 0.5), rotation_about(axis, 0.8),
                               atol=1e-12)
    np.testing.assert_allclose(rotation_about(axis, -0.4), rotation_about(axis, 0.4).T, atol=1e-12)


def test_rotation_about_z_turns_x_into_y():
    np.testing.assert_allclose(rotation_about([0, 0, 2.0], math.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_rotation_about_a_zero_axis_is_refused():
    with pytest.raises(ValueError, match="non-zero"):
        rotation_about([0, 0, 0], 1.0)


def test_rotate_pose_about_keeps_the_point_on_the_axis_fixed():
    rng = np.random.default_rng(1)
    pose = transform(rotation_about(rng.normal(size=3), 1.1), rng.normal(size=3))
    point, axis = rng.normal(size=3), rng.normal(size=3)
    turned = rotate_pose_about(pose, axis, point, 0.9)
    point_in_x = np.linalg.inv(pose) @ np.append(point, 1.0)  # the body point that sits on the axis
    np.testing.assert_allclose((turned @ point_in_x)[:3], point, atol=1e-12)
    other_in_x = np.array([0.1, -0.2, 0.3, 1.0])  # any body point keeps its distance to the axis point
    assert np.linalg.norm((turned @ other_in_x)[:3] - point) == pytest.approx(
        np.linalg.norm((pose @ other_in_x)[:3] - point))
    np.testing.assert_allclose(rotate_pose_about(turned, axis, point, -0.9), pose, atol=1e-12)


def test_hand_T_pad_axes():
    t = hand_T_pad((0.0, 0.02, 0.01))
    x_pad, y_pad, z_pad = t[:3, 0], t[:3, 1], t[:3, 2]
    np.testing.assert_allclose(z_pad, [0, -1, 0])  # outward normal of the +y finger's pad: -hand y
    np.testing.assert_allclose(x_pad, [1, 0, 0])  # pad x = hand x
    np.testing.assert_allclose(y_pad, [0, 0, 1])  # pad y = hand z
    np.testing.assert_allclose(np.cross(x_pad, y_pad), z_pad)  # right-handed
    assert np.linalg.det(HAND_R_PAD) == pytest.approx(1.0)
    np.testing.assert_allclose(t[:3, 3], [0.0, 0.02, 0.01])


@pytest.mark.parametrize("angle_rad", [-3.0, -1.2, 0.0, 0.4, 1.5707, 3.1])
def test_angle_in_plane_recovers_the_angle(angle_rad):
    frame = transform(rotation_about([1, 2, 3], 0.5), [0.1, 0.2, 0.3])
    direction = frame[:3, :3] @ [math.cos(angle_rad), math.sin(angle_rad), 0.7]  # z part is ignored
    assert angle_in_plane(direction, frame) == pytest.approx(angle_rad)


def test_angle_in_plane_of_the_normal_is_undefined():
    with pytest.raises(ValueError, match="z axis"):
        angle_in_plane(np.array([0.0, 0.0, 1.0]), np.eye(4))


def test_rotation_about_the_pad_normal_turns_the_in_plane_angle():
    """The correction of the trials: turning the hand about the pad normal by a turns hand x by +a in the pad."""
    base_T_hand = transform(rotation_about([1, 0, 0], math.pi), [0.45, 0.0, 0.4])  # hand pointing down
    base_T_pad = base_T_hand @ hand_T_pad()
    turned = rotate_pose_about(base_T_hand, base_T_pad[:3, 2], base_T_pad[:3, 3], 0.25)
    assert angle_in_plane(turned[:3, 0], base_T_pad) == pytest.approx(0.25)
