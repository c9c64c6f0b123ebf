"""``tactile-manip serve`` as a user runs it: the graph, services and diagnostics an independent client sees;
bad input refused in one line with exit 2; and no listener left behind by Ctrl-C, SIGTERM or SIGKILL."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")

from ros2_helpers import (STOPS, Client, free_port, serve, serve_on_taken_port, stop_frees_port, wait_listening,
                          wait_no_listener)


def test_serve_sim_shows_topics_services_and_diagnostics_to_a_client(tmp_path, defs):
    pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    port = free_port()
    proc = serve("--sim", "--seconds", "9", "--zenoh-port", str(port), "--depth-hz", "5", "--namespace", "/hand/left")
    try:
        wait_listening(proc, port)
        client = Client(port, defs, tmp_path / "got.json", seconds=4.0,
                        extra=("--call", "/hand/left/describe_board", "--call", "/hand/left/tare"))
        got = client.result()
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    kinds = {(t["kind"], t.get("topic"), t.get("type")) for t in got["tokens"]}
    for name, ros_type in [("field_raw", "std_msgs/msg/Float32MultiArray"), ("field", "std_msgs/msg/Float32MultiArray"),
                           ("angle", "tactile_manip_msgs/msg/Angle"), ("contact", "tactile_manip_msgs/msg/Contact"),
                           ("depth", "sensor_msgs/msg/Image")]:
        assert ("MP", f"/hand/left/{name}", ros_type) in kinds
    assert ("MP", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray") in kinds
    assert ("SS", "/hand/left/tare", "std_srvs/srv/Trigger") in kinds
    assert ("SS", "/hand/left/describe_board", "std_srvs/srv/Trigger") in kinds
    depth = got["topics"]["/hand/left/depth"]
    assert 5 <= len(depth["seqs"]) <= 25  # 5 Hz for the 3-4 s the client listened
    img = depth["values"][0]
    assert (img["height"], img["width"], img["encoding"]) == (200, 200, "32FC1")
    diag = got["topics"]["/diagnostics"]["values"]
    status = diag[-1]["status"][0]
    assert status["name"] == "tactile_manip: /hand/left" and status["level"] in (0, 1), status  # OK (or WARN: a
    assert status["hardware_id"] == "simulated"  # frame lost on a busy machine), streaming either way
    described = got["calls"]["/hand/left/describe_board"]
    assert described["response"]["success"] is True and described["reply_seq"] == 7
    assert described["reply_gid"] == list(range(16))
    board = json.loads(described["response"]["message"])
    assert board["board"] == "supermag-4x4" and board["topics"]["/hand/left/angle"] == "tactile_manip_msgs/msg/Angle"
    tare = got["calls"]["/hand/left/tare"]["response"]
    assert isinstance(tare["success"], bool) and tare["message"]  # a pressed pad refuses, a free one re-zeroes
    assert "published" in err and wait_no_listener(port)


@pytest.mark.parametrize("args, says", [
    (("--namespace", "/tactile/2nd"), "token '2nd': a token may not start with a digit"),
    (("--namespace", "/a__b"), "holds '__'"),
    (("--namespace", "/tactile/"), "no trailing '/'"),
    (("--bind", "0.0.0.0"), "add --allow-remote"),
    (("--node", "my-node"), "character '-'"),
    (("--depth-hz", "5", "--model", "none"), "decodes no depth image"),
])
def test_bad_input_is_one_line_and_exit_2(args, says):
    proc = serve("--sim", "--seconds", "1", "--zenoh-port", str(free_port()), *args)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2, err
    assert len(err.strip().splitlines()) == 1 and says in err, err
    assert out == ""


def test_a_port_in_use_is_one_line_and_exit_2():
    _, status, _, err = serve_on_taken_port("--zenoh-port", "--sim", "--seconds", "1")
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1 and "port is in use" in err and "--connect" in err, err


@pytest.mark.parametrize("sig, status", STOPS)
def test_no_listener_outlives_serve(sig, status):
    port = free_port()
    stop_frees_port(("--sim", "--zenoh-port", str(port)), port, sig, status)


@pytest.mark.slow  # a second client or source of what the default tests serve; CI runs it
def test_serve_replays_a_recording_as_several_pads(tmp_path, defs):
    pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    rec = tmp_path / "press.tmrec"
    done = subprocess.run([sys.executable, "-m", "tactile_manip", "record", "--sim", "--out", str(rec), "--seconds", "3"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    port = free_port()
    proc = serve("--replay", str(rec), "--pads", "2", "--seconds", "7", "--zenoh-port", str(port), "--node", "hand")
    try:
        wait_listening(proc, port)
        got = Client(port, defs, tmp_path / "got.json", seconds=3.0).result()
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    nodes = [(t["namespace"], t["node"]) for t in got["tokens"] if t["kind"] == "NN"]
    assert nodes == [("/tactile", "hand")]
    for pad in ("pad0", "pad1"):
        seqs = got["topics"][f"/tactile/{pad}/angle"]["seqs"]
        assert len(seqs) > 100 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # joined mid-stream: no gap
    statuses = {s["name"] for d in got["topics"]["/diagnostics"]["values"] for s in d["status"]}
    assert statuses == {"tactile_manip: /tactile/pad0", "tactile_manip: /tactile/pad1"}
    assert "from 2 pad(s)" in err


@pytest.mark.slow  # a second client or source of what the default tests serve; CI runs it
def test_serve_joins_a_zenoh_router_instead_of_listening(tmp_path, defs):
    """Where a router holds the port (rmw_zenohd on a ROS 2 machine), serve connects to it and listens nowhere;
    a client of the router sees the graph and the topics."""
    pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    import zenoh

    port = free_port()
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    router = zenoh.open(config)
    try:
        proc = serve("--sim", "--seconds", "8", "--no-listen", "--connect", f"tcp/127.0.0.1:{port}")
        try:
            said = [proc.stderr.readline() for _ in range(2)]  # where it connected; then that it streams
            client = Client(port, defs, tmp_path / "got.json", seconds=3.0)
            got = client.result()
        finally:
            _, err = proc.communicate(timeout=60)
            err = "".join(said) + err
    finally:
        router.close()
    assert proc.returncode == 0, err
    assert f"connected to tcp/127.0.0.1:{port}" in err and "listening" not in err
    assert ("MP", "/tactile/angle") in {(t["kind"], t.get("topic")) for t in got["tokens"]}
    seqs = got["topics"]["/tactile/angle"]["seqs"]
    assert len(seqs) > 100 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))
