"""A scene on another simulated board: the [sensor] board reaches the simulated cell, its sensor and its presses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tactile_manip.trials.cells import SimulatedCell
from tactile_manip.trials.methods import build_tactile_estimators
from tactile_manip.trials.presentation import draw_presentation
from tactile_manip.trials.scene import load_scene

pytest.importorskip("roboticstoolbox")
pytest.importorskip("onnxruntime")

SCENES = Path(__file__).resolve().parents[2] / "configs" / "scenes"


@pytest.mark.parametrize("name, board", [("grip_eflesh", "eflesh"), ("grip_anyskin5", "anyskin-5")])
def test_a_grip_scene_runs_on_its_board_and_its_contact_method_closes_the_loop(name, board):
    scene = load_scene(SCENES / f"{name}.toml")
    assert scene.sensor.board == board
    cell = SimulatedCell(scene)
    assert cell.sensor.layout.name == board and cell.sensor.pair.board.name == board
    p = draw_presentation(scene, 0, holds=cell.holds)
    pair = cell._pair_of(p)
    assert pair.board.name == board
    estimators = build_tactile_estimators(scene, SCENES / f"{name}.toml", layout=board)
    assert estimators["contact"].contact is not None and estimators["contact"].contact.board_layout == board
    assert estimators["blind"].contact is None     # the open-loop baseline, though the scene names a model
    with cell.connected():
        result = cell.run_one(p, estimators["contact"])
        reading = cell.sensor.read_latest(max_age_s=1.0)
    assert reading.field_ut.shape == (3, 3, 3) and not reading.field_ut[0, 0].any()
    assert result.outcome == "done" and result.true_force_n is not None
    assert np.isfinite(result.force_error_n)
