"""Episodes to an MCAP file (``tactile-manip export SOURCE --format mcap``) with ROS 2 message types.

Topics, for a sensor called ``name`` (default ``mbts``; SI units unless named):

- ``/tactile/<name>/field``: ``std_msgs/msg/Float32MultiArray``, the field in uT, dims ``taxels`` (R*C, row
  major from row 0 at +y) x ``axes`` (x, y, z of the pad frame), every frame;
- ``/tactile/<name>/depth``: ``sensor_msgs/msg/Image`` ``32FC1``, the reconstructed depth in mm, where given;
- ``/tactile/<name>/angle`` and ``/tactile/<name>/confidence``: ``std_msgs/msg/Float32`` (rad; [0, 1]),
  where an estimate was made;
- ``/tactile/vbts/depth``: ``sensor_msgs/msg/Image`` ``32FC1``, the vision-based sensor's depth (pair logs);
- ``/joint_states``: ``sensor_msgs/msg/JointState``, ``fr3_joint1..7`` (rad) and, with a gripper,
  ``fr3_finger_joint1/2`` (m, half the width each);
- ``/trial/target_angle``: ``std_msgs/msg/Float32`` (rad); ``/trial/phase``: ``std_msgs/msg/String`` on change.

Times: an episode's frames are stamped (log time, publish time and header stamp) on the sensor clock, from
the first frame's host time (see :mod:`tactile_manip.interop.timeline`); image frames are ``<name>_pad``.
Encodings: ``ros2msg`` schemas and CDR messages (:mod:`tactile_manip.interop.cdr`) by default, which Foxglove
and Rerun's MCAP loader decode without ROS; ``ros2=True`` adds what rosbag2 writes (profile ``ros2`` and the
QoS metadata of each channel), so ``ros2 bag`` reads the file. ``encoding="json"`` writes JSON messages with
JSON Schemas instead (readable anywhere with a JSON parser; Rerun shows them only as raw bytes). Episode
facts go to MCAP metadata records (``tactile_manip``, ``episode_000``, ...). mcap is imported only inside
:func:`write_mcap`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.interop import cdr
from tactile_manip.interop.frames import Episode, Frame
from tactile_manip.interop.rerun_log import JOINT_NAMES
from tactile_manip.interop.ros_msgs import MESSAGES, json_schema, ros2msg_text, schema_name, to_json
from tactile_manip.interop.timeline import check_exportable, episode_starts_s, first_host_time_s, layout_of

FINGER_NAMES = ("fr3_finger_joint1", "fr3_finger_joint2")
# what rosbag2 stores per channel: reliable, volatile, keep-last (history 3 = "unknown" as recorded), no deadline
ROSBAG2_QOS = """- history: 3
  depth: 0
  reliability: 1
  durability: 2
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: 1
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false
"""


def topics_for(name: str) -> dict[str, str]:
    """Topic -> message type (``pkg/Type``) of an export of the sensor ``name``."""
    return {f"/tactile/{name}/field": "std_msgs/Float32MultiArray", f"/tactile/{name}/depth": "sensor_msgs/Image",
            f"/tactile/{name}/angle": "std_msgs/Float32", f"/tactile/{name}/confidence": "std_msgs/Float32",
            "/tactile/vbts/depth": "sensor_msgs/Image", "/joint_states": "sensor_msgs/JointState",
            "/trial/target_angle": "std_msgs/Float32", "/trial/phase": "std_msgs/String"}


def stamp(ns: int) -> dict[str, int]:
    """builtin_interfaces/Time of a time in ns."""
    return {"sec": int(ns // 1_000_000_000), "nanosec": int(ns % 1_000_000_000)}


def field_message(field_ut: np.ndarray) -> dict[str, Any]:
    """Float32MultiArray of an (R, C, 3) field in uT: dims taxels (R*C) x axes (3), row major."""
    f = np.asarray(field_ut, dtype=np.float32)
    if not np.isfinite(f).all():
        raise ValueError("field_ut: holds NaN or infinite values")
    taxels = f.shape[0] * f.shape[1]
    return {"layout": {"dim": [{"label": "taxels", "size": taxels, "stride": taxels * 3},
                               {"label": "axes", "size": 3, "stride": 3}], "data_offset": 0},
            "data": f.reshape(-1)}


def image_message(depth_mm: np.ndarray, ns: int, frame_id: str) -> dict[str, Any]:
    """sensor_msgs/Image 32FC1 (little endian) of an (H, W) depth in mm."""
    d = np.ascontiguousarray(depth_mm, dtype="<f4")
    if d.ndim != 2:
        raise ValueError(f"depth_mm: expected shape (H, W), got {d.shape}")
    return {"header": {"stamp": stamp(ns), "frame_id": frame_id}, "height": d.shape[0], "width": d.shape[1],
            "encoding": "32FC1", "is_bigendian": 0, "step": d.shape[1] * 4, "data": d.tobytes()}


def joint_state_message(frame: Frame, ns: int) -> dict[str, Any]:
    """sensor_msgs/JointState of the arm (rad) and, where the width is known, the two fingers (m)."""
    names, position = list(JOINT_NAMES), list(np.asarray(frame.joints_rad, dtype=np.float64))
    if math.isfinite(frame.gripper_width_m):
        names += FINGER_NAMES
        position += [frame.gripper_width_m / 2] * 2
    return {"header": {"stamp": stamp(ns), "frame_id": ""}, "name": names,
            "position": np.array(position, np.float64), "velocity": np.zeros(0), "effort": np.zeros(0)}


def frame_messages(frame: Frame, ns: int, name: str, previous_phase: str | None) -> list[tuple[str, dict[str, Any]]]:
    """(topic, message) pairs of one frame, in topic order (see the module docstring)."""
    out = [(f"/tactile/{name}/field", field_message(frame.field_ut))]
    if frame.depth_mm is not None:
        out.append((f"/tactile/{name}/depth", image_message(frame.depth_mm, ns, f"{name}_pad")))
    if math.isfinite(frame.angle_rad):
        out.append((f"/tactile/{name}/angle", {"data": frame.angle_rad}))
    if math.isfinite(frame.confidence):
        out.append((f"/tactile/{name}/confidence", {"data": frame.confidence}))
    if frame.vbts_depth_mm is not None:
        out.append(("/tactile/vbts/depth", image_message(frame.vbts_depth_mm, ns, "vbts_pad")))
    if frame.joints_rad is not None:
        out.append(("/joint_states", joint_state_message(frame, ns)))
    if math.isfinite(frame.target_angle_rad):
        out.append(("/trial/target_angle", {"data": frame.target_angle_rad}))
    if frame.phase and frame.phase != previous_phase:
        out.append(("/trial/phase", {"data": frame.phase}))
    return out


class _Channels:
    """Registers a topic's schema and channel on first use and encodes its messages."""

    def __init__(self, writer, types: dict[str, str], *, cdr: bool, ros2: bool) -> None:
        self.writer, self.types, self.cdr, self.ros2 = writer, types, cdr, ros2
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def add(self, topic: str, msg: dict[str, Any], ns: int) -> None:
        type_name = self.types[topic]
        if topic not in self.channels:
            self.channels[topic] = self._register(topic, type_name)
            self.counts[topic] = 0
        if self.cdr:
            data = cdr.encode(MESSAGES, type_name, msg)
        else:
            data = json.dumps(to_json(type_name, msg), allow_nan=False, separators=(",", ":")).encode()
        self.writer.add_message(self.channels[topic], log_time=ns, data=data, publish_time=ns,
                                sequence=self.counts[topic])
        self.counts[topic] += 1

    def _register(self, topic: str, type_name: str) -> int:
        if type_name not in self.schemas:
            if self.cdr:
                schema = (schema_name(type_name), "ros2msg", ros2msg_text(type_name).encode())
            else:
                schema = (schema_name(type_name), "jsonschema", json.dumps(json_schema(type_name)).encode())
            self.schemas[type_name] = self.writer.register_schema(*schema)
        metadata = {"offered_qos_profiles": ROSBAG2_QOS} if self.ros2 else {}
        return self.writer.register_channel(topic, "cdr" if self.cdr else "json", self.schemas[type_name], metadata)


