"""Shared fixtures: a simulated DTact camera and its ball-press calibration, rendered without threads."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig, ball_indenter
from tactile_manip.collection.pair_log import PairLogWriter, PairRecord
from tactile_manip.collection.vbts_calibration import calibrate_ball
from tactile_manip.sim.objects import IndenterPose

BALL_RADIUS_MM = 4.0
BALL_FORCE_N = 4.5  # ~1.78 mm deep: covers the paper's objects at 10-11 N (up to ~1.7 mm)


def render_frames(camera: SimulatedCamera, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` noisy frames of the camera's current contact (no thread, no waiting)."""
    return [camera.render(0.0, rng) for _ in range(n)]


def ball_press_frames(camera: SimulatedCamera, rng: np.random.Generator, *, force_n: float = BALL_FORCE_N,
                      pose: IndenterPose | None = None, radius_mm: float = BALL_RADIUS_MM, n: int = 10
                      ) -> list[np.ndarray]:
    camera.set_contact(ball_indenter(radius_mm), pose or IndenterPose(x_mm=0.7, y_mm=-0.4), force_n)
    frames = render_frames(camera, n, rng)
    camera.clear_contact()
    return frames


@pytest.fixture(scope="session")
def sim_camera() -> SimulatedCamera:
    """The default simulated camera (sensor_1 response, mirror x), not connected."""
    return SimulatedCamera(SimulatedCameraConfig(seed=0))


@pytest.fixture(scope="session")
def reference_frames(sim_camera) -> list[np.ndarray]:
    sim_camera.clear_contact()
    return render_frames(sim_camera, 10, np.random.default_rng(1))


@pytest.fixture(scope="session")
def calibration(sim_camera, reference_frames):
    """Ball-press calibration of the default simulated camera (4 mm radius, 4.5 N)."""
    press = ball_press_frames(sim_camera, np.random.default_rng(2))
    return calibrate_ball(sim_camera.alignment, reference_frames, [press], BALL_RADIUS_MM)


@pytest.fixture
def render():
    """``render(camera, n, rng)``: ``n`` noisy frames of the camera's current contact."""
    return render_frames


@pytest.fixture
def ball_press():
    """``ball_press(camera, rng, force_n=..., pose=..., radius_mm=..., n=...)``: frames of a still ball press."""
    return ball_press_frames


def _pair_record(k: int, obj: str) -> PairRecord:
    """A synthetic pair ``k`` of object ``obj`` (random field and depth, 2 ms apart)."""
    rng = np.random.default_rng(k)
    return PairRecord(rng.normal(0, 50, (4, 4, 3)).astype(np.float32), rng.normal(0, 50, (4, 4, 3)).astype(np.float32),
                      np.zeros((4, 4, 3), bool), rng.integers(0, 180, (200, 200)).astype(np.uint8),
                      {"t_depth_s": k * 0.1, "t_field_s": k * 0.1 + 0.002, "dt_s": 0.002, "seq_depth": k,
                       "seq_field": 4 * k, "force_n": 10.2, "object": obj, "pose": None, "press": k})


def _write_log(path, objects):
    with PairLogWriter(path, {"config": {"tolerance_s": 0.005}, "pixel_mm": 0.1}) as log:
        log.write_event(0.0, {"event": "start"})
        for k, obj in enumerate(objects):
            log.write_pair(k * 0.1, _pair_record(k, obj))
    return path


@pytest.fixture
def pair_record():
    """``pair_record(k, object_name)``: a synthetic logged pair."""
    return _pair_record


@pytest.fixture
def write_log():
    """``write_log(path, object_names)``: a pair log with one synthetic pair per name."""
    return _write_log
