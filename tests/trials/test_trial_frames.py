"""Per-frame streams of trials: every sensor frame kept, stamped with the phase and state, crash-safe on disk."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.sensors.config import SimulatedSensorConfig
from tactile_manip.sensors.simulated import SimulatedSensor
from tactile_manip.trials.frames import (PHASES, RECORD, TrialFrameStream, frame_dtype, frames_path,
                                         read_trial_frames)
from tactile_manip.types import AngleEstimate

REPO = Path(__file__).resolve().parents[2]


class _Arm:
    def __init__(self) -> None:
        self.q = np.zeros(7)

    def state(self):
        return type("S", (), {"q_rad": self.q.copy()})()


class _Gripper:
    def __init__(self) -> None:
        self.width_m = 0.08

    def state(self):
        return type("S", (), {"width_m": self.width_m})()


def _wait_frames(sensor, n: int) -> None:
    for _ in range(n):
        sensor.wait_new(timeout_s=1.0)


def test_a_stream_keeps_every_frame_from_the_grasp_on_stamped_with_the_state_that_held(tmp_path) -> None:
    arm, gripper = _Arm(), _Gripper()
    path = tmp_path / "frames" / "m-0000.tmframes"
    with SimulatedSensor(SimulatedSensorConfig(seed=0)) as sensor:
        _wait_frames(sensor, 3)  # before the trial: not kept
        with TrialFrameStream(path, sensor=sensor, arm=arm, gripper=gripper, header={"trial": 0, "method": "m"},
                              target_angle_rad=0.25) as stream:
            stream.phase("grasp")
            _wait_frames(sensor, 4)
            gripper.width_m = 0.004
            stream.phase("estimate")
            _wait_frames(sensor, 4)
            stream.estimate(AngleEstimate(angle_rad=0.5, confidence=0.8, defined=True))
            _wait_frames(sensor, 2)
            stream.phase("turn")
            arm.q = np.full(7, 0.1)
            _wait_frames(sensor, 2)
            stream.phase("release")
            gripper.width_m = 0.08
    frames = read_trial_frames(path)
    rows = frames.rows
    assert frames.header["trial"] == 0 and frames.header["rate_hz"] == 125.0 and frames.header["grid"] == [4, 4]
    assert len(frames) >= 12 and frames.truncated_bytes == 0
    assert np.all(np.diff(rows["seq"]) == 1)  # no frame of the sensor missing in between
    phases = frames.phases
    assert phases[0] == "grasp" and phases[-1] == "release"
    order = [PHASES.index(p) for p in phases]
    assert order == sorted(order)  # grasp, estimate, turn, release in time order
    grasp = rows[np.array(phases) == "grasp"]
    assert np.all(grasp["gripper_width_m"] == 0.08) and np.isnan(grasp["angle_rad"]).all()
    assert rows["gripper_width_m"][np.array(phases) == "estimate"][0] == 0.004
    assert rows["angle_rad"][-1] == 0.5 and rows["confidence"][-1] == pytest.approx(0.8)
    assert np.all(rows["target_angle_rad"] == 0.25)
    assert rows["gripper_width_m"][-1] == 0.08 and np.all(rows["joints_rad"][-1] == 0.1)
    assert np.all(np.diff(frames.t_host_s) > 0)


def test_a_torn_tail_and_a_damaged_record_lose_only_themselves(tmp_path) -> None:
    path = tmp_path / "x.tmframes"
    with SimulatedSensor(SimulatedSensorConfig(seed=1)) as sensor:
        with TrialFrameStream(path, sensor=sensor, header={"trial": 1, "method": "m"}, target_angle_rad=0.0) as s:
            s.phase("grasp")
            _wait_frames(sensor, 10)
            s.phase("release")
    whole = read_trial_frames(path)
    n = len(whole)
    record = RECORD.size + frame_dtype((4, 4)).itemsize + 4
    data = bytearray(path.read_bytes())
    start = len(data) - n * record
    data[start + 3 * record + RECORD.size + 20] ^= 0xFF  # a flipped byte inside the 4th frame
    path.write_bytes(bytes(data[:-7]))  # and the last record torn
    damaged = read_trial_frames(path)
    assert len(damaged) == n - 2 and damaged.damaged_records == 1 and damaged.truncated_bytes == record - 7
    kept = np.delete(whole.rows["seq"], [3, n - 1])
    assert np.array_equal(damaged.rows["seq"], kept)
    assert np.array_equal(damaged.rows["field_ut"], np.delete(whole.rows["field_ut"], [3, n - 1], axis=0))


def test_trial_runs_record_one_frames_file_per_trial_and_method_unless_told_not_to(tmp_path) -> None:
    pytest.importorskip("roboticstoolbox")
    from tactile_manip.trials.log import read_trials
    from tactile_manip.trials.runner import run_trials
    from tactile_manip.trials.scene import MethodSpec, load_scene

    scene = dataclasses.replace(load_scene(REPO / "configs" / "scenes" / "reorient_sim.toml"), trials=2,
                                methods=[MethodSpec("bilinear", "bilinear", output_px=16)])
    run_trials(scene, tmp_path / "run", progress=False)
    for r in read_trials(tmp_path / "run"):
        frames = read_trial_frames(frames_path(tmp_path / "run", r.trial, r.method))
        assert frames.header["seed"] == r.seed and frames.header["object"] == r.object
        assert np.all(np.diff(frames.rows["seq"]) == 1)
        assert {"estimate", "release"} <= set(frames.phases)
        if r.estimated_angle_rad is not None:  # the estimate acted on is one the frames carried (re-grasps: the best)
            assert np.isclose(frames.rows["angle_rad"], r.estimated_angle_rad).any()
        assert np.isfinite(frames.rows["joints_rad"]).all() and np.isfinite(frames.rows["gripper_width_m"]).all()
    run_trials(scene, tmp_path / "bare", progress=False, frames=False)
    assert not (tmp_path / "bare" / "frames").exists()


def test_the_trials_command_records_frames_unless_no_frames_is_given() -> None:
    from tactile_manip.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["trials", "--config", "s.toml"]).frames is True
    assert parser.parse_args(["trials", "--config", "s.toml", "--no-frames"]).frames is False
