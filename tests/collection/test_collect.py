"""The pair recorder: trigger logic, crash-safe log, dataset writer, and the collector on in-process sensors
(pairs with the right content, and clear errors for a camera or MBTS that stops or a pressed reference)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tactile_manip.errors import CalibrationError, RecordingError, SensorTimeoutError
from tactile_manip.sensors import SimulatedSensor, SimulatedSensorConfig
from tactile_manip.collection.camera import CameraTimeoutError
from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig
from tactile_manip.collection.collect import CollectConfig, PairCollector
from tactile_manip.collection.force import FieldForce, ForceSource, FunctionForce, PressTrigger, ScriptForce
from tactile_manip.sensors.simulated.contacts import Press
from tactile_manip.collection.pair_log import dataset_from_pair_logs, read_pair_log
from tactile_manip.data import load_dataset, save_dataset
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.shapes import make_indenter

FAST = dict(baseline_frames=20, reference_frames=4, camera_timeout_s=0.4, mbts_timeout_s=0.3)


# ---------------------------------------------------------------------------------------------- trigger


def test_trigger_takes_n_frames_per_press_and_rearms_only_after_release():
    trig = PressTrigger(threshold_n=10.0, release_n=2.0, pairs_per_press=2)
    forces = [0, 4, 9.9, 10.0, 10.5, 10.5, 10.5, 6, 9, 10.2, 10.2, 1.0, 10.1, 10.1, 10.1]
    taken = [trig.want(0.01 * i, f) for i, f in enumerate(forces)]
    assert taken == [None, None, None, 0, 0, None, None, None, None, None, None, None, 1, 1, None]
    assert trig.presses == 2  # the dip to 6-9 N did not re-arm: same press


def test_trigger_gives_a_failed_pairs_slot_back_while_the_press_lasts():
    trig = PressTrigger(10.0, 2.0, pairs_per_press=1)
    assert trig.want(0.0, 11.0) == 0
    trig.result(0, paired=False)
    assert trig.want(0.03, 11.0) == 0
    trig.result(0, paired=True)
    assert trig.want(0.06, 11.0) is None and trig.complete == 1


def test_trigger_waits_settle_time():
    trig = PressTrigger(10.0, 2.0, pairs_per_press=1, settle_s=0.05)
    assert trig.want(1.00, 10.0) is None
    assert trig.want(1.03, 10.0) is None
    assert trig.want(1.06, 10.0) == 0


@pytest.mark.parametrize("kwargs, match", [
    ({"release_n": 10.0}, "release_n"), ({"tolerance_s": 0.0}, "tolerance_s"),
    ({"pairs_per_press": 0}, "pairs_per_press"),
    ({"mbts_clock": "gps"}, "mbts_clock"), ({"object_name": ""}, "object_name")])
def test_collect_config_refuses_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CollectConfig(**kwargs)


def test_script_force_follows_the_presses_and_labels_them():
    p = Press("letter_r", start_s=1.0, peak_force_n=10.0, rise_s=0.2, hold_s=0.3, pose=IndenterPose(x_mm=1.5))
    f = ScriptForce([p], start_host_s=100.0)
    assert f.force_n(100.5) == 0.0 and f.force_n(101.1) == pytest.approx(5.0) and f.force_n(101.3) == 10.0
    assert f.label(101.3).object_name == "letter_r" and f.label(101.3).pose[0] == 1.5
    assert f.label(100.0) is None and f.finished(101.8) and not f.finished(101.6)


# ---------------------------------------------------------------------------------------------- log and dataset


def test_pair_log_round_trip(tmp_path, write_log, pair_record):
    path = write_log(tmp_path / "a.tmpairs", ["allen_key", "letter_r"])
    log = read_pair_log(path)
    assert len(log) == 2 and log.truncated_bytes == 0 and log.events[0]["event"] == "start"
    rec = pair_record(1, "letter_r")
    got = log.pairs[1]
    assert np.array_equal(got.field_ut, rec.field_ut) and np.array_equal(got.depth_q, rec.depth_q)
    assert got.info["object"] == "letter_r" and got.info["dt_s"] == 0.002


def test_a_torn_tail_loses_only_the_last_record(tmp_path, write_log):
    path = write_log(tmp_path / "a.tmpairs", ["allen_key"] * 5)
    data = path.read_bytes()
    path.write_bytes(data[:-50])  # a crash in the middle of the last record
    log = read_pair_log(path)
    assert len(log) == 4 and log.truncated_bytes > 0
    path.write_bytes(b"not a log\n")
    with pytest.raises(RecordingError, match="not a tactile_manip pair log"):
        read_pair_log(path)


def test_dataset_from_logs_has_the_simulators_format_and_splits(tmp_path, write_log):
    logs = [write_log(tmp_path / "a.tmpairs", ["allen_key"] * 10 + ["letter_r"] * 10),
            write_log(tmp_path / "b.tmpairs", ["rod"] * 3)]
    data = dataset_from_pair_logs(logs, test_objects=["rod"], validation_fraction=0.2)
    back = load_dataset(save_dataset(tmp_path / "d.npz", data))
    assert len(back) == 23 and back.object_names.tolist() == ["allen_key", "letter_r", "rod"]
    assert [len(back.indices(s)) for s in ("train", "val", "test")] == [16, 4, 3]
    assert back.images.dtype == np.uint8 and back.images.shape == (23, 200, 200)
    assert np.isnan(back.extra("pose")).all() and back.provenance["sync"]["max_abs_dt_s"] == pytest.approx(0.002)
    with pytest.raises(ValueError, match="no pairs"):
        dataset_from_pair_logs([write_log(tmp_path / "e.tmpairs", [])])


# ---------------------------------------------------------------------------------------------- the collector


@pytest.fixture
def devices():
    sensor = SimulatedSensor(SimulatedSensorConfig(seed=3))
    camera = SimulatedCamera(SimulatedCameraConfig(seed=0), pair=sensor.pair)
    with sensor, camera:
        yield sensor, camera


class _StepForce(ForceSource):
    """No press before ``on_s`` (host time), then ``force_n``: the force by frame time, so that camera frames
    still in the camera's buffer from before the press was set are not taken as pressed."""

    def __init__(self) -> None:
        self.on_s, self.value_n = math.inf, 0.0

    def press(self, force_n: float) -> None:
        self.on_s, self.value_n = time.monotonic(), force_n

    def force_n(self, t_host_s: float) -> float:
        return self.value_n if t_host_s >= self.on_s else 0.0


