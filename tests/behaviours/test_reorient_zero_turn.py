"""A correction of zero is not sent to the arm: a real arm's planner refuses a motion of zero length (franky-sim
raised "Motion planner failed with error code -111" for it)."""

from __future__ import annotations

import pytest

from tactile_manip.behaviours.reorient import grasp_estimate_reorient
from tactile_manip.perception.baselines import blind_estimator
from tactile_manip.trials.cells import SimulatedCell
from tactile_manip.trials.presentation import draw_presentation
from tactile_manip.trials.scene import MethodSpec, PresentationConfig, TrialObject, TrialScene

pytest.importorskip("roboticstoolbox")


class CountingArm:
    """The cell's arm, counting the Cartesian moves it is asked for."""

    def __init__(self, arm) -> None:
        self._arm, self.cartesian_moves = arm, 0

    def move_cartesian(self, *args, **kwargs) -> None:
        self.cartesian_moves += 1
        self._arm.move_cartesian(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._arm, name)


def test_a_zero_correction_moves_nothing() -> None:
    scene = TrialScene(trials=1, seed=2, methods=[MethodSpec("blind", "blind")],
                       presentation=PresentationConfig(objects=[TrialObject("cylinder", "c3", {"size_mm": 3.0})]))
    cell = SimulatedCell(scene)
    with cell.connected(), cell.presented(draw_presentation(scene, 0)) as (obj, truth):
        arm = CountingArm(cell.arm)
        before = arm.state().base_T_hand
        result = grasp_estimate_reorient(arm, cell.gripper, cell.sensor, blind_estimator(),  # answers the target
                                         object_width_m=obj.width_m, target_angle_rad=0.0, truth=truth)
        assert result.outcome == "done" and result.correction_rad == 0.0
        assert arm.cartesian_moves == 0 and (arm.state().base_T_hand == before).all()
