"""Live ROS 2 topics over Zenoh, received by an independent subscriber in another process (``zenoh_client.py``:
plain zenoh and mcap-ros2-support's decoder): every topic at the source's rate, sequence numbers without a gap,
decoded values equal to the estimator's output in this process, and the graph a ROS 2 node would see."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")
pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")

from ros2_helpers import Client, free_port

from tactile_manip.interop.ros2.publisher import TactilePublisher
from tactile_manip.interop.ros2.transport import SENSOR_DATA
from tactile_manip.interop.ros2.type_hash import type_hash
from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport, qos_keyexpr
from tactile_manip.perception.tactile_estimator import TactileEstimator
from tactile_manip.sensors import SimulatedSensor, parse_press

TOPICS = {"/tactile/field_raw": "std_msgs/msg/Float32MultiArray", "/tactile/field": "std_msgs/msg/Float32MultiArray",
          "/tactile/angle": "tactile_manip_msgs/msg/Angle", "/tactile/contact": "tactile_manip_msgs/msg/Contact"}


def _f32(x) -> float:
    return float(np.float32(x))


def _same(got, want) -> bool:
    """A decoded number equals the published one (NaN equals NaN; the client writes NaN as "nan")."""
    if want is None or (isinstance(want, float) and math.isnan(want)):
        return got == "nan"
    return got == want


def serve_to_client(tmp_path, defs, seconds: float, *, client_seconds: float | None = None):
    """Publish a simulated pad's every reading for ``seconds`` (in this process) while the client listens;
    returns (what the client got, the readings and estimates published, the publisher, elapsed s)."""
    port = free_port()
    est = TactileEstimator.load()
    published = []
    with ZenohTransport(namespace="/tactile", port=port) as zt:
        client = Client(port, defs, tmp_path / "got.json", seconds=client_seconds or seconds + 4.0)
        time.sleep(1.0)  # the client's subscription reaches this session
        pub = TactilePublisher(est, zt, namespace="/tactile")
        with SimulatedSensor() as sensor:
            noise = sensor.calibrate_baseline(125).noise_ut
            est.set_noise_floor(noise)
            sensor.play([parse_press("letter_r,t=0.2,force=10,yaw=20,rise=0.3,hold=0.5")], period_s=1.5)
            with sensor.subscribe() as frames:
                start = time.monotonic()
                while time.monotonic() - start < seconds:
                    reading = frames.get(1.0).reading
                    published.append((reading, pub.estimate(reading)))
                elapsed = time.monotonic() - start
        time.sleep(0.5)
        got = client.result()
    return got, published, pub, elapsed


def check_stream(got, published, pub, elapsed, *, values: bool, rate_tolerance: float) -> None:
    """What the client got against what was published; rates compared within ``rate_tolerance`` (a relative
    error: a few seconds on a busy machine see bursts that a minute averages out)."""
    n = len(published)
    source_hz = n / elapsed
    assert abs(source_hz - 125.0) / 125.0 < rate_tolerance, source_hz
    graph = {t["topic"]: t for t in got["tokens"] if t["kind"] == "MP"}
    nodes = [t for t in got["tokens"] if t["kind"] == "NN"]
    assert [(t["namespace"], t["node"]) for t in nodes] == [("/tactile", "tactile_manip")]
    for topic, ros_type in TOPICS.items():
        assert graph[topic]["type"] == ros_type, topic          # the topic list, with ROS 2 types
        assert graph[topic]["hash"] == type_hash(ros_type)
        assert graph[topic]["qos"] == qos_keyexpr(SENSOR_DATA) == "2::,5:,:,:,,"
        t = got["topics"][topic]
        assert t["type"] == ros_type and t["hash"] == type_hash(ros_type) and t["gid_len"] == 16
        assert t["seqs"] == list(range(1, n + 1)), topic      # every message, in order, no gap
        recv = np.array(t["recv_s"])
        rate = (n - 1) / (recv[-1] - recv[0])
        assert abs(rate - source_hz) / source_hz < rate_tolerance, (topic, rate, source_hz)
    assert pub.drops == 0
    if not values:
        return
    vals = {topic: got["topics"][topic]["values"] for topic in TOPICS}
    contacts = 0
    for i, (reading, e) in enumerate(published):
        assert vals["/tactile/field_raw"][i]["data"] == [_f32(v) for v in np.ravel(reading.field_raw_ut)]
        assert vals["/tactile/field"][i]["data"] == [_f32(v) for v in np.ravel(reading.field_ut)]
        a = vals["/tactile/angle"][i]
        assert (a["angle"], a["confidence"], a["defined"], a["plausible"]) == (
            _f32(e.angle.angle_rad), _f32(e.angle.confidence), e.angle.defined, e.angle.plausible)
        assert a["header"]["frame_id"] == "tactile_pad"
        assert a["header"]["stamp"]["sec"] * 10**9 + a["header"]["stamp"]["nanosec"] == pub.stamp_ns(reading.t_host_s)
        c, s = vals["/tactile/contact"][i], e.contact
        assert (c["in_contact"], c["plausible"]) == (e.in_contact, e.plausible)
        assert _same(c["force"]["z"], s.force_n) and _same(c["force_sigma"]["z"], s.force_sigma_n)
        if e.in_contact:
            contacts += 1
            assert _same(c["position"]["x"], s.x_mm * 1e-3) and _same(c["position"]["y"], s.y_mm * 1e-3)
            assert _same(c["position_sigma"]["x"], s.x_sigma_mm * 1e-3)
        else:
            assert c["position"]["x"] == "nan"
    assert contacts > 20  # the press was seen, so contact values were compared, not only NaNs


def test_an_independent_client_gets_every_topic_with_the_estimators_values(tmp_path, defs):
    got, published, pub, elapsed = serve_to_client(tmp_path, defs, 2.5)
    check_stream(got, published, pub, elapsed, values=True, rate_tolerance=0.25)


@pytest.mark.slow
def test_an_independent_client_gets_every_topic_for_a_minute_at_125_hz(tmp_path, defs):
    got, published, pub, elapsed = serve_to_client(tmp_path, defs, 60.0)
    assert len(published) > 0.95 * 125 * 60
    check_stream(got, published, pub, elapsed, values=True, rate_tolerance=0.05)
