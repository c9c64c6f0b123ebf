"""The Franka Research 3's limits and the properties every FR3 backend shares (numpy only)."""

from __future__ import annotations

import math

import numpy as np

from tactile_manip.checks import check_array
from tactile_manip.robot.base import N_JOINTS, Arm


def _frozen(values: list[float]) -> np.ndarray:
    a = np.array(values, dtype=np.float64)
    a.flags.writeable = False
    return a


# FR3 datasheet (Franka Research 3), rad and rad/s; joint 6's range is shifted compared to the Panda.
FR3_Q_MIN_RAD = _frozen([-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159])
FR3_Q_MAX_RAD = _frozen([2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159])
FR3_DQ_MAX_RAD_S = _frozen([2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26])
# Panda's "ready" pose qr with joint 6 at 1.9 rad instead of 2.0, so the hand z axis points straight down
# (qr tilts it by 5.7 deg): TCP at (0.463, 0, 0.403) m, hand x = base x, fingers closing along base y.
FR3_HOME_Q_RAD = (0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4)


def fr3_joint_violation(q_rad: np.ndarray) -> str:
    """'' when ``q_rad`` (7,) is inside the FR3 limits, else a phrase naming the first joint outside them."""
    for j in range(N_JOINTS):
        if not FR3_Q_MIN_RAD[j] <= q_rad[j] <= FR3_Q_MAX_RAD[j]:
            return f"joint {j + 1} = {q_rad[j]:.4f} rad outside the FR3 limits [{FR3_Q_MIN_RAD[j]}, {FR3_Q_MAX_RAD[j]}]"
    return ""


def check_fr3_configuration(name: str, q_rad: object) -> np.ndarray:
    """``q_rad`` as a (7,) float array inside the FR3 limits, or a ValueError naming ``name`` and the joint."""
    q = check_array(name, q_rad, shape=(N_JOINTS,))
    problem = fr3_joint_violation(q)
    if problem:
        raise ValueError(f"{name}: {problem}")
    return q


class FR3Arm(Arm):
    """An :class:`Arm` with the FR3's limits; ``self.config.home_q_rad`` gives the home configuration."""

    config: object

    @property
    def q_min_rad(self) -> np.ndarray:
        return FR3_Q_MIN_RAD.copy()

    @property
    def q_max_rad(self) -> np.ndarray:
        return FR3_Q_MAX_RAD.copy()

    @property
    def dq_max_rad_s(self) -> np.ndarray:
        return FR3_DQ_MAX_RAD_S.copy()

    @property
    def home_q_rad(self) -> np.ndarray:
        return np.array(self.config.home_q_rad, dtype=np.float64)
