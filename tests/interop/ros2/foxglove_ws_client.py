"""An independent client of a Foxglove WebSocket server, run as its own process by the tests.

It speaks the protocol itself with the ``websockets`` package (subprotocol ``foxglove.sdk.v1``, the renamed
``foxglove.websocket.v1``; the messages are the same): it reads ``serverInfo``, ``advertise`` and
``advertiseServices``, subscribes to every channel (or to those named), receives binary message-data frames
(opcode 1: subscription id, receive time in ns, payload), optionally calls one service (opcode 2 out, opcode 3
back), and decodes every payload with mcap-ros2-support's ROS 2 decoder built from the schema the server
advertised. Nothing of tactile_manip is imported.

    python foxglove_ws_client.py ws://127.0.0.1:8765 --seconds 3 --out got.json [--call /tactile/tare]
        [--topics /a,/b] [--stall-after 50 --stall-s 5]

Prints ``subscribed`` once its subscriptions are sent, then writes ``--out``: the channels, the services, the
service response (decoded), and per topic the list of [the frame's time ns, decoded message, arrival time ns].
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import time

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def plain(obj):
    """A decoded message as JSON-able values (bytes as lists of ints)."""
    if isinstance(obj, (bytes, bytearray)):
        return list(obj)
    if hasattr(obj, "__slots__") and not isinstance(obj, str):
        return {k: plain(getattr(obj, k)) for k in obj.__slots__}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return obj


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("url")
    p.add_argument("--seconds", type=float, default=3.0, help="how long to receive after subscribing")
    p.add_argument("--out", required=True)
    p.add_argument("--topics", default="", help="comma-separated topics to subscribe to (default: all)")
    p.add_argument("--call", default="", help="a service to call once, with an empty request")
    p.add_argument("--wait-topics", type=int, default=1, help="channels to wait for before subscribing")
    p.add_argument("--stall-after", type=int, default=0, help="stop reading after this many messages...")
    p.add_argument("--stall-s", type=float, default=0.0, help="...for this long (a slow client)")
    args = p.parse_args(argv)

    from mcap_ros2._dynamic import generate_dynamic
    from websockets.sync.client import connect

    wanted = [t for t in args.topics.split(",") if t]
    channels: dict[int, dict] = {}
    services: dict[str, dict] = {}
    frames: list[tuple[int, int, bytes, int]] = []
    response = None
    with connect(args.url, subprotocols=SUBPROTOCOLS, max_size=None, open_timeout=10) as ws:
        deadline = time.monotonic() + 10
        # the server announces itself, its channels and its services first
        while time.monotonic() < deadline:
            try:
                m = ws.recv(timeout=0.5)
            except TimeoutError:
                if len(channels) >= args.wait_topics and (not args.call or args.call in services):
                    break
                continue
            if isinstance(m, bytes):
                continue
            op = json.loads(m)
            if op["op"] == "advertise":
                channels.update({c["id"]: c for c in op["channels"]})
            elif op["op"] == "advertiseServices":
                services.update({s["name"]: s for s in op["services"]})
        subs = {}
        for i, (cid, ch) in enumerate(sorted(channels.items())):
            if not wanted or ch["topic"] in wanted:
                subs[i + 1] = cid
        ws.send(json.dumps({"op": "subscribe",
                            "subscriptions": [{"id": sid, "channelId": cid} for sid, cid in subs.items()]}))
        print("subscribed", flush=True)
        if args.call:
            svc = services[args.call]
            enc = b"cdr"
            ws.send(b"\x02" + struct.pack("<III", svc["id"], 1, len(enc)) + enc + b"\x00\x01\x00\x00\x00")
        end = time.monotonic() + args.seconds
        stalled = False
        while time.monotonic() < end:
            if args.stall_after and not stalled and len(frames) >= args.stall_after:
                stalled = True
                time.sleep(args.stall_s)
            try:
                m = ws.recv(timeout=max(0.01, end - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(m, str):
                op = json.loads(m)
                if op["op"] == "serviceCallFailure":
                    response = {"failure": op.get("message", "")}
                continue
            if m[0] == 1:
                sid, t_ns = struct.unpack_from("<IQ", m, 1)
                frames.append((sid, t_ns, bytes(m[13:]), time.time_ns()))
            elif m[0] == 3:
                service_id, call_id, n = struct.unpack_from("<III", m, 1)
                payload = bytes(m[13 + n:])
                svc = next(s for s in services.values() if s["id"] == service_id)
                schema = svc.get("response") or {}
                name = schema.get("schemaName") or svc["type"] + "_Response"
                text = schema.get("schema", svc.get("responseSchema", ""))
                response = {"call_id": call_id, "encoding": m[13:13 + n].decode(),
                            "message": plain(generate_dynamic(name, text)[name](payload))}

    decoders = {}
    messages: dict[str, list] = {}
    for sid, t_ns, payload, arrival_ns in frames:
        ch = channels[subs[sid]]
        if ch["topic"] not in decoders:
            decoders[ch["topic"]] = generate_dynamic(ch["schemaName"], ch["schema"])[ch["schemaName"]]
        messages.setdefault(ch["topic"], []).append([t_ns, plain(decoders[ch["topic"]](payload)), arrival_ns])
    out = {"channels": [{k: c[k] for k in ("topic", "encoding", "schemaName", "schemaEncoding")}
                        for c in channels.values()],
           "services": [{"name": s["name"], "type": s["type"]} for s in services.values()],
           "response": response, "messages": messages}
    with open(args.out, "w") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
