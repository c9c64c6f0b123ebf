"""A scene's presentations: which object each trial holds, at which in-hand angle, offset and force, and on
which sensor; a pure function of the scene's seed and the trial's index, so every method meets the same one."""

from __future__ import annotations

import math
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

    def sensor_params(self):
        """The simulator parameters of this trial's sensor (drawn from its seed), or None for the nominal one."""
        if self.sensor_spread == 0:
            return None
        from tactile_manip.sim.params import SimParams, randomise

        return randomise(SimParams(), np.random.default_rng([self.seed, 1]), spread=self.sensor_spread)


def draw_presentation(scene: TrialScene, trial: int) -> Presentation:
    """The presentation of trial ``trial``: a pure function of the scene's seed and the index."""
    seed = int(np.random.SeedSequence([scene.seed, trial]).generate_state(1)[0])
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
