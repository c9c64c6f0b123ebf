"""The Camera contract on the simulated camera, its timing faults, and the OpenCV backend's missing dependency."""

from __future__ import annotations

import importlib.util
import math
import time

import numpy as np
import pytest

from tactile_manip.errors import SensorDisconnectedError
from tactile_manip.collection.camera import CameraError, CameraFrame, CameraTimeoutError, make_camera
from tactile_manip.collection.camera_opencv import OpenCVCamera, OpenCVCameraConfig
from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig, ball_indenter
from tactile_manip.sensors.simulated.contacts import Press
from tactile_manip.sim.objects import IndenterPose


def _camera(**kwargs) -> SimulatedCamera:
    return SimulatedCamera(SimulatedCameraConfig(**{"rate_hz": 100.0, **kwargs}))


def test_frames_arrive_in_order_with_host_times_and_sequence_numbers():
    with _camera() as cam:
        frames = [cam.read(1.0) for _ in range(10)]
        h = cam.health()
    assert all(isinstance(f, CameraFrame) for f in frames)
    assert frames[0].image.dtype == np.uint8 and frames[0].image.shape == (480, 640)
    assert not frames[0].image.flags.writeable
    seqs = [f.seq for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == 10
    assert np.all(np.diff([f.t_host_s for f in frames]) > 0)
    assert all(abs(f.t_host_s - f.t_exposure_s) < 1e-9 for f in frames)  # no latency configured
    assert h.connected and h.frames >= 10 and h.dropped == 0


def test_contract_connect_disconnect_and_reading_while_disconnected():
    cam = _camera()
    with pytest.raises(SensorDisconnectedError, match="connect"):
        cam.read(0.1)
    cam.connect()
    try:
        with pytest.raises(CameraError, match="already connected"):
            cam.connect()
    finally:
        cam.disconnect()
    cam.disconnect()  # idempotent
    assert not cam.is_connected
    with pytest.raises(SensorDisconnectedError):
        cam.read(0.1)


def test_a_camera_that_stops_raises_a_timeout_naming_it_and_recovers():
    with _camera() as cam:
        cam.stall()
        cam.drain()
        with pytest.raises(CameraTimeoutError, match="stalled: call resume"):
            cam.read(0.15)
        cam.resume()
        assert isinstance(cam.read(1.0), CameraFrame)


def test_dropped_frames_leave_gaps_in_seq_and_are_counted():
    with _camera(rate_hz=200.0, drop_rate=0.3, seed=4) as cam:
        frames = [cam.read(1.0) for _ in range(60)]
        h = cam.health()
    gaps = sum(b.seq - a.seq - 1 for a, b in zip(frames, frames[1:]))
    assert gaps > 5
    assert h.dropped >= gaps


def test_jitter_and_latency_move_timestamps_but_keep_order():
    with _camera(rate_hz=100.0, jitter_s=0.002, latency_s=0.004, seed=5) as cam:
        frames = [cam.read(1.0) for _ in range(40)]
    assert all(abs(f.t_host_s - f.t_exposure_s - 0.004) < 1e-9 for f in frames)
    steps = np.diff([f.t_exposure_s for f in frames])
    assert np.all(steps > 0) and steps.std() > 5e-4


def test_a_press_darkens_the_pad_where_the_simulator_says():
    cam = _camera()
    rng = np.random.default_rng(0)
    idle = cam.render(0.0, None).astype(np.float32)
    cam.set_contact(ball_indenter(4.0), IndenterPose(), 3.0)
    pressed = cam.render(0.0, None).astype(np.float32)
    truth = cam.indentation_at(0.0)
    darker = idle - pressed
    assert truth.max() > 1.0 and darker.max() > 30
    assert np.all(darker[truth == 0] == 0)  # noise-free: nothing changes off the contact
    noisy = cam.render(0.0, rng).astype(np.float32)
    assert 0.7 < np.std(noisy - pressed) < 1.3  # ~1 grey level of read noise


class _WatchedCamera(SimulatedCamera):
    """A simulated camera that reads its contact, as the frame thread would, after every attribute it sets."""

    seen: list

    def __setattr__(self, name, value):
        super().__setattr__(name, value)
        if "seen" in self.__dict__:
            self.seen.append(self._contact_at(1.0)[0] is not None)


def test_switching_between_a_script_and_a_still_press_never_shows_a_frame_without_either():
    cam = _WatchedCamera(SimulatedCameraConfig(rate_hz=100.0))
    script = [Press(ball_indenter(4.0), start_s=0.0, peak_force_n=3.0, rise_s=1.0, hold_s=10.0)]
    cam.play(script, start_host_s=0.0)  # solved once; the host time 1.0 s read below is within the press
    cam.seen = []
    for _ in range(3):
        cam.set_contact(ball_indenter(4.0), IndenterPose(), 3.0)
        cam.play(script, start_host_s=0.0)
    assert cam.seen and all(cam.seen)  # every state the frame thread could read holds a contact
    cam.clear_contact()
    assert cam.seen[-1] is False


def test_simulated_camera_config_refuses_bad_values():
    with pytest.raises(ValueError, match="rate_hz"):
        SimulatedCameraConfig(rate_hz=0.0)
    with pytest.raises(ValueError, match="drop_rate"):
        SimulatedCameraConfig(drop_rate=1.5)
    with pytest.raises(ValueError, match="mirror"):
        SimulatedCameraConfig(mirror="z")


def test_make_camera_builds_from_the_config_table():
    assert isinstance(make_camera(SimulatedCameraConfig()), SimulatedCamera)
    assert isinstance(make_camera(OpenCVCameraConfig()), OpenCVCamera)
    with pytest.raises(ValueError, match="camera config"):
        make_camera(object())


@pytest.mark.skipif(importlib.util.find_spec("cv2") is not None, reason="opencv is installed here")
def test_opencv_backend_without_opencv_names_the_extra():
    cam = OpenCVCamera(OpenCVCameraConfig(device=0))
    with pytest.raises(ImportError, match=r'pip install -e "\.\[camera\]"'):
        cam.connect()
    assert not cam.is_connected


def test_opencv_config_refuses_bad_values():
    with pytest.raises(ValueError, match="width_px"):
        OpenCVCameraConfig(width_px=0)
    with pytest.raises(ValueError, match="fps"):
        OpenCVCameraConfig(fps=math.nan)


def test_read_returns_frames_in_fifo_order_and_counts_overruns():
    with _camera(rate_hz=200.0, buffer_frames=4) as cam:
        time.sleep(0.1)  # ~20 frames into a FIFO of 4
        frames = cam.drain()
        h = cam.health()
    assert len(frames) <= 4 and h.overruns > 0
    assert [f.seq for f in frames] == sorted(f.seq for f in frames)
