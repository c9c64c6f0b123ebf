"""A scene's presentations: which object each trial holds, at which in-hand angle, offset and force, and on
which sensor; a pure function of the scene's seed and the trial's index, so every method meets the same one.

A cell may refuse a draw it cannot hold (the simulated cell: a press that would drive the object through the
skin's elastic layer, where the simulator no longer holds); the trial is then drawn again from the next seed of
its own, the object kept, so that no other trial's draw moves."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tactile_manip.perception.pose import wrap_axial
from tactile_manip.robot.frames import rotation_about, transform
from tactile_manip.trials.scene import TrialObject, TrialScene


@dataclass(frozen=True)
class Presentation:
    """One trial's draw: which object, at which in-hand angle (rad, pad frame), offset (mm) and force (N)."""

    trial: int
    seed: int
    obj: TrialObject
    angle_rad: float
    offset_mm: tuple[float, float]
    force_n: float
    sensor_spread: float = 0.0      # > 0: this trial's sensor is drawn (see sensor_params)

    def sensor_params(self, board: str = "supermag-4x4"):
        """The simulator parameters of this trial's sensor on ``board`` (a board's name or file; drawn from the
        trial's seed about the board's figures), or None for the nominal one."""
        if self.sensor_spread == 0:
            return None
        from tactile_manip.boards import load_board
        from tactile_manip.sim.params import for_board, randomise

        return randomise(for_board(load_board(board)), np.random.default_rng([self.seed, 1]),
                         spread=self.sensor_spread)


MAX_REDRAWS = 20  # draws of one trial a cell may refuse before the last is kept (and its trial fails)


def draw_presentation(scene: TrialScene, trial: int, *,
                      holds: Callable[[Presentation], bool] | None = None) -> Presentation:
    """The presentation of trial ``trial``: a pure function of the scene's seed, the index and ``holds``.

    ``holds``: whether the cell can hold a draw (``SimulatedCell.holds``); a draw it cannot hold is replaced by
    the trial's next one (same object; angle, offset, force and sensor drawn again), up to ``MAX_REDRAWS``
    times, after which the last is kept and the trial records the cell's error. A draw it holds is the one
    drawn without ``holds``.
    """
    for attempt in range(MAX_REDRAWS + 1):
        entropy = [scene.seed, trial] + ([attempt] if attempt else [])
        p = _draw(scene, trial, int(np.random.SeedSequence(entropy).generate_state(1)[0]))
        if holds is None or holds(p):
            break
    return p


def _draw(scene: TrialScene, trial: int, seed: int) -> Presentation:
    rng = np.random.default_rng(seed)
    p = scene.presentation
    obj = p.objects[trial % len(p.objects)]
    angle = float(wrap_axial(math.radians(rng.uniform(*p.angle_deg))))
    offset = rng.uniform(-p.offset_mm, p.offset_mm, size=2)
    force = float(rng.uniform(*p.force_n))
    return Presentation(trial, seed, obj, angle, (float(offset[0]), float(offset[1])), force, p.sensor_spread)


def pad_T_object(angle_rad: float, offset_mm: tuple[float, float], width_m: float) -> np.ndarray:
    """Object frame (x along its axis, its centre ``width_m / 2`` off the pad surface) in the pad frame."""
    return transform(rotation_about(np.array([0.0, 0.0, 1.0]), angle_rad),
                     np.array([offset_mm[0] * 1e-3, offset_mm[1] * 1e-3, width_m / 2]))
