"""Live ROS 2 topics over Zenoh, received by an independent subscriber in another process (``zenoh_client.py``:
plain zenoh and mcap-ros2-support's decoder): every topic at the source's rate, sequence numbers without a gap,
decoded values equal to the estimator's output in this process, and the graph a ROS 2 node would see."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")
pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")

from ros2_helpers import TOPICS, Client, check_values, free_port, stream_a_press

from tactile_manip.interop.ros2.publisher import TactilePublisher
from tactile_manip.interop.ros2.transport import SENSOR_DATA
from tactile_manip.interop.ros2.type_hash import type_hash
from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport, qos_keyexpr
from tactile_manip.perception.tactile_estimator import TactileEstimator

def serve_to_client(tmp_path, defs, seconds: float, *, client_seconds: float | None = None):
    """Publish a simulated pad's every reading for ``seconds`` (in this process) while the client listens;
    returns (what the client got, the readings and estimates published, the publisher, elapsed s)."""
    port = free_port()
    est = TactileEstimator.load()
    with ZenohTransport(namespace="/tactile", port=port) as zt:
        client = Client(port, defs, tmp_path / "got.json", seconds=client_seconds or seconds + 4.0)
        time.sleep(1.0)  # the client's subscription reaches this session
        pub = TactilePublisher(est, zt, namespace="/tactile")
        published, elapsed = stream_a_press(est, pub, seconds)
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
    check_values(vals, published, [pub.stamp_ns(r.t_host_s) for r, _ in published], frame_id="tactile_pad")


def test_an_independent_client_gets_every_topic_with_the_estimators_values(tmp_path, defs):
    got, published, pub, elapsed = serve_to_client(tmp_path, defs, 2.5)
    check_stream(got, published, pub, elapsed, values=True, rate_tolerance=0.25)


@pytest.mark.slow
def test_an_independent_client_gets_every_topic_for_a_minute_at_125_hz(tmp_path, defs):
    got, published, pub, elapsed = serve_to_client(tmp_path, defs, 60.0)
    assert len(published) > 0.95 * 125 * 60
    check_stream(got, published, pub, elapsed, values=True, rate_tolerance=0.05)