def write_mcap(episodes: list[Episode], out: Path, *, ros2: bool = False, encoding: str = "cdr") -> dict[str, Any]:
    """Write ``episodes`` to the MCAP file ``out`` (CDR messages; the rosbag2 profile with ``ros2``).

    Args:
        encoding: ``"cdr"`` (ROS 2 messages) or ``"json"`` (JSON messages with JSON Schemas; not with ``ros2``).

    Returns:
        ``{"frames": n, "episodes": k, "topics": {topic: messages}, "profile": ..., "encoding": ...}``.

    Raises:
        ValueError: no episode has frames, they mix sensors, a field holds NaN, or a bad ``encoding``.
    """
    from tactile_manip.extras import require
    from tactile_manip.version import __version__

    if encoding not in ("cdr", "json") or (ros2 and encoding != "cdr"):
        raise ValueError(f"encoding: expected 'cdr' or 'json' ('cdr' with ros2), got {encoding!r}")
    require("mcap", "export --format mcap")
    from mcap.writer import CompressionType, Writer

    episodes, name = check_exportable(episodes)
    base_s = max(first_host_time_s(episodes), 0.0)  # MCAP times are unsigned ns
    frames = 0
    with open(out, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile="ros2" if ros2 else "", library=f"tactile_manip {__version__}")
        channels = _Channels(writer, topics_for(name), cdr=encoding == "cdr", ros2=ros2)
        layout = layout_of(episodes[0])
        writer.add_metadata("tactile_manip", {
            "sensor_name": name, "grid": json.dumps(list(episodes[0].grid)), "episodes": str(len(episodes)),
            "layout": layout.name if layout is not None else "", "field_unit": "uT", "depth_unit": "mm"})
        for episode, start in zip(episodes, episode_starts_s(episodes)):
            t0_ns = round((base_s + start) * 1e9)
            phase = None
            for frame in episode.frames:
                ns = t0_ns + round(frame.t_s * 1e9)
                for topic, msg in frame_messages(frame, ns, name, phase):
                    channels.add(topic, msg, ns)
                phase = frame.phase
            frames += len(episode.frames)
            writer.add_metadata(f"episode_{episode.index:03d}", {
                "task": episode.task, "fps": repr(episode.fps), "frames": str(len(episode.frames)),
                "success": "" if episode.success is None else str(bool(episode.success)).lower(),
                "first_log_time_ns": str(t0_ns), "meta": json.dumps(episode.meta, default=str)})
        writer.finish()
    return {"frames": frames, "episodes": len(episodes), "topics": dict(channels.counts),
            "profile": "ros2" if ros2 else "", "encoding": encoding}
