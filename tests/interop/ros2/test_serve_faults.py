"""Faults: a subscriber that is slow or vanishes never holds the reading loop (what cannot be sent is dropped
and counted), and a sensor that stops is reported on /diagnostics, with no estimate published meanwhile."""

from __future__ import annotations

import threading
import time

import pytest

from tactile_manip.interop import cdr
from tactile_manip.interop.ros2 import messages as m
from tactile_manip.interop.ros2.publisher import TactilePublisher
from tactile_manip.interop.ros2.serve import Pad, Server
from tactile_manip.interop.ros2.transport import MemoryTransport, SendQueue
from tactile_manip.interop.ros_msgs import MESSAGES
from tactile_manip.perception.tactile_estimator import TactileEstimator
from tactile_manip.sensors import SimulatedSensor


def test_a_send_that_blocks_never_blocks_put_and_every_drop_is_counted():
    release, taken = threading.Event(), threading.Event()
    sent, dropped = [], []

    def send(item):
        taken.set()
        release.wait()  # a link that does not drain: the transport's back-pressure
        sent.append(item)

    q = SendQueue(send, max_items=10, on_drop=dropped.append)
    q.put(0)
    assert taken.wait(5.0)  # item 0 is in flight, held by the link
    for i in range(1, 1000):
        q.put(i)  # returns at once although nothing is sent
    assert len(dropped) == 1000 - 10 - 1  # one item in flight, ten queued, the oldest dropped
    assert dropped == list(range(1, 990))  # the oldest go first; the newest wait
    release.set()
    q.close()
    assert sent == [0, *range(990, 1000)] and q.sent == 11


def _serve_with_client(tmp_path, defs, client_args, kill_after_s=None, seconds=3.0):
    pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")
    pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    from ros2_helpers import Client, free_port

    from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport

    port = free_port()
    est = TactileEstimator.load()
    frames_seen = 0
    with ZenohTransport(namespace="/tactile", port=port, max_queued=64) as zt:
        client = Client(port, defs, tmp_path / "got.json", seconds=seconds + 3, extra=client_args)
        time.sleep(1.0)
        pub = TactilePublisher(est, zt, namespace="/tactile")
        with SimulatedSensor() as sensor, sensor.subscribe() as frames:
            start = time.monotonic()
            killed = False
            while time.monotonic() - start < seconds:
                pub.estimate(frames.get(1.0).reading)
                frames_seen += 1
                if kill_after_s is not None and not killed and time.monotonic() - start > kill_after_s:
                    client.kill()  # the subscriber vanishes mid-stream
                    killed = True
            overflowed = frames.overflowed
        queued = zt.queued
        publishers = zt.publishers
        got = None if killed else client.result()
    return pub, publishers, frames_seen, overflowed, queued, got


@pytest.mark.parametrize("case", ["slow", "vanishes"])
def test_a_slow_or_vanished_subscriber_costs_drops_not_readings(tmp_path, defs, case):
    args = ("--slow-ms", "20") if case == "slow" else ()
    pub, publishers, frames_seen, overflowed, queued, got = _serve_with_client(
        tmp_path, defs, args, kill_after_s=1.0 if case == "vanishes" else None)
    assert overflowed == 0                     # the loop took every frame the sensor gave
    assert pub.readings == frames_seen > 300   # and published each one
    for p in publishers:                       # every message was sent, dropped (and counted) or is still queued
        assert p.sent + p.drops <= pub.readings <= p.sent + p.drops + queued
    if got is not None:  # the slow subscriber saw fewer messages than were sent: its gaps are in the sequence
        seqs = got["topics"]["/tactile/field"]["seqs"]
        assert seqs == sorted(seqs) and len(seqs) <= pub.readings


def test_a_sensor_that_stops_is_stale_on_diagnostics_and_publishes_nothing_meanwhile():
    est = TactileEstimator.load()
    mt = MemoryTransport()
    with SimulatedSensor() as sensor:
        pad = Pad(sensor, TactilePublisher(est, mt, namespace="/tactile"))
        server = Server([pad], est, mt, stale_s=0.2)
        runner = threading.Thread(target=server.run, kwargs={"seconds": 2.5})
        runner.start()
        time.sleep(0.6)
        sensor.stall()
        stalled_s = time.monotonic()
        time.sleep(0.9)
        resumed_s = time.monotonic()
        sensor.resume()
        runner.join()
    statuses = [cdr.decode(MESSAGES, m.DIAGNOSTICS_TYPE, x.cdr)["status"][0] for x in mt.on("/diagnostics")]
    levels = [s["level"] for s in statuses]
    assert m.STALE in levels and levels[-1] == m.OK, levels
    stale = next(s for s in statuses if s["level"] == m.STALE)
    assert stale["message"].startswith("no frame for") and stale["hardware_id"] == "simulated"
    offset_ns = pad.publisher.stamp_ns(0)  # a stamp less the reading's monotonic time
    angles = [cdr.decode(MESSAGES, "tactile_manip_msgs/Angle", x.cdr)["header"]["stamp"] for x in mt.on("/tactile/angle")]
    readings_s = [(a["sec"] * 10**9 + a["nanosec"] - offset_ns) / 1e9 for a in angles]
    during = [t for t in readings_s if stalled_s + 0.05 < t < resumed_s - 0.05]
    assert during == [] and len(readings_s) > 150  # nothing stale went out; streaming before and after
