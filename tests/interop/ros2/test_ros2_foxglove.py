"""The Foxglove WebSocket transport: an independent client in another process (foxglove_ws_client.py beside this:
the `websockets` package and mcap-ros2-support's decoder, nothing of ours) receives every message with its ROS 2
schema, values equal to what was published and no gap; a service answers in CDR; slow and vanished clients
never hold up publishing; where it listens is checked before anything starts."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.errors import ConfigError
from tactile_manip.interop import cdr
from tactile_manip.interop.ros2.foxglove_transport import (
    FoxgloveTransport,
    PortInUseError,
    is_loopback,
)
from tactile_manip.interop.ros_msgs import MESSAGES

CLIENT = Path(__file__).with_name("foxglove_ws_client.py")
RATE_HZ = 125.0
TOPICS = {"/tactile/pad0/contact_point": "geometry_msgs/msg/PointStamped",
          "/tactile/pad0/wrench": "geometry_msgs/msg/WrenchStamped",
          "/tactile/pad0/field": "std_msgs/msg/Float32MultiArray",
          "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}


def _needs_sdk_and_client():
    pytest.importorskip("foxglove", reason="the Foxglove transport needs foxglove-sdk (extra 'foxglove')")
    pytest.importorskip("websockets", reason="the test client needs websockets (extra 'dev')")
    pytest.importorskip("mcap_ros2._dynamic", reason="the test client decodes with mcap-ros2-support")


def _header(seq: int) -> dict:
    stamp_ns = 1_700_000_000_000_000_000 + seq * 8_000_000
    return {"stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000}, "frame_id": "pad0"}


def _message(type_name: str, seq: int, rng: np.random.Generator) -> dict:
    """One message of each topic's type; ``seq`` is in its header stamp (and the point's x)."""
    if type_name == "geometry_msgs/msg/PointStamped":
        return {"header": _header(seq), "point": {"x": float(seq), "y": rng.normal(), "z": rng.normal()}}
    if type_name == "geometry_msgs/msg/WrenchStamped":
        f, t = rng.normal(size=3), rng.normal(size=3)
        return {"header": _header(seq), "wrench": {"force": dict(zip("xyz", f.tolist())),
                                                   "torque": dict(zip("xyz", t.tolist()))}}
    if type_name == "std_msgs/msg/Float32MultiArray":
        data = rng.normal(0, 100, 48).astype(np.float32)
        return {"layout": {"dim": [{"label": "taxels", "size": 16, "stride": 48},
                                   {"label": "axes", "size": 3, "stride": 3}], "data_offset": 0}, "data": data}
    return {"header": _header(seq), "status": [
        {"level": seq % 4, "name": "tactile_manip: pad0", "message": f"reading {seq}",
         "hardware_id": "sim", "values": [{"key": "seq", "value": str(seq)}]}]}


def _table(type_name: str) -> str:
    pkg, _, name = type_name.split("/")
    return f"{pkg}/{name}"


def _json_like(msg):
    """What the client writes for ``msg``: numpy arrays as lists, bytes as lists of ints."""
    if isinstance(msg, dict):
        return {k: _json_like(v) for k, v in msg.items()}
    if isinstance(msg, list):
        return [_json_like(v) for v in msg]
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, bytes):
        return list(msg)
    return msg


def _start_client(url: str, out: Path, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(CLIENT), url, "--out", str(out), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.strip() == "subscribed", line + proc.stderr.read()
    return proc


def _wait_subscribed(pubs, timeout_s: float = 10.0) -> None:
    end = time.monotonic() + timeout_s
    while not all(p.channel.has_sinks() for p in pubs):
        assert time.monotonic() < end, "the client's subscriptions never reached the server"
        time.sleep(0.01)


def _stream(transport: FoxgloveTransport, seconds: float, *, seed: int = 0) -> dict[str, list[dict]]:
    """Publish every topic at 125 Hz for ``seconds`` (with the source's timing); return what was published."""
    rng = np.random.default_rng(seed)
    pubs = {t: transport.publishers[t] for t in TOPICS}
    sent: dict[str, list[dict]] = {t: [] for t in TOPICS}
    n = round(seconds * RATE_HZ)
    t0 = time.perf_counter()
    for seq in range(1, n + 1):
        delay = t0 + seq / RATE_HZ - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        for topic, type_name in TOPICS.items():
            msg = _message(type_name, seq, rng)
            pubs[topic].publish(cdr.encode(MESSAGES, _table(type_name), msg), 1_000 + seq, seq)
            sent[topic].append(msg)
    return sent


def _advertise_all(transport: FoxgloveTransport) -> list:
    return [transport.advertise(topic, type_name) for topic, type_name in TOPICS.items()]


def test_only_loopback_unless_allowed_and_the_description_says_so():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    with pytest.raises(ConfigError, match=r"0\.0\.0\.0 is not a loopback address.*--allow-remote"):
        FoxgloveTransport(host="0.0.0.0")
    remote = FoxgloveTransport(host="0.0.0.0", allow_remote=True)
    assert "OTHER MACHINES CAN CONNECT" in remote.description() and remote.url == "ws://127.0.0.1:8765"
    assert "this machine only" in FoxgloveTransport().description()
    with pytest.raises(ConfigError, match="port"):
        FoxgloveTransport(port=70000)
    with pytest.raises(ConfigError, match="backlog"):
        FoxgloveTransport(backlog=0)


def test_a_port_in_use_is_one_clear_error_and_close_frees_the_port():
    pytest.importorskip("foxglove", reason="the Foxglove transport needs foxglove-sdk (extra 'foxglove')")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(PortInUseError, match=f"127.0.0.1:{port}: the port is in use"):
            FoxgloveTransport(port=port).start()
    with FoxgloveTransport(port=0) as t:
        port = t.port
        assert port > 0
        with pytest.raises(ValueError, match="advertised already"):
            t.advertise("/a", "std_msgs/msg/String")
            t.advertise("/a", "std_msgs/msg/String")
    assert t.closed
    with socket.socket() as s:  # nothing listens there any more
        s.bind(("127.0.0.1", port))
    t.close()  # idempotent


def test_an_independent_client_gets_every_topic_decoded_with_equal_values_and_the_service_answers(tmp_path):
    _needs_sdk_and_client()
    calls = []

    def tare(request: bytes) -> bytes:
        calls.append(request)
        return cdr.encode(MESSAGES, "std_srvs/Trigger_Response", {"success": True, "message": "tared"})

    with FoxgloveTransport(port=0) as transport:
        pubs = _advertise_all(transport)
        transport.add_service("/tactile/pad0/tare", "std_srvs/srv/Trigger", tare)
        out = tmp_path / "got.json"
        client = _start_client(transport.url, out, "--seconds", "4", "--wait-topics", str(len(TOPICS)),
                               "--call", "/tactile/pad0/tare")
        _wait_subscribed(pubs)
        sent = _stream(transport, 2.0)
        assert client.wait(timeout=30) == 0, client.stderr.read()
    got = json.loads(out.read_text())

    assert {c["topic"]: (c["schemaName"], c["schemaEncoding"], c["encoding"]) for c in got["channels"]} == \
        {t: (ty, "ros2msg", "cdr") for t, ty in TOPICS.items()}
    assert got["services"] == [{"name": "/tactile/pad0/tare", "type": "std_srvs/srv/Trigger"}]
    assert got["response"]["message"] == {"success": True, "message": "tared"}
    assert calls == [b"\x00\x01\x00\x00\x00"]  # the empty request: its one placeholder byte
    for topic in TOPICS:
        received = got["messages"][topic]
        assert len(received) == len(sent[topic]) == 250, topic
        assert [t for t, _, _ in received] == [1_000 + seq for seq in range(1, 251)], topic  # in order, no gap
        assert [m for _, m, _ in received] == [_json_like(m) for m in sent[topic]], topic
    assert all(p.drops == 0 and p.sent == 250 for p in pubs)


def test_a_slow_client_and_a_vanished_one_never_hold_up_publishing(tmp_path):
    _needs_sdk_and_client()
    big = {"header": _header(0), "height": 200, "width": 200, "encoding": "32FC1", "is_bigendian": 0,
           "step": 800, "data": bytes(160_000)}
    image = cdr.encode(MESSAGES, "sensor_msgs/Image", big)
    with FoxgloveTransport(port=0, backlog=8) as transport:
        pub = transport.advertise("/tactile/pad0/depth", "sensor_msgs/msg/Image")
        # a client that reads 5 messages, then nothing for 30 s: publishing must not wait for it
        slow = _start_client(transport.url, tmp_path / "slow.json", "--seconds", "60", "--stall-after", "5",
                             "--stall-s", "30")
        _wait_subscribed([pub])
        for seq in range(1, 401):  # 64 MB, far more than the client's socket and queue hold
            pub.publish(image, seq, seq)
        assert slow.poll() is None  # still stalled: every publish returned while it read nothing
        assert pub.sent == 400 and pub.drops == 0
        deadline = time.monotonic() + 35  # the SDK reports the full queue in its log (at most every 30 s)
        while transport.slow_client_events == 0 and time.monotonic() < deadline:
            pub.publish(image, 0, 0)
            time.sleep(0.05)
        assert transport.slow_client_events >= 1
        slow.kill()

        # a client killed mid-stream: the server drops it, publishing goes on, a new client is served
        gone = _start_client(transport.url, tmp_path / "gone.json", "--seconds", "60")
        _wait_subscribed([pub])
        for seq in range(1, 51):
            pub.publish(image, seq, seq)
        gone.send_signal(signal.SIGKILL)
        gone.wait(timeout=10)
        for seq in range(51, 201):
            pub.publish(image, seq, seq)
        assert pub.drops == 0
        fresh = _start_client(transport.url, tmp_path / "fresh.json", "--seconds", "2")
        _wait_subscribed([pub])
        for seq in range(1, 11):  # at the board's rate, which a reading client keeps up with
            pub.publish(image, 5_000 + seq, seq)
            time.sleep(1 / RATE_HZ)
        assert fresh.wait(timeout=30) == 0, fresh.stderr.read()
    got = json.loads((tmp_path / "fresh.json").read_text())
    assert [t for t, _, _ in got["messages"]["/tactile/pad0/depth"]] == [5_000 + s for s in range(1, 11)]


@pytest.mark.slow
def test_sixty_seconds_at_125_hz_arrive_whole_at_the_source_rate(tmp_path):
    _needs_sdk_and_client()
    seconds = 60.0
    with FoxgloveTransport(port=0) as transport:
        pubs = _advertise_all(transport)
        out = tmp_path / "got.json"
        client = _start_client(transport.url, out, "--seconds", str(seconds + 5), "--wait-topics",
                               str(len(TOPICS)))
        _wait_subscribed(pubs)
        t0 = time.time_ns()
        sent = _stream(transport, seconds, seed=1)
        source_hz = (len(sent["/diagnostics"]) - 1) / ((time.time_ns() - t0) * 1e-9)
        assert client.wait(timeout=120) == 0, client.stderr.read()
    got = json.loads(out.read_text())
    n = round(seconds * RATE_HZ)
    for topic in TOPICS:
        received = got["messages"][topic]
        assert [t for t, _, _ in received] == [1_000 + seq for seq in range(1, n + 1)], topic  # none missing
        assert [m for _, m, _ in received] == [_json_like(m) for m in sent[topic]], topic
        # the rate the client saw them arrive at, against the rate they were published at
        received_hz = (len(received) - 1) / ((received[-1][2] - received[0][2]) * 1e-9)
        assert abs(received_hz - source_hz) / source_hz < 0.05, (topic, received_hz, source_hz)


def test_a_slow_client_shows_on_diagnostics_and_in_the_summary():
    import threading

    from tactile_manip.interop.ros2 import messages as m
    from tactile_manip.interop.ros2.publisher import TactilePublisher
    from tactile_manip.interop.ros2.serve import Pad, Server, summary
    from tactile_manip.interop.ros2.transport import MemoryTransport
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import SimulatedSensor

    class SlowClients(MemoryTransport):
        slow_client_events = 0  # what FoxgloveTransport counts from its SDK's log

    est = TactileEstimator.load()
    mt = SlowClients()
    with SimulatedSensor() as sensor:
        pad = Pad(sensor, TactilePublisher(est, mt, namespace="/tactile"))
        server = Server([pad], est, mt)
        runner = threading.Thread(target=server.run, kwargs={"seconds": 3.5})
        runner.start()
        time.sleep(1.2)
        mt.slow_client_events = 1  # a client's queue overflowed
        runner.join()
    statuses = [cdr.decode(MESSAGES, m.DIAGNOSTICS_TYPE, x.cdr)["status"][0] for x in mt.on("/diagnostics")]
    levels = [s["level"] for s in statuses]
    warned = [s for s in statuses if s["level"] == m.WARN]
    assert len(warned) == 1 and "fell behind and lost messages" in warned[0]["message"], levels
    assert {"key": "slow_client_events", "value": "1"} in warned[0]["values"]
    after = statuses[statuses.index(warned[0]) + 1:]
    assert after and all("fell behind" not in s["message"] for s in after)  # reported once, not again
    assert all({"key": "slow_client_events", "value": "1"} in s["values"] for s in after)  # the count stays
    assert "1 slow-client events" in summary(server, "memory", 3.5)