def test_a_still_press_gives_pairs_with_the_simulators_content(devices, calibration, tmp_path):
    sensor, camera = devices
    force = _StepForce()
    collector = PairCollector(sensor, camera, calibration, force, tmp_path / "p.tmpairs",
                              config=CollectConfig(pairs_per_press=3, object_name="allen_key", **FAST))
    collector.prepare()
    obj, pose = make_indenter("allen_key"), IndenterPose(x_mm=1.0, yaw_rad=0.3)
    change = sensor.set_contact(obj, pose, 10.5)
    camera.set_contact(obj, pose, 10.5)
    force.press(10.5)
    summary = collector.run(presses=1, duration_s=10.0)
    assert summary.pairs == 3 and summary.complete_presses == 1 and summary.max_abs_dt_s <= 0.005
    data = dataset_from_pair_logs([summary.path])
    imprint = sensor.pair.press(obj, pose, 10.5, np.random.default_rng(0)).imprint_mm
    for i in range(3):
        assert np.sqrt(np.mean((data.depth_mm(i) - imprint) ** 2)) < 0.03
        assert np.abs(data.field_ut[i] - change).max() < 25.0  # chip noise and quantisation only
    assert data.object_names.tolist() == ["allen_key"] and data.extra("force_n")[0] == pytest.approx(10.5)


