"""MCAP export: our CDR encoder against hand-made bytes and an independent ROS 2 codec, and episodes written
then read back with the mcap reader, every message decoded with exact values."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from tactile_manip.interop import cdr
from tactile_manip.interop.mcap_export import FINGER_NAMES, field_message, image_message, write_mcap
from tactile_manip.interop.rerun_log import JOINT_NAMES
from tactile_manip.interop.ros_msgs import MESSAGES, from_json, json_schema, ros2msg_text, schema_name
from tactile_manip.interop.timeline import episode_starts_s, first_host_time_s


def _joint_state():
    return {"header": {"stamp": {"sec": 3, "nanosec": 7}, "frame_id": "ab"}, "name": ["j1", "j22", "j333"],
            "position": np.array([0.5, -1.25, 3.0]), "velocity": np.zeros(0), "effort": np.array([2.0])}


def test_cdr_bytes_of_a_joint_state_follow_the_alignment_rules():
    data = cdr.encode(MESSAGES, "sensor_msgs/JointState", _joint_state())
    expected = (b"\x00\x01\x00\x00"                        # CDR little endian; offsets count from here
                + struct.pack("<iI", 3, 7)                # stamp, 0..7
                + struct.pack("<I", 3) + b"ab\0"          # frame_id 8..14: the length counts the NUL
                + b"\0" + struct.pack("<I", 3)            # pad to 16; 3 names, 16..19
                + struct.pack("<I", 3) + b"j1\0"          # 20..26
                + b"\0" + struct.pack("<I", 4) + b"j22\0"  # pad to 28; 28..35
                + struct.pack("<I", 5) + b"j333\0"        # 36..44
                + b"\0" * 3 + struct.pack("<I", 3)        # pad to 48; 3 positions, 48..51
                + b"\0" * 4 + struct.pack("<3d", 0.5, -1.25, 3.0)  # pad to 56 (8-aligned); 56..79
                + struct.pack("<I", 0)                    # velocity: empty, so no padding after its count
                + struct.pack("<I", 1)                    # effort count at 84
                + struct.pack("<d", 2.0))                 # 88: already 8-aligned
    assert data == expected


def test_cdr_round_trip_of_every_message_type():
    rng = np.random.default_rng(0)
    msgs = {
        "std_msgs/Float32MultiArray": field_message(rng.normal(0, 100, (4, 4, 3))),
        "sensor_msgs/Image": image_message(rng.uniform(0, 2, (5, 3)), 1_234_567_890_123, "mbts_pad"),
        "sensor_msgs/JointState": _joint_state(),
        "std_msgs/Float32": {"data": np.float32(0.3).item()},
        "std_msgs/String": {"data": "turn"},
    }
    for type_name, msg in msgs.items():
        back = cdr.decode(MESSAGES, type_name, cdr.encode(MESSAGES, type_name, msg))
        assert _same(back, msg), type_name


def test_cdr_refuses_damage_and_what_it_cannot_encode():
    data = cdr.encode(MESSAGES, "std_msgs/String", {"data": "grasp"})
    with pytest.raises(ValueError, match="ends at byte"):
        cdr.decode(MESSAGES, "std_msgs/String", data[:-2])
    with pytest.raises(ValueError, match="header"):
        cdr.decode(MESSAGES, "std_msgs/String", b"\x00\x00" + data[2:])
    with pytest.raises(ValueError, match="NUL"):
        cdr.encode(MESSAGES, "std_msgs/String", {"data": "a\0b"})
    with pytest.raises(ValueError, match="unsupported"):
        cdr.split_type("float64[<=9]")


def test_an_independent_ros2_codec_writes_the_same_bytes_and_reads_ours():
    dyn = pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    rng = np.random.default_rng(0)
    msgs = {"sensor_msgs/JointState": _joint_state(),
            "std_msgs/Float32MultiArray": field_message(rng.normal(0, 100, (4, 4, 3))),
            "sensor_msgs/Image": image_message(rng.uniform(0, 2, (3, 2)), 5_000_000_001, "mbts_pad")}
    for type_name, msg in msgs.items():
        name = schema_name(type_name)
        ours = cdr.encode(MESSAGES, type_name, msg)
        theirs = dyn.serialize_dynamic(name, ros2msg_text(type_name))[name](_plain(msg))
        assert bytes(theirs) == ours, type_name
        decoded = dyn.generate_dynamic(name, ros2msg_text(type_name))[name](ours)
        assert _same(_plain_obj(decoded), _plain(msg)), type_name


def test_json_schema_and_ros2msg_text_describe_the_types():
    text = ros2msg_text("sensor_msgs/Image")
    assert text.startswith("std_msgs/Header header\nuint32 height\n")
    assert "=" * 80 + "\nMSG: std_msgs/Header\n" in text and "MSG: builtin_interfaces/Time\nint32 sec" in text
    schema = json_schema("sensor_msgs/Image")
    assert schema["properties"]["data"] == {"type": "string", "contentEncoding": "base64"}
    assert schema["properties"]["header"]["properties"]["stamp"]["properties"]["sec"] == {"type": "integer"}


@pytest.mark.parametrize("ros2, encoding", [(False, "cdr"), (True, "cdr"), (False, "json")])
def test_every_message_reads_back_with_exact_values(tmp_path, episodes, ros2, encoding):
    mcap_reader = pytest.importorskip("mcap.reader", reason="MCAP export needs mcap (extra 'mcap')")
    out = tmp_path / "run.mcap"
    summary = write_mcap(episodes, out, ros2=ros2, encoding=encoding)
    assert summary["frames"] == 80 and summary["topics"]["/tactile/mbts/field"] == 80
    with open(out, "rb") as f:
        reader = mcap_reader.make_reader(f)
        header = reader.get_header()
        assert header.profile == ("ros2" if ros2 else "")
        by_topic: dict[str, list] = {}
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == encoding
            assert schema.encoding == ("ros2msg" if encoding == "cdr" else "jsonschema")
            assert ("offered_qos_profiles" in channel.metadata) == ros2
            type_name = schema.name.replace("/msg/", "/")
            msg = (cdr.decode(MESSAGES, type_name, message.data) if encoding == "cdr"
                   else from_json(type_name, json.loads(message.data)))
            by_topic.setdefault(channel.topic, []).append((message.log_time, message.publish_time, msg))
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    frames = [f for e in episodes for f in e.frames]
    base = first_host_time_s(episodes)
    ns = [round((base + s) * 1e9) + round(f.t_s * 1e9)
          for s, e in zip(episode_starts_s(episodes), episodes) for f in e.frames]

    field = by_topic["/tactile/mbts/field"]
    assert [t for t, _, _ in field] == ns == [p for _, p, _ in field]
    for (_, _, msg), f in zip(field, frames):
        dims = [(d["label"], d["size"], d["stride"]) for d in msg["layout"]["dim"]]
        assert dims == [("taxels", 16, 48), ("axes", 3, 3)]
        np.testing.assert_array_equal(msg["data"].reshape(4, 4, 3), f.field_ut)
    odd = [(t, f) for t, f in zip(ns, frames) if math.isfinite(f.angle_rad)]
    assert [(t, m["data"]) for t, _, m in by_topic["/tactile/mbts/angle"]] == \
        [(t, float(np.float32(f.angle_rad))) for t, f in odd]
    assert [m["data"] for _, _, m in by_topic["/tactile/mbts/confidence"]] == \
        [float(np.float32(f.confidence)) for _, f in odd]
    depth = [(t, f) for t, f in zip(ns, frames) if f.depth_mm is not None]
    assert len(by_topic["/tactile/mbts/depth"]) == len(depth) == 8
    for (t, _, msg), (t_frame, f) in zip(by_topic["/tactile/mbts/depth"], depth):
        assert t == t_frame and msg["header"]["stamp"] == {"sec": t // 10**9, "nanosec": t % 10**9}
        assert (msg["encoding"], msg["is_bigendian"], msg["step"]) == ("32FC1", 0, msg["width"] * 4)
        image = np.frombuffer(msg["data"], "<f4").reshape(msg["height"], msg["width"])
        np.testing.assert_array_equal(image, f.depth_mm)
    assert len(by_topic["/tactile/vbts/depth"]) == 4
    joints = by_topic["/joint_states"]
    assert len(joints) == 80 and joints[0][2]["name"] == [*JOINT_NAMES, *FINGER_NAMES]
    for (_, _, msg), f in zip(joints, frames):
        np.testing.assert_array_equal(msg["position"], [*f.joints_rad, f.gripper_width_m / 2, f.gripper_width_m / 2])
    assert [m["data"] for _, _, m in by_topic["/trial/phase"]] == ["grasp", "estimate", "turn", "release"] * 2
    assert metadata["episode_001"]["task"] == episodes[1].task and metadata["episode_000"]["success"] == "true"
    assert metadata["tactile_manip"]["layout"] == "supermag-4x4"


def test_the_file_opens_in_rerun_with_decoded_messages(tmp_path, episodes):
    chunk = pytest.importorskip("rerun.chunk", reason="needs rerun-sdk with the MCAP reader (0.41 and later)")
    if not hasattr(chunk, "McapReader"):
        pytest.skip("this rerun-sdk has no MCAP reader in its Python API")
    out = tmp_path / "run.mcap"
    write_mcap(episodes, out, ros2=True)
    rows: dict[str, int] = {}
    for c in chunk.McapReader(out).stream():
        names = c.to_record_batch().schema.names
        if any(n.endswith(":message") or n.startswith(("DepthImage:", "Scalars:", "TextDocument:")) for n in names):
            rows[c.entity_path] = rows.get(c.entity_path, 0) + c.num_rows
    assert rows["/tactile/mbts/field"] == 80 and rows["/tactile/mbts/depth"] == 8
    assert rows["/joint_states/position"] == 80 and rows["/trial/phase"] == 8


def test_refuses_a_field_with_nan_and_json_for_rosbag2(tmp_path, episodes):
    pytest.importorskip("mcap", reason="MCAP export needs mcap (extra 'mcap')")
    with pytest.raises(ValueError, match="'cdr' with ros2"):
        write_mcap(episodes, tmp_path / "x.mcap", ros2=True, encoding="json")
    episodes[0].frames[3].field_ut[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        write_mcap(episodes, tmp_path / "y.mcap")


def _plain(msg):
    """A message with numpy arrays as lists (what the independent codec takes)."""
    if isinstance(msg, dict):
        return {k: _plain(v) for k, v in msg.items()}
    if isinstance(msg, list):
        return [_plain(v) for v in msg]
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    return msg


def _plain_obj(obj):
    if hasattr(obj, "__slots__") and not isinstance(obj, (str, bytes)):
        return {k: _plain_obj(getattr(obj, k)) for k in obj.__slots__}
    if isinstance(obj, (list, tuple)):
        return [_plain_obj(v) for v in obj]
    return obj


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and not isinstance(b, np.ndarray):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    if isinstance(a, (bytes, bytearray)) or isinstance(b, (bytes, bytearray)):
        return bytes(a) == bytes(b)
    return a == b


def test_the_ros2_decoder_of_mcap_ros2_support_reads_the_whole_file(tmp_path, episodes):
    decoder = pytest.importorskip("mcap_ros2.decoder", reason="mcap-ros2-support is not installed")
    mcap_reader = pytest.importorskip("mcap.reader", reason="MCAP export needs mcap (extra 'mcap')")
    out = tmp_path / "run.mcap"
    summary = write_mcap(episodes, out, ros2=True)
    counts: dict[str, int] = {}
    with open(out, "rb") as f:
        for _, channel, _, msg in mcap_reader.make_reader(
                f, decoder_factories=[decoder.DecoderFactory()]).iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/tactile/mbts/field":
                assert len(msg.data) == 48 and msg.layout.dim[0].label == "taxels"
    assert counts == summary["topics"]
