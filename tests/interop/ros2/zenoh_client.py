"""An independent ROS 2 subscriber over Zenoh, run in its own process by the tests: it knows rmw_zenoh's layout
(liveliness tokens, key expressions, attachments) and decodes CDR with mcap-ros2-support's decoder, given only
the message definitions (a JSON file of ROS 2 type -> ``ros2msg`` text). It imports nothing of tactile_manip.

    python zenoh_client.py --connect tcp/127.0.0.1:7447 --defs defs.json --seconds 3 --out got.json
        [--slow-ms 50] [--call /tactile/describe_board] [--exit-after-s S]

It prints ``ready`` once subscribed, then writes ``got.json``: the graph (every token: kind, topic, ROS 2 type,
hash, QoS), and per topic the sequence numbers, arrival times and decoded messages it received.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import sys
import threading
import time


def demangle_type(dds: str) -> str:
    """``std_msgs::msg::dds_::String_`` -> ``std_msgs/msg/String``."""
    pkg, kind, _, name = dds.split("::")
    return f"{pkg}/{kind}/{name[:-1]}"


def parse_token(key: str) -> dict:
    p = key.split("/")
    out = {"kind": p[5], "zid": p[2], "namespace": p[7].replace("%", "/"), "node": p[8]}
    if len(p) >= 13:
        out.update(topic=p[9].replace("%", "/"), type=demangle_type(p[10]), hash=p[11], qos=p[12])
    return out


def plain(value):
    """A decoded message as JSON values (NaN as the string "nan")."""
    if hasattr(value, "__slots__") or hasattr(value, "__dict__"):
        fields = getattr(value, "__slots__", None) or vars(value)
        return {k: plain(getattr(value, k)) for k in fields}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    return value


def main() -> int:
    import zenoh
    from mcap_ros2._dynamic import generate_dynamic

    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True)
    ap.add_argument("--defs", required=True)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--domain", default="0")
    ap.add_argument("--slow-ms", type=float, default=0.0)
    ap.add_argument("--call", action="append", default=[])
    ap.add_argument("--keep-values", type=int, default=10**9)
    a = ap.parse_args()
    with open(a.defs) as f:
        defs = json.load(f)
    decoders = {t: generate_dynamic(t, text)[t] for t, text in defs.items()}
    cfg = zenoh.Config()
    cfg.insert_json5("mode", '"client"')  # as a ROS 2 tool joins a router: it listens nowhere
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("connect/endpoints", json.dumps([a.connect]))
    session = zenoh.open(cfg)
    lock = threading.Lock()
    tokens: dict[str, dict] = {}
    topics: dict[str, dict] = {}

    def on_token(sample) -> None:
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                tokens[str(sample.key_expr)] = parse_token(str(sample.key_expr))

    def on_data(sample) -> None:
        key = str(sample.key_expr)
        parts = key.split("/")
        topic, ros_type = "/" + "/".join(parts[1:-2]), demangle_type(parts[-2])
        att = sample.attachment.to_bytes() if sample.attachment is not None else b""
        seq, stamp_ns = struct.unpack_from("<qq", att) if len(att) >= 16 else (-1, -1)
        now = time.time()
        payload = sample.payload.to_bytes()
        with lock:
            t = topics.setdefault(topic, {"type": ros_type, "hash": parts[-1], "seqs": [], "recv_s": [],
                                          "stamps_ns": [], "values": [], "gid_len": att[16] if len(att) > 16 else -1})
            t["seqs"].append(seq)
            t["recv_s"].append(now)
            t["stamps_ns"].append(stamp_ns)
            if len(t["values"]) < a.keep_values and ros_type in decoders:
                t["values"].append(plain(decoders[ros_type](payload)))
        if a.slow_ms:
            time.sleep(a.slow_ms / 1000)

    liveliness = session.liveliness()
    lsub = liveliness.declare_subscriber(f"@ros2_lv/{a.domain}/**", on_token, history=True)
    sub = session.declare_subscriber(f"{a.domain}/**", on_data)
    print("ready", flush=True)
    deadline = time.monotonic() + a.seconds
    calls = {}
    time.sleep(min(0.5, a.seconds / 4))
    for name in a.call:  # a ROS 2 client's call: a query on the service's key with rmw_zenoh's attachment
        srv = []
        while not srv and time.monotonic() < deadline:  # its liveliness token may take a moment to arrive
            with lock:
                srv = [t for t in tokens.values() if t["kind"] == "SS" and t.get("topic") == name]
            time.sleep(0.05)
        if not srv:
            calls[name] = {"error": "no such service in the graph"}
            continue
        s = srv[0]
        dds = s["type"].replace("/", "::").replace("::srv::", "::srv::dds_::") + "_"
        key = f"{a.domain}/{name.strip('/')}/{dds}/{s['hash']}"
        att = struct.pack("<qqB", 7, time.time_ns(), 16) + bytes(range(16))
        replies = list(session.get(key, payload=b"\x00\x01\x00\x00\x00", attachment=att, timeout=10.0))
        ok = [r.ok for r in replies if r.ok is not None]
        if not ok:
            calls[name] = {"error": "no reply"}
            continue
        rep = ok[0]
        ratt = rep.attachment.to_bytes() if rep.attachment is not None else b""
        decode = decoders.get(s["type"].replace("/srv/", "/msg/") + "_Response")
        calls[name] = {"response": plain(decode(rep.payload.to_bytes())) if decode else None,
                       "reply_seq": struct.unpack_from("<q", ratt)[0] if len(ratt) >= 8 else None,
                       "reply_gid": list(ratt[17:]) if len(ratt) > 17 else None}
    while time.monotonic() < deadline:
        time.sleep(0.05)
    with lock:
        out = {"tokens": list(tokens.values()), "topics": topics, "calls": calls, "pid": os.getpid()}
    tmp = a.out + ".tmp"
    with open(tmp, "w") as f:
        json.dump(out, f)
    os.replace(tmp, a.out)
    sub.undeclare()
    lsub.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