def test_a_camera_that_stops_ends_the_run_with_a_clear_error_and_a_readable_log(devices, calibration, tmp_path):
    sensor, camera = devices
    collector = PairCollector(sensor, camera, calibration, FunctionForce(lambda: 0.0), tmp_path / "p.tmpairs",
                              config=CollectConfig(**FAST))
    collector.prepare()
    camera.stall()
    camera.drain()
    with pytest.raises(CameraTimeoutError, match="camera simulated"):
        collector.run(duration_s=10.0)
    events = [e["event"] for e in read_pair_log(tmp_path / "p.tmpairs").events]
    assert events[0] == "start" and "error" in events and events[-1] == "stop"


def test_an_mbts_that_stops_while_frames_wait_is_a_timeout(devices, calibration, tmp_path):
    sensor, camera = devices
    force = {"n": 0.0}
    collector = PairCollector(sensor, camera, calibration, FunctionForce(lambda: force["n"]), tmp_path / "p.tmpairs",
                              config=CollectConfig(pairs_per_press=50, **FAST))
    collector.prepare()
    sensor.stall()
    force["n"] = 12.0
    with pytest.raises(SensorTimeoutError, match="no MBTS frame"):
        collector.run(duration_s=10.0)


def test_no_reference_or_baseline_while_the_gripper_presses(devices, calibration, tmp_path):
    sensor, camera = devices
    collector = PairCollector(sensor, camera, calibration, FunctionForce(lambda: 5.0), tmp_path / "p.tmpairs",
                              config=CollectConfig(**FAST))
    with pytest.raises(CalibrationError, match="presses with 5.0 N"):
        collector.prepare()


def test_a_reference_under_a_contact_the_force_missed_is_refused(devices, calibration, tmp_path):
    sensor, camera = devices
    collector = PairCollector(sensor, camera, calibration, FunctionForce(lambda: 0.0), tmp_path / "p.tmpairs",
                              config=CollectConfig(**FAST))
    camera.set_contact(make_indenter("letter_r"), IndenterPose(), 10.0)
    with pytest.raises(CalibrationError, match="looks pressed"):
        collector.prepare()
    with pytest.raises(CalibrationError, match="prepare"):
        PairCollector(sensor, camera, calibration, FunctionForce(lambda: 0.0), tmp_path / "q.tmpairs").run()
    assert math.isfinite(calibration.reference.noise_levels)


def test_field_force_proxy_reads_zero_before_a_baseline_and_the_press_after(devices):
    sensor, _ = devices
    proxy = FieldForce(sensor, ut_per_n=60.0)
    assert proxy.force_n(sensor.read_latest().t_host_s) == 0.0  # raw fields would read as a huge force
    sensor.set_baseline(sensor.expected_baseline_ut)
    sensor.set_contact(make_indenter("allen_key"), IndenterPose(), 10.0)
    reading = sensor.wait_new(1.0)
    reading = sensor.wait_new(1.0)
    assert 5.0 < proxy.force_n(reading.t_host_s) < 25.0


def test_a_killed_writer_leaves_a_readable_log(tmp_path):
    """SIGKILL mid-stream: every pair up to the last sync (at most 0.5 s before the kill) reads back."""
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "killed.tmpairs"
    code = ("import numpy as np, time\n"
            "from tactile_manip.collection.pair_log import PairLogWriter, PairRecord\n"
            f"w = PairLogWriter({str(path)!r}, {{'config': {{'tolerance_s': 0.005}}}}, sync_every_s=0.2)\n"
            "z = np.zeros((4, 4, 3), np.float32)\n"
            "k = 0\n"
            "while True:\n"
            "    w.write_pair(k, PairRecord(z, z, z.astype(bool), np.full((200, 200), k % 200, np.uint8),\n"
            "                               {'dt_s': 0.001, 'object': 'x', 'k': k}))\n"
            "    k += 1\n"
            "    print(k, flush=True) if k == 50 else None\n"
            "    time.sleep(0.002)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "50"
    time.sleep(0.5)
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    log = read_pair_log(path)
    assert len(log) >= 50
    assert [p.info["k"] for p in log.pairs] == list(range(len(log)))
    assert all(p.depth_q[0, 0] == p.info["k"] % 200 for p in log.pairs)
