"""The live topics and services over a Foxglove WebSocket server (``foxglove-sdk``, extra ``foxglove``).

Foxglove (the app, or any client of its WebSocket protocol) connects to ``ws://HOST:PORT`` and sees each
advertised topic as a channel with schema encoding ``ros2msg`` (the type's ``.msg`` text with the definitions it
uses, :func:`tactile_manip.interop.ros_msgs.ros2msg_text`) and message encoding ``cdr``: the very bytes the zenoh
transport sends, so the app decodes them as it decodes a ROS 2 bag. Services (tare, the board's description) are
advertised with their request and response schemas and answered in CDR.

Where it listens: 127.0.0.1 by default. Any other address is refused unless the caller allows it
(``allow_remote=True``, the command's ``--allow-remote``), and :meth:`FoxgloveTransport.description` then says
that other machines can connect. A port in use is refused with :class:`PortInUseError` (one line at the CLI).

What a slow client costs: ``publish`` hands the bytes to the SDK, which queues them per client (``backlog``
messages) and never blocks the caller; when a client's queue is full the SDK drops that client's oldest message.
The SDK does not count those drops: it logs "outbox for client ... full" at most every 30 s per client, and
:attr:`FoxgloveTransport.slow_client_events` counts those lines (so a slow client is reported, its drops are
not counted one by one). ``drops`` of a publisher counts what this side could not hand over: messages published
after ``close`` or refused by the SDK. A client that vanishes is unsubscribed by the server; publishing goes on.

The server runs on the SDK's threads inside this process, so it ends with the process, however that ends.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from tactile_manip.errors import ConfigError, TactileManipError
from tactile_manip.extras import require
from tactile_manip.interop.ros2.type_hash import ros_name, table_name
from tactile_manip.interop.ros_msgs import MESSAGES, ros2msg_text

DEFAULT_PORT = 8765            # Foxglove's own default WebSocket port
LOOPBACK = "127.0.0.1"
DEFAULT_BACKLOG = 1024         # messages queued per client before the SDK drops that client's oldest
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30 accepts (the renamed foxglove.websocket.v1)
SLOW_CLIENT_LOGGER = "foxglove.websocket.connected_client.send_lossy"
STOP_TIMEOUT_S = 2.0           # close() waits this long at most for the SDK to stop listening


class PortInUseError(TactileManipError, OSError):
    """The WebSocket server cannot listen on its address: the port is taken or the address is not ours."""


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an IP address or ``localhost``) is reachable from this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _wait_until_free(host: str, port: int, timeout_s: float) -> bool:
    """Wait until nothing listens on ``host:port`` (the SDK stops its server asynchronously); False on timeout."""
    host = LOOPBACK if host == "localhost" else host.strip("[]")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    end = time.monotonic() + timeout_s
    while True:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # a listener refuses the bind, TIME_WAIT not
            try:
                s.bind((host, port))
                return True
            except OSError:
                if time.monotonic() > end:
                    return False
        time.sleep(0.005)


class _SlowClientCounter(logging.Handler):
    """Counts the SDK's "outbox ... full" lines (one per slow client, at most every 30 s)."""

    def __init__(self) -> None:
        super().__init__(level=logging.INFO)
        self.events = 0

    def emit(self, record: logging.LogRecord) -> None:
        if "full" in record.getMessage():
            self.events += 1


_COUNTER = _SlowClientCounter()
_COUNTER_LOCK = threading.Lock()


def _count_slow_clients() -> _SlowClientCounter:
    """The process's one counter, attached to the SDK's logger before a server starts (the SDK reads the
    logger's level when it first logs there)."""
    with _COUNTER_LOCK:
        logger = logging.getLogger(SLOW_CLIENT_LOGGER)
        if _COUNTER not in logger.handlers:
            logger.addHandler(_COUNTER)
            if logger.getEffectiveLevel() > logging.INFO:
                logger.setLevel(logging.INFO)
    return _COUNTER


@dataclass
class FoxglovePublisher:
    """One channel of the server. ``publish`` never blocks; ``drops`` counts what could not be handed over,
    ``sent`` what was handed to the SDK while a client was subscribed, ``unheard`` what no client subscribed to
    (nothing is queued for a channel nobody subscribes to)."""

    topic: str
    type_name: str
    channel: Any
    transport: FoxgloveTransport
    drops: int = 0
    sent: int = 0
    unheard: int = 0

    def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
        """Hand one CDR message (with its 4-byte encapsulation header) to the SDK, stamped ``stamp_ns`` (the
        frame's time a client sees). ``seq`` is not sent: the protocol has no field for it (clients see order
        and gaps in the stamps)."""
        if self.transport.closed:
            self.drops += 1
            return
        try:
            if not self.channel.has_sinks():
                self.unheard += 1
                return
            self.channel.log(cdr, log_time=stamp_ns)
            self.sent += 1
        except RuntimeError:  # the SDK refused it (FoxgloveError): that message is lost, not the loop
            self.drops += 1


