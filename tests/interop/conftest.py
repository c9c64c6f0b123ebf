"""Episodes with every stream filled in (and some gaps), built directly from seeded random values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.interop.frames import PHASES, Episode, Frame


def make_episodes(*, episodes: int = 2, frames: int = 40, depth_every: int = 10, fps: float = 125.0,
                  depth_shape: tuple[int, int] = (20, 24), seed: int = 0) -> list[Episode]:
    """``episodes`` trials of ``frames`` frames: fields of any sign, estimates on odd frames only, depth on
    every ``depth_every``-th frame, joints everywhere, phases in order, the VBTS depth on the first episode."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(episodes):
        host0 = 100.0 + 7.5 * k
        items = []
        for i in range(frames):
            odd = i % 2 == 1
            depth = rng.uniform(0, 1.5, depth_shape).astype(np.float32) if i % depth_every == 0 else None
            items.append(Frame(
                t_s=i / fps, host_time_s=host0 + i / fps + rng.uniform(0, 1e-3),
                field_ut=rng.normal(0, 80, (4, 4, 3)).astype(np.float32),
                angle_rad=float(rng.uniform(-math.pi / 2, math.pi / 2)) if odd else math.nan,
                confidence=float(rng.uniform(0, 1)) if odd else math.nan,
                joints_rad=rng.uniform(-2, 2, 7), gripper_width_m=float(rng.uniform(0, 0.08)),
                target_angle_rad=0.25 * k, phase=PHASES[1 + min(3, 4 * i // frames)], depth_mm=depth,
                vbts_depth_mm=depth + 0.5 if depth is not None and k == 0 else None))
        out.append(Episode(index=k, task=f"reorient rod to {15 * k} deg (supermag)", fps=fps, frames=items,
                           success=k % 2 == 0, meta={"layout": "supermag-4x4"}))
    return out


@pytest.fixture
def episodes() -> list[Episode]:
    return make_episodes()
