"""The live topics through the Foxglove WebSocket server, as an independent client in another process sees them
(foxglove_ws_client.py: websockets and mcap-ros2-support's decoder): a TactilePublisher's every topic at the
source's rate with the estimator's values, and `tactile-manip serve --transport foxglove` as a user runs it,
services and diagnostics included; a port in use is one line, and no listener outlives the command."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("foxglove", reason="the Foxglove transport needs foxglove-sdk (extra 'foxglove')")
pytest.importorskip("websockets", reason="the test client needs websockets (extra 'dev')")
pytest.importorskip("mcap_ros2._dynamic", reason="the test client decodes with mcap-ros2-support")

from ros2_helpers import (STOPS, TOPICS, check_values, free_port, listening, serve_on_taken_port, stop_frees_port,
                          stream_a_press, wait_listening)
from ros2_helpers import serve as _serve
from ros2_helpers import wait_no_listener as nothing_listens

from tactile_manip.interop.ros2.foxglove_transport import FoxgloveTransport
from tactile_manip.interop.ros2.publisher import TactilePublisher
from tactile_manip.perception.tactile_estimator import TactileEstimator

CLIENT = Path(__file__).with_name("foxglove_ws_client.py")


def _client(url: str, out: Path, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(CLIENT), url, "--out", str(out), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if line.strip() != "subscribed":
        proc.kill()
        raise AssertionError(f"client did not start: {line!r} {proc.stderr.read()[-2000:]}")
    return proc


def _result(proc: subprocess.Popen, out: Path, timeout_s: float = 60.0) -> dict:
    _, err = proc.communicate(timeout=timeout_s)
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out.read_text())


def serve_to_client(tmp_path, seconds: float):
    """Publish a simulated pad's every reading for ``seconds`` through Foxglove while the client listens; returns
    (what the client got, the readings and estimates published, the publisher, elapsed s)."""
    est = TactileEstimator.load()
    out = tmp_path / "got.json"
    with FoxgloveTransport(port=0) as fox:
        pub = TactilePublisher(est, fox, namespace="/tactile")
        client = _client(fox.url, out, "--seconds", str(seconds + 4.0), "--wait-topics", str(len(TOPICS)))
        end = time.monotonic() + 10
        while not all(p.channel.has_sinks() for p in fox.publishers.values()):
            assert time.monotonic() < end, "the client's subscriptions never reached the server"
            time.sleep(0.01)
        published, elapsed = stream_a_press(est, pub, seconds)
        got = _result(client, out)
    return got, published, pub, elapsed


def check_stream(got, published, pub, elapsed) -> None:
    n = len(published)
    source_hz = n / elapsed  # the simulated board's 125 Hz, less what a loaded machine costs it
    channels = {c["topic"]: c for c in got["channels"]}
    stamps = [pub.stamp_ns(r.t_host_s) for r, _ in published]
    for topic, ros_type in TOPICS.items():
        assert (channels[topic]["schemaName"], channels[topic]["encoding"]) == (ros_type, "cdr"), topic
        received = got["messages"][topic]
        assert [t for t, _, _ in received] == stamps, topic   # every message, in order, no gap
        arrival = np.array([a for _, _, a in received]) * 1e-9
        rate = (n - 1) / (arrival[-1] - arrival[0])
        assert abs(rate - source_hz) / source_hz < 0.05, (topic, rate, source_hz)
    assert pub.drops == 0
    vals = {topic: [m for _, m, _ in got["messages"][topic]] for topic in TOPICS}
    check_values(vals, published, stamps)


def test_a_foxglove_client_gets_every_topic_with_the_estimators_values(tmp_path):
    check_stream(*serve_to_client(tmp_path, 2.5))


@pytest.mark.slow
def test_a_foxglove_client_gets_every_topic_for_a_minute_at_125_hz(tmp_path):
    got, published, pub, elapsed = serve_to_client(tmp_path, 60.0)
    check_stream(got, published, pub, elapsed)
    assert len(published) > 0.95 * 125 * 60  # the source kept the board's rate (a loaded machine's may not)


def serve(*args: str):
    """``tactile-manip serve --transport foxglove ARGS`` (a later ``--transport`` in ARGS wins)."""
    return _serve("--transport", "foxglove", *args)


def test_serve_over_foxglove_shows_topics_services_and_diagnostics(tmp_path):
    port = free_port()
    proc = serve("--sim", "--seconds", "9", "--foxglove-port", str(port), "--depth-hz", "5",
                 "--namespace", "/hand/left")
    out = tmp_path / "got.json"
    try:
        wait_listening(proc, port)
        client = _client(f"ws://127.0.0.1:{port}", out, "--seconds", "4", "--wait-topics", "6",
                         "--call", "/hand/left/describe_board")
        got = _result(client, out)
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert f"foxglove WebSocket server on 127.0.0.1:{port} (this machine only)" in err
    types = {c["topic"]: c["schemaName"] for c in got["channels"]}
    assert types == {"/hand/left/field_raw": "std_msgs/msg/Float32MultiArray",
                     "/hand/left/field": "std_msgs/msg/Float32MultiArray",
                     "/hand/left/angle": "tactile_manip_msgs/msg/Angle",
                     "/hand/left/contact": "tactile_manip_msgs/msg/Contact",
                     "/hand/left/depth": "sensor_msgs/msg/Image",
                     "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
    assert sorted((s["name"], s["type"]) for s in got["services"]) == [
        ("/hand/left/describe_board", "std_srvs/srv/Trigger"), ("/hand/left/tare", "std_srvs/srv/Trigger")]
    board = json.loads(got["response"]["message"]["message"])
    assert got["response"]["message"]["success"] is True and board["board"] == "supermag-4x4"
    field = [t for t, _, _ in got["messages"]["/hand/left/field"]]
    assert field == sorted(set(field)) and 0.9 * 125 * 3 < len(field)  # in order, about 4 s at 125 Hz
    depth = got["messages"]["/hand/left/depth"]
    assert 10 <= len(depth) <= 25  # 5 Hz for the 3-4 s the client listened
    img = depth[0][1]
    assert (img["height"], img["width"], img["encoding"], len(img["data"])) == (200, 200, "32FC1", 160_000)
    status = got["messages"]["/diagnostics"][-1][1]["status"][0]
    assert status["name"] == "tactile_manip: /hand/left" and status["level"] == 0, status
    assert "published" in err and nothing_listens(port)


def test_a_foxglove_port_in_use_is_one_line_and_exit_2():
    port, status, out, err = serve_on_taken_port("--foxglove-port", "--transport", "foxglove", "--sim", "--seconds", "1")
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1 and f"127.0.0.1:{port}: the port is in use" in err, err
    assert out == ""


@pytest.mark.slow  # a second client or source of what the default tests serve; CI runs it
def test_serve_over_both_transports_listens_on_both_and_foxglove_streams(tmp_path):
    pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")
    fox_port, zenoh_port = free_port(), free_port()
    proc = serve("--sim", "--seconds", "6", "--foxglove-port", str(fox_port), "--zenoh-port", str(zenoh_port),
                 "--transport", "both")
    out = tmp_path / "got.json"
    try:
        wait_listening(proc, fox_port)
        assert listening(zenoh_port)
        client = _client(f"ws://127.0.0.1:{fox_port}", out, "--seconds", "2", "--wait-topics", "5")
        got = _result(client, out)
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "zenoh (rmw_zenoh layout" in err and "foxglove WebSocket server" in err
    assert len(got["messages"]["/tactile/angle"]) > 100  # about 2 s at 125 Hz
    assert nothing_listens(fox_port) and nothing_listens(zenoh_port)


@pytest.mark.parametrize("sig, status", STOPS)
def test_no_foxglove_listener_outlives_serve(sig, status):
    port = free_port()
    stop_frees_port(("--transport", "foxglove", "--sim", "--foxglove-port", str(port)), port, sig, status)
