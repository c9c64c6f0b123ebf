"""The slot placement behaviour: angle and centroid of the tactile pose used to put a rod into a slot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.behaviours.place import Slot, place_in_slot, slot_errors
from tactile_manip.robot.frames import hand_T_pad, transform
from tactile_manip.trials.cells import SimulatedCell
from tactile_manip.trials.methods import build_tactile_estimators
from tactile_manip.trials.presentation import draw_presentation
from tactile_manip.trials.scene import MethodSpec, PresentationConfig, TrialObject, TrialScene

pytest.importorskip("roboticstoolbox")
pytest.importorskip("onnxruntime")

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "supermag.onnx")


@pytest.fixture(scope="module")
def cell():
    scene = TrialScene(trials=3, seed=5, methods=[MethodSpec("supermag", MODEL)],
                       presentation=PresentationConfig(objects=[TrialObject("cylinder", "c3", {"size_mm": 3.0})]))
    cell = SimulatedCell(scene)
    with cell.connected():
        yield cell


def _slot(base_T_pad: np.ndarray, angle_rad: float) -> Slot:
    axis = base_T_pad[:3, :3] @ np.array([math.cos(angle_rad), math.sin(angle_rad), 0.0])
    return Slot((base_T_pad @ np.array([0.004, -0.05, 0.0, 1.0]))[:3], axis, clearance_m=0.001)


@pytest.mark.parametrize("trial, slot_deg", [(0, 70.0), (1, -20.0), (2, 5.0)])
def test_the_rod_ends_in_the_slot(cell, trial, slot_deg) -> None:
    estimator = build_tactile_estimators(cell.scene)["supermag"]
    with cell.presented(draw_presentation(cell.scene, trial)) as (obj, truth):
        base_T_pad = cell.arm.state().base_T_hand @ hand_T_pad()
        slot = _slot(base_T_pad, math.radians(slot_deg))
        result = place_in_slot(cell.arm, cell.gripper, cell.sensor, estimator, slot, object_width_m=obj.width_m,
                               truth=truth)
    assert result.outcome == "done", result.detail
    assert abs(math.degrees(result.angle_error_rad)) < 5.0
    assert result.lateral_error_m < 1e-3
    assert result.succeeded(math.radians(5.0), 1e-3)


def test_a_slot_out_of_the_pad_plane_is_refused_before_grasping(cell) -> None:
    estimator = build_tactile_estimators(cell.scene)["supermag"]
    with cell.presented(draw_presentation(cell.scene, 0)) as (obj, _):
        normal = (cell.arm.state().base_T_hand @ hand_T_pad())[:3, 2]
        with pytest.raises(ValueError, match="pad plane"):
            place_in_slot(cell.arm, cell.gripper, cell.sensor, estimator, Slot(np.zeros(3), normal),
                          object_width_m=obj.width_m)
        assert not cell.gripper.state().is_grasped


def test_slot_errors_measure_angle_and_distance_to_the_axis() -> None:
    pad = np.eye(4)
    slot = Slot(np.array([0.0, 0.002, 0.0]), np.array([1.0, 0.0, 0.0]))
    rod = transform(np.eye(3), np.array([0.03, 0.0, 0.0]))          # parallel, 2 mm beside the slot centre
    angle, lateral = slot_errors(rod, slot, pad)
    assert angle == pytest.approx(0.0) and lateral == pytest.approx(0.002)
    c, s = math.cos(0.1), math.sin(0.1)
    turned = transform(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), np.array([0.0, 0.002, 0.0]))
    angle, lateral = slot_errors(turned, slot, pad)
    assert angle == pytest.approx(0.1) and lateral == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="non-zero"):
        Slot(np.zeros(3), np.zeros(3))
