"""``tactile-manip serve`` seen by zenoh-ros2-sdk, a Python implementation of rmw_zenoh's client side written by
others, given our message definitions offline (``sdk_client.py``, in its own process): its own type hashes
find our topics and our service, and it decodes what we publish."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (extra 'ros2')")
pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk is not installed (CI installs it)")

from ros2_helpers import free_port, serve, wait_listening  # noqa: E402

from tactile_manip.interop.ros2.messages import msg_text  # noqa: E402
from tactile_manip.interop.ros2.type_hash import type_hash  # noqa: E402
from tactile_manip.interop.ros_msgs import MESSAGES  # noqa: E402

SDK_CLIENT = Path(__file__).resolve().parent / "sdk_client.py"


@pytest.mark.slow  # a second client or source of what the default tests serve; CI runs it
def test_zenoh_ros2_sdk_receives_every_topic_and_calls_a_service(tmp_path):
    defs = tmp_path / "defs.json"  # the .msg text of every type, as a ROS 2 machine's packages hold it
    defs.write_text(json.dumps({t.replace("/", "/msg/"): msg_text(t) for t in MESSAGES if not t.endswith("_Request")}))
    port = free_port()
    proc = serve("--sim", "--seconds", "10", "--zenoh-port", str(port))
    try:
        wait_listening(proc, port)
        client = subprocess.run([sys.executable, str(SDK_CLIENT), "--port", str(port), "--defs", str(defs),
                                 "--seconds", "3", "--out", str(tmp_path / "got.json")],
                                capture_output=True, text=True, timeout=120)
        assert client.returncode == 0, client.stderr[-3000:]
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    got = json.loads((tmp_path / "got.json").read_text())
    for ros_type, theirs in got["hashes"].items():
        assert theirs == type_hash(ros_type), ros_type  # two implementations of REP-2011 agree
    assert got["service_hash"] == type_hash("std_srvs/srv/Trigger")
    for topic, t in got["topics"].items():
        assert t["count"] > 150, (topic, t["count"])  # about 3 s at 125 Hz
    assert len(got["topics"]["/tactile/field"]["last"]["data"]) == 48
    angle = got["topics"]["/tactile/angle"]["last"]
    assert angle["header"]["frame_id"] == "tactile_pad" and 0.0 <= angle["confidence"] <= 1.0
    contact = got["topics"]["/tactile/contact"]["last"]
    assert set(contact) >= {"in_contact", "plausible", "position", "position_sigma", "force", "force_sigma"}
    assert got["describe"]["success"] is True
    assert json.loads(got["describe"]["message"])["board"] == "supermag-4x4"
