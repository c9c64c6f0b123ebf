"""Rigid transforms and the tactile pad's frame on the Franka Hand (numpy only).

The fingers close along the hand y axis, so each pad lies in the hand x-z plane. The sensor sits on the
finger at +y; its pad frame (docs/design.md, Conventions) has z along the outward normal, i.e. pointing at the object
(-y of the hand), x along the hand x axis and y = z cross x = hand z (towards the fingertips' approach
direction). An in-hand angle is therefore a rotation about the hand y axis, and a correction is a Cartesian
rotation of the hand about the pad normal through the contact.
"""

from __future__ import annotations

import math

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar

# pad frame in the hand (TCP) frame: columns are the pad's x, y, z axes in hand coordinates
HAND_R_PAD = np.array([[1.0, 0.0, 0.0],
                       [0.0, 0.0, -1.0],
                       [0.0, 1.0, 0.0]])


def transform(rotation: np.ndarray | None = None, translation_m: np.ndarray | None = None) -> np.ndarray:
    """4x4 homogeneous transform from a 3x3 rotation (default identity) and a translation (default 0)."""
    t = np.eye(4)
    if rotation is not None:
        t[:3, :3] = check_array("rotation", rotation, shape=(3, 3))
    if translation_m is not None:
        t[:3, 3] = check_array("translation_m", translation_m, shape=(3,))
    return t


def rotation_about(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """3x3 rotation by ``angle_rad`` about ``axis`` (any non-zero length; Rodrigues' formula)."""
    a = check_array("axis", axis, shape=(3,))
    norm = float(np.linalg.norm(a))
    if not norm > 1e-12:
        raise ValueError(f"axis must be a non-zero 3-vector, got {a.tolist()}")
    angle = check_finite_scalar("angle_rad", angle_rad)
    k = a / norm
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def rotate_pose_about(base_T_x: np.ndarray, axis_base: np.ndarray, point_base_m: np.ndarray,
                      angle_rad: float) -> np.ndarray:
    """``base_T_x`` turned by ``angle_rad`` about the line through ``point_base_m`` along ``axis_base``."""
    pose = check_array("base_T_x", base_T_x, shape=(4, 4))
    point = check_array("point_base_m", point_base_m, shape=(3,))
    r = rotation_about(axis_base, angle_rad)
    out = pose.copy()
    out[:3, :3] = r @ pose[:3, :3]
    out[:3, 3] = r @ (pose[:3, 3] - point) + point
    return out


def hand_T_pad(pad_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Pad frame in the hand frame; ``pad_offset_m`` is the pad centre in hand coordinates (m).

    The pad centre's y coordinate is half the finger opening and changes with the grasp width; the contact
    geometry only needs the pad's axes and a point on its normal, so the default keeps it on the hand axis.
    """
    return transform(HAND_R_PAD, np.asarray(pad_offset_m, dtype=np.float64))


def hand_T_finger_pad(opening_m: float) -> np.ndarray:
    """Pad frame of the sensor on the +y finger when the fingers are ``opening_m`` apart (pad surface at
    hand y = +opening/2, so an object centred between the fingers has its centre at pad z = opening/2)."""
    opening = check_finite_scalar("opening_m", opening_m, low=0.0, high=0.2)
    return hand_T_pad((0.0, opening / 2, 0.0))


def angle_in_plane(direction: np.ndarray, frame_T: np.ndarray) -> float:
    """Angle (rad, atan2) of a 3-vector's projection on the x-y plane of ``frame_T`` (a 4x4 pose, same base)."""
    d = check_array("direction", direction, shape=(3,))
    r = check_array("frame_T", frame_T, shape=(4, 4))[:3, :3]
    local = r.T @ d
    if math.hypot(local[0], local[1]) < 1e-12:
        raise ValueError("direction is along the frame's z axis: no in-plane angle")
    return math.atan2(local[1], local[0])