@dataclass
class FoxgloveTransport:
    """A Foxglove WebSocket server for the live topics: the ``Transport`` of ``tactile-manip serve`` named
    ``"foxglove"``.

    Constructing it does no I/O; :meth:`start` listens (and is called by :meth:`__enter__`).

    Attributes:
        host: address to listen on; a non-loopback one needs ``allow_remote``.
        port: TCP port (0: any free port; :attr:`port` holds the chosen one once started).
        allow_remote: allow a non-loopback ``host`` (other machines can then connect).
        backlog: messages queued per client before the SDK drops that client's oldest, >= 1.
        server_name: the name clients show for the server.
    """

    host: str = LOOPBACK
    port: int = DEFAULT_PORT
    allow_remote: bool = False
    backlog: int = DEFAULT_BACKLOG
    server_name: str = "tactile_manip"
    name: str = field(default="foxglove", init=False)
    closed: bool = field(default=False, init=False)
    publishers: dict[str, FoxglovePublisher] = field(default_factory=dict, init=False)
    services: dict[str, str] = field(default_factory=dict, init=False)
    _server: Any = field(default=None, init=False, repr=False)
    _context: Any = field(default=None, init=False, repr=False)
    _slow_at_start: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.port, int) or not 0 <= self.port <= 65535:
            raise ConfigError(f"foxglove port: expected 0..65535, got {self.port!r}")
        if not isinstance(self.backlog, int) or self.backlog < 1:
            raise ConfigError(f"foxglove backlog: expected an integer >= 1, got {self.backlog!r}")
        if not self.host:
            raise ConfigError("foxglove host: expected an IP address such as 127.0.0.1, got ''")
        if not is_loopback(self.host) and not self.allow_remote:
            raise ConfigError(f"foxglove: {self.host} is not a loopback address, so other machines could connect; "
                              f"allow that explicitly (--allow-remote) or listen on {LOOPBACK}")

    @property
    def url(self) -> str:
        """``ws://HOST:PORT`` as a client on this machine opens it."""
        host = LOOPBACK if self.host in ("0.0.0.0", "::", "[::]") else self.host
        return f"ws://{f'[{host}]' if ':' in host and not host.startswith('[') else host}:{self.port}"

    def description(self) -> str:
        """Where the server listens and who can connect, for the command's status line."""
        reach = ("this machine only" if is_loopback(self.host)
                 else "OTHER MACHINES CAN CONNECT: not loopback, --allow-remote")
        return f"foxglove WebSocket server on {self.host}:{self.port} ({reach}): open {self.url} in Foxglove"

    @property
    def slow_client_events(self) -> int:
        """The SDK's "client outbox full" lines since :meth:`start`: each means a client fell behind and lost
        messages (at most one line per client every 30 s; the SDK does not count the messages)."""
        return _COUNTER.events - self._slow_at_start

    def start(self) -> FoxgloveTransport:
        """Listen on ``host:port``.

        Raises:
            MissingExtraError: foxglove-sdk is not installed (extra ``foxglove``).
            PortInUseError: the port is taken, or ``host`` is not an address of this machine.
        """
        if self._server is not None:
            return self
        foxglove = require("foxglove", "the Foxglove transport")
        from foxglove.websocket import Capability

        self._slow_at_start = _count_slow_clients().events
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name=self.server_name, host=self.host, port=self.port, context=self._context,
                capabilities=[Capability.Services], supported_encodings=["cdr"],
                message_backlog_size=self.backlog)
        except RuntimeError as e:
            why = "the port is in use" if "in use" in str(e) else str(e).removeprefix("FoxgloveError: ")
            raise PortInUseError(f"foxglove: cannot listen on {self.host}:{self.port}: {why}; "
                                 f"choose another port or stop what listens there") from e
        self.port = self._server.port
        return self

    def advertise(self, topic: str, type_name: str, qos: Any = None) -> FoxglovePublisher:
        """A channel ``topic`` (fully qualified, ``/ns/x``) of ROS 2 type ``type_name`` (``pkg/msg/Type``).

        ``qos`` is accepted for the Transport protocol and not used: a WebSocket client gets every message in
        order until its queue is full (then its oldest are dropped), whatever the profile.
        """
        import foxglove

        self._require_started()
        if topic in self.publishers:
            raise ValueError(f"foxglove: topic {topic!r} is advertised already")
        full = ros_name(type_name)
        schema = foxglove.Schema(name=full, encoding="ros2msg", data=ros2msg_text(table_name(full)).encode())
        channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._context)
        self.publishers[topic] = FoxglovePublisher(topic, full, channel, self)
        return self.publishers[topic]

    def add_service(self, name: str, srv_type: str, handler: Callable[[bytes], bytes]) -> None:
        """Serve ``name`` of type ``srv_type`` (``pkg/srv/Type``, its request and response in the message table
        as ``pkg/Type_Request`` / ``pkg/Type_Response``): ``handler`` maps request CDR to response CDR, on the
        SDK's thread; an exception in it is sent to the client as the call's failure."""
        import foxglove

        self._require_started()
        if name in self.services:
            raise ValueError(f"foxglove: service {name!r} is served already")
        full = ros_name(srv_type)
        pkg, _, short = full.split("/")
        parts = {}
        for part in ("Request", "Response"):
            key = f"{pkg}/{short}_{part}"
            if key not in MESSAGES:
                raise KeyError(f"foxglove: service type {full!r} has no {key!r} in the message table")
            parts[part] = foxglove.MessageSchema(encoding="cdr", schema=foxglove.Schema(
                name=f"{pkg}/srv/{short}_{part}", encoding="ros2msg", data=ros2msg_text(key).encode()))
        schema = foxglove.ServiceSchema(full, request=parts["Request"], response=parts["Response"])
        self._server.add_services([foxglove.Service(name, schema=schema,
                                                    handler=lambda request: handler(bytes(request.payload)))])
        self.services[name] = full

    def close(self) -> None:
        """Unadvertise every channel and stop listening (the port is free on return); idempotent."""
        if self.closed:
            return
        self.closed = True
        for pub in self.publishers.values():
            pub.channel.close()
        if self._server is not None:
            self._server.stop()
            _wait_until_free(self.host, self.port, STOP_TIMEOUT_S)

    def __enter__(self) -> FoxgloveTransport:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _require_started(self) -> None:
        if self._server is None or self.closed:
            raise RuntimeError("foxglove: call start() before advertising (and not after close())")
