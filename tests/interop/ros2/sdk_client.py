"""A second independent ROS 2 client, run in its own process by the tests: ``zenoh-ros2-sdk``'s subscriber and
service client (written against rmw_zenoh), given only our message definitions, offline. The SDK computes each
type's hash itself from those definitions, so a topic arrives only where its key expression, hash included,
is the one we publish on. It imports nothing of tactile_manip.

    python sdk_client.py --port 7447 --defs defs.json --seconds 3 --out got.json

``defs.json``: ROS 2 type (``pkg/msg/Type``) -> ``.msg`` text. Writes, per topic, the messages received (count,
the last one's fields) and the responses of ``/tactile/describe_board``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import traceback

TOPICS = {"/tactile/field_raw": "std_msgs/msg/Float32MultiArray", "/tactile/field": "std_msgs/msg/Float32MultiArray",
          "/tactile/angle": "tactile_manip_msgs/msg/Angle", "/tactile/contact": "tactile_manip_msgs/msg/Contact"}
# what the SDK would fetch from the ROS 2 repositories; offline, it is given them
EMPTY = "uint8 structure_needs_at_least_one_member"
DEPENDENCIES = ("builtin_interfaces/msg/Time", "std_msgs/msg/Header", "geometry_msgs/msg/Point",
                "geometry_msgs/msg/Vector3", "std_msgs/msg/MultiArrayDimension", "std_msgs/msg/MultiArrayLayout")


def plain(msg):
    if hasattr(msg, "__dataclass_fields__"):
        return {k: plain(getattr(msg, k)) for k in msg.__dataclass_fields__ if not k.startswith("__")}
    if isinstance(msg, (list, tuple)):
        return [plain(v) for v in msg]
    if hasattr(msg, "tolist"):
        return plain(msg.tolist())
    if isinstance(msg, float) and math.isnan(msg):
        return "nan"
    return msg


def main() -> int:
    from zenoh_ros2_sdk import ROS2ServiceClient, ROS2Subscriber
    from zenoh_ros2_sdk.session import ZenohSession
    from zenoh_ros2_sdk.utils import (
        compute_service_type_hash,
        compute_type_hash_from_msg,
    )

    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--defs", required=True)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    defs = json.load(open(a.defs))
    session = ZenohSession.get_instance("127.0.0.1", a.port)
    for dep in DEPENDENCIES:
        session.register_message_type(defs[dep], dep)
    got: dict[str, list] = {t: [] for t in TOPICS}
    subs = [ROS2Subscriber(topic=t, msg_type=ty, callback=lambda m, t=t: got[t].append(m), msg_definition=defs[ty],
                           router_port=a.port, type_hash=compute_type_hash_from_msg(ty, defs[ty], defs))
            for t, ty in TOPICS.items()]
    hashes = {ty: compute_type_hash_from_msg(ty, defs[ty], defs) for ty in set(TOPICS.values())}
    # an empty request is, to rosidl, one uint8 member (the SDK refuses an empty definition)
    srv_hash = compute_service_type_hash("std_srvs/srv/Trigger", EMPTY, defs["std_srvs/msg/Trigger_Response"], defs)
    client = ROS2ServiceClient("/tactile/describe_board", "std_srvs/srv/Trigger", request_definition=EMPTY,
                               response_definition=defs["std_srvs/msg/Trigger_Response"], router_port=a.port,
                               type_hash=srv_hash, timeout=10.0)
    print("ready", flush=True)
    time.sleep(a.seconds)
    response = client.call()
    out = {"topics": {t: {"count": len(m), "last": plain(m[-1]) if m else None} for t, m in got.items()},
           "hashes": hashes, "service_hash": srv_hash,
           "describe": None if response is None else {"success": bool(response.success),
                                                      "message": response.message}}
    with open(a.out, "w") as f:
        json.dump(out, f)
    for s in subs:
        s.close()
    client.close()
    session.close()
    return 0


if __name__ == "__main__":
    try:
        status = main()
    except BaseException:  # noqa: BLE001 - said on stderr, then the exit status says it
        traceback.print_exc()
        status = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the SDK's session threads would keep the process alive
