"""Live ROS 2 topics over Zenoh as ``rmw_zenoh`` lays them out, so that ROS 2 nodes using ``rmw_zenoh_cpp`` see
them (``ros2 topic list``, ``ros2 topic echo``, ``ros2 service call``) without ROS installed here (extra ``ros2``).

What goes on the wire, after ``rmw_zenoh``'s design (``docs/design.md`` of ros2/rmw_zenoh, Jazzy):

- a message on the key expression ``<domain>/<topic without its leading />/<DDS type>/<type hash>``, e.g.
  ``0/tactile/field/std_msgs::msg::dds_::Float32MultiArray_/RIHS01_<sha256>``, its payload the CDR bytes, its
  attachment the publisher's sequence number (int64, from 1), the source time (int64 ns since the epoch) and
  the publisher's 16-byte GID, in Zenoh's serialization (little-endian integers; the GID as a sequence: its
  length, 16, as one LEB128 byte, then the bytes);
- liveliness tokens, one for the node and one per publisher and service:
  ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|SS>/<enclave>/<namespace>/<node>[/<topic>/<DDS type>/
  <type hash>/<qos>]``, names with ``/`` written as ``%``, the QoS as ``rmw_zenoh`` abbreviates it (each field
  left empty where it equals rmw_zenoh's default: reliable, volatile, keep last 42, infinite durations);
- a service as a queryable on its key expression (``std_srvs::srv::dds_::Trigger_``); the reply carries the
  request's sequence number and client GID back in its attachment.

The GID is the first 16 bytes of the BLAKE2b hash of the entity's liveliness key expression (``rmw_zenoh``
hashes the same text with XXH3; a GID only has to be unique and stable). Type hashes come from
:mod:`tactile_manip.interop.ros2.type_hash`.

The session is a Zenoh peer that listens on ``tcp/127.0.0.1:7447`` by default (the port ``rmw_zenohd`` uses,
so ROS 2 nodes on this machine find it where they look for their router) with multicast scouting off: nothing
listens beyond loopback unless ``bind`` names another address and ``allow_remote`` is set. It may instead (or
also) connect to a Zenoh router (``connect``: ``tcp/HOST:7447``). Messages are sent on a thread of their own
from a bounded queue (:class:`~tactile_manip.interop.ros2.transport.SendQueue`): ``publish`` never blocks, and a
subscriber too slow to keep up costs dropped messages, counted per publisher, not time in the reading loop.
zenoh is imported only when a transport is opened.
"""

from __future__ import annotations

import hashlib
import ipaddress
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from tactile_manip.interop.ros2.names import check_namespace, check_node_name
from tactile_manip.interop.ros2.transport import (
    BEST_EFFORT,
    TRANSIENT_LOCAL,
    Qos,
    SendQueue,
)
from tactile_manip.interop.ros2.type_hash import dds_type_name as dds_type
from tactile_manip.interop.ros2.type_hash import type_hash

ADMIN_SPACE = "@ros2_lv"
DEFAULT_PORT = 7447
LOOPBACK = "127.0.0.1"
NO_TYPE_HASH = "TypeHashNotSupported"  # what rmw_zenoh writes for a type without a hash
GID_BYTES = 16
SERVICE_QOS = Qos(reliability="reliable", depth=10)  # rmw_qos_profile_services_default


def mangle(name: str) -> str:
    """A ROS 2 name as one key-expression chunk: ``/`` -> ``%``."""
    return name.replace("/", "%")


def qos_keyexpr(qos: Qos) -> str:
    """The QoS chunk of a liveliness token: ``reliability:durability:history,depth:deadline s,ns:lifespan s,ns:
    liveliness,lease s,ns``, each value left out where it equals rmw_zenoh's default (reliable = 1, volatile = 2,
    keep last = 1, depth 42, infinite durations, automatic liveliness); best effort is 2, transient local 1."""
    reliability = "2" if qos.reliability == BEST_EFFORT else ""
    durability = "1" if qos.durability == TRANSIENT_LOCAL else ""
    depth = "" if qos.depth == 42 else str(qos.depth)
    return f"{reliability}:{durability}:,{depth}:,:,:,,"


def attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's attachment: int64 sequence number, int64 source time (ns), the GID as a 16-byte sequence."""
    return struct.pack("<qqB", seq, stamp_ns, GID_BYTES) + gid


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source time ns, GID) of an rmw_zenoh attachment (ValueError when it is not one)."""
    if len(data) != 17 + GID_BYTES or data[16] != GID_BYTES:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    seq, stamp_ns = struct.unpack_from("<qq", data)
    return seq, stamp_ns, bytes(data[17:])


def rmw_zid(zid_hex: str) -> str:
    """A Zenoh session id as rmw_zenoh writes it in tokens: each byte in hex without a leading zero."""
    raw = bytes.fromhex(zid_hex if len(zid_hex) % 2 == 0 else "0" + zid_hex)
    return "".join(f"{b:x}" for b in raw)


def type_hash_of(type_name: str) -> str:
    """The RIHS01 hash of a ROS 2 type (``pkg/msg/T`` or ``pkg/srv/T``); :data:`NO_TYPE_HASH` for a type
    outside our table."""
    try:
        return type_hash(type_name)
    except (KeyError, ValueError):
        return NO_TYPE_HASH


def check_bind(host: str, *, allow_remote: bool) -> str:
    """``host`` when it is a loopback address, or any address with ``allow_remote``; ValueError otherwise."""
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        raise ValueError(f"--bind {host!r}: expected an IP address (127.0.0.1, 0.0.0.0, ...)") from None
    if not loopback and not allow_remote:
        raise ValueError(f"--bind {host}: not a loopback address, so anyone on the network could read the topics "
                         "and call tare; add --allow-remote to listen there anyway")
    return host


@dataclass
class _Outgoing:
    publisher: _ZenohPublisher
    cdr: bytes
    attachment: bytes


class _ZenohPublisher:
    """One topic. ``publish`` queues (never blocks); ``drops`` counts messages dropped unsent."""

    def __init__(self, transport: ZenohTransport, topic: str, type_name: str, qos: Qos, zpub, token, gid: bytes,
                 key: str) -> None:
        self.transport, self.topic, self.type_name, self.qos = transport, topic, type_name, qos
        self._zpub, self._token, self.gid, self.key = zpub, token, gid, key
        self.drops = 0
        self.sent = 0

    def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
        self.transport._queue.put(_Outgoing(self, cdr, attachment(seq, stamp_ns, self.gid)))


class ZenohTransport:
    """A Zenoh session that publishes and serves as a ROS 2 node ``node`` in ``namespace`` would under
    rmw_zenoh (see the module docstring).

    Args:
        bind: address to listen on (loopback unless ``allow_remote``); None: listen nowhere (``connect`` only).
        port: TCP port to listen on (7447, rmw_zenohd's).
        connect: Zenoh endpoints to connect to (``tcp/HOST:PORT``), e.g. a ROS machine's ``rmw_zenohd``.
        domain_id: the ROS domain (``ROS_DOMAIN_ID``), 0 by default.
        max_queued: messages waiting to be sent before the oldest is dropped.
        on_sent: called on the send thread after each message went to zenoh, with its topic and the monotonic
            time (for measurements: ``benchmarks/bench_serve.py``).

    Raises:
        ValueError: a non-loopback ``bind`` without ``allow_remote``, or a bad namespace or node name.
        OSError: the port is in use (the message says what to do instead).
        MissingExtraError: zenoh is not installed (extra ``ros2``).
    """

    name = "zenoh"

    def __init__(self, *, namespace: str = "/", node: str = "tactile_manip", bind: str | None = LOOPBACK,
                 port: int = DEFAULT_PORT, connect: Sequence[str] = (), allow_remote: bool = False,
                 domain_id: int = 0, max_queued: int = 4096,
                 on_sent: Callable[[str, float], None] | None = None) -> None:
        from tactile_manip.extras import require

        zenoh = require("zenoh", "the Zenoh transport of `serve`")
        self.namespace, self.node = check_namespace(namespace), check_node_name(node)
        if bind is not None:
            check_bind(bind, allow_remote=allow_remote)
        if not (0 <= int(domain_id) <= 232):
            raise ValueError(f"domain_id: expected 0..232 (ROS_DOMAIN_ID), got {domain_id}")
        self.domain_id = int(domain_id)
        self.endpoint = None if bind is None else f"tcp/{'[' + bind + ']' if ':' in bind else bind}:{int(port)}"
        self.connect = list(connect)
        self._on_sent = on_sent
        self._zenoh = zenoh
        config = zenoh.Config()
        config.insert_json5("mode", '"peer"')
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("listen/endpoints", _json_list([self.endpoint] if self.endpoint else []))
        config.insert_json5("connect/endpoints", _json_list(self.connect))
        try:
            self.session = zenoh.open(config)
        except zenoh.ZError as e:
            if "in use" in str(e).lower():
                raise OSError(f"{self.endpoint}: the port is in use (another `tactile-manip serve`, or a Zenoh "
                              f"router such as rmw_zenohd): choose another --zenoh-port, or join that router "
                              f"with --connect tcp/127.0.0.1:{port}") from None
            raise OSError(f"zenoh could not open a session ({self.endpoint or self.connect}): {e}") from None
        self.zid = rmw_zid(str(self.session.zid()))
        self._lock = threading.Lock()
        self._next_id = 1
        self._tokens: list = []
        self._publishers: list[_ZenohPublisher] = []
        self._queryables: list = []
        self._closed = False
        self._queue = SendQueue(self._send, max_items=max_queued, name="zenoh-send", on_drop=self._dropped)
        self._tokens.append(self.session.liveliness().declare_token(self._token("NN", 0)))

    # ------------------------------------------------------------------ names

    def _token(self, entity: str, entity_id: int, topic: str | None = None, ros2_type: str | None = None,
               type_hash: str | None = None, qos: Qos | None = None) -> str:
        parts = [ADMIN_SPACE, str(self.domain_id), self.zid, "0", str(entity_id), entity, mangle("/"),
                 mangle(self.namespace), self.node]
        if topic is not None:
            parts += [mangle(topic), dds_type(ros2_type), type_hash, qos_keyexpr(qos)]
        return "/".join(parts)

    def key_expr(self, topic: str, ros2_type: str) -> str:
        """Where rmw_zenoh puts the messages of ``topic`` (fully qualified) of type ``ros2_type``."""
        return f"{self.domain_id}/{topic.strip('/')}/{dds_type(ros2_type)}/{type_hash_of(ros2_type)}"

    def _entity_id(self) -> int:
        with self._lock:
            self._next_id += 1
            return self._next_id - 1

    # ------------------------------------------------------------------ Transport

    def advertise(self, topic: str, type_name: str, qos: Qos) -> _ZenohPublisher:
        """Declare ``topic`` (``/ns/x``) of ``type_name`` (``pkg/msg/Type``) and its liveliness token."""
        self._require_open()
        key = self.key_expr(topic, type_name)
        token_key = self._token("MP", self._entity_id(), topic, type_name, type_hash_of(type_name), qos)
        # BLOCK: a full link holds the send thread (and the queue counts what it drops), never the caller
        zpub = self.session.declare_publisher(key, congestion_control=self._zenoh.CongestionControl.BLOCK)
        token = self.session.liveliness().declare_token(token_key)
        pub = _ZenohPublisher(self, topic, type_name, qos, zpub, token, _gid(token_key), key)
        self._publishers.append(pub)
        return pub

    def add_service(self, name: str, srv_type: str, handler: Callable[[bytes], bytes]) -> None:
        """Serve ``name`` (``/ns/x``) of ``srv_type`` (``pkg/srv/Type``): request CDR in, response CDR out."""
        self._require_open()
        key = self.key_expr(name, srv_type)
        token_key = self._token("SS", self._entity_id(), name, srv_type, type_hash_of(srv_type), SERVICE_QOS)

        def on_query(query) -> None:
            try:
                seq, _, client_gid = parse_attachment(query.attachment.to_bytes() if query.attachment else b"")
            except ValueError:
                seq, client_gid = 0, bytes(GID_BYTES)  # a plain zenoh get: answer it all the same
            payload = query.payload.to_bytes() if query.payload is not None else b""
            try:
                response = handler(payload)
            except Exception as e:  # noqa: BLE001 - a failing handler answers with an error, it does not end the server
                query.reply_err(f"{name}: {type(e).__name__}: {e}")
                return
            query.reply(query.key_expr, response, attachment=attachment(seq, time.time_ns(), client_gid))

        self._queryables.append(self.session.declare_queryable(key, on_query, complete=True))
        self._tokens.append(self.session.liveliness().declare_token(token_key))

    @property
    def publishers(self) -> list[_ZenohPublisher]:
        return list(self._publishers)

    @property
    def queued(self) -> int:
        """Messages waiting to be sent now."""
        return len(self._queue)

    def _send(self, item: _Outgoing) -> None:
        item.publisher._zpub.put(item.cdr, attachment=item.attachment)
        item.publisher.sent += 1
        if self._on_sent is not None:
            self._on_sent(item.publisher.topic, time.monotonic())

    @staticmethod
    def _dropped(item: _Outgoing) -> None:
        item.publisher.drops += 1

    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("the Zenoh transport is closed")

    def close(self) -> None:
        """Send what is queued (2 s at most), undeclare every token, publisher and queryable, close the session
        (its listener with it). Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.close(timeout_s=2.0)
        for entity in [*self._queryables, *(p._token for p in self._publishers), *self._tokens,
                       *(p._zpub for p in self._publishers)]:
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001, S110 - closing the session below undeclares what is left
                pass
        try:
            self.session.close()
        except Exception as e:  # noqa: BLE001 - nothing more to release; say so, do not mask the caller's error
            print(f"serve: closing the Zenoh session: {e}", file=sys.stderr)

    def __enter__(self) -> ZenohTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def description(self) -> str:
        where = [f"listening on {self.endpoint}"] if self.endpoint else []
        where += [f"connected to {e}" for e in self.connect]
        return f"zenoh (rmw_zenoh layout, domain {self.domain_id}) " + ", ".join(where)


def _gid(token_key: str) -> bytes:
    return hashlib.blake2b(token_key.encode(), digest_size=GID_BYTES).digest()


def _json_list(items: Sequence[str]) -> str:
    import json

    return json.dumps(list(items))


