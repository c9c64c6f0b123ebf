"""What a transport of live ROS 2 topics does: the :class:`Transport` and :class:`Publisher` protocols, their
QoS (:class:`Qos`), the bounded send queue that keeps a publisher from ever blocking (:class:`SendQueue`), and an
in-memory transport (:class:`MemoryTransport`) for tests, users' included.

A transport advertises topics (fully qualified names, ``/ns/x``, and ROS 2 type names, ``pkg/msg/Type``) and
serves services (request CDR in, response CDR out); a publisher takes one CDR message at a time with its source
time and sequence number. ``publish`` never blocks the caller: a message that cannot go out at once waits in a
bounded queue, and when that queue is full the oldest waiting message is dropped and counted on its publisher
(``drops``). A slow or vanished subscriber thus costs dropped messages, never time in the reading loop.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

RELIABLE, BEST_EFFORT = "reliable", "best_effort"
VOLATILE, TRANSIENT_LOCAL = "volatile", "transient_local"


@dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile, as far as a publisher here sets one; the default is ROS 2's sensor-data profile
    (``rclcpp::SensorDataQoS``: best effort, volatile, keep last 5).

    Attributes:
        reliability: "best_effort" or "reliable".
        durability: "volatile" or "transient_local" (late joiners get the last ``depth`` messages).
        depth: history depth (keep last), messages, >= 1.
    """

    reliability: str = BEST_EFFORT
    durability: str = VOLATILE
    depth: int = 5

    def __post_init__(self) -> None:
        if self.reliability not in (RELIABLE, BEST_EFFORT):
            raise ValueError(f"Qos.reliability: expected 'reliable' or 'best_effort', got {self.reliability!r}")
        if self.durability not in (VOLATILE, TRANSIENT_LOCAL):
            raise ValueError(f"Qos.durability: expected 'volatile' or 'transient_local', got {self.durability!r}")
        if not (isinstance(self.depth, int) and self.depth >= 1):
            raise ValueError(f"Qos.depth: expected an integer >= 1, got {self.depth!r}")


SENSOR_DATA = Qos()
#: ROS 2's default profile (``rmw_qos_profile_default``): reliable, volatile, keep last 10 (diagnostics use it)
DEFAULT = Qos(reliability=RELIABLE, depth=10)


@runtime_checkable
class Publisher(Protocol):
    """One advertised topic. ``publish`` never blocks; ``drops`` counts messages it could not send."""

    drops: int

    def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
        """Send one CDR message (``stamp_ns``: source time, ns since the epoch; ``seq``: 1, 2, ... per topic)."""


@runtime_checkable
class Transport(Protocol):
    """A way out for ROS 2 topics and services: ``"zenoh"``, ``"foxglove"`` or ``"memory"``.

    ``advertise`` takes a fully qualified topic (``/ns/x``) and a ROS 2 type name (``pkg/msg/Type``);
    ``add_service`` a fully qualified service name, its type (``pkg/srv/Type``) and a handler from request CDR
    to response CDR, called on the transport's own thread. ``close`` undeclares everything and stops listening;
    it is idempotent.
    """

    name: str

    def advertise(self, topic: str, type_name: str, qos: Qos) -> Publisher: ...

    def add_service(self, name: str, srv_type: str, handler: Callable[[bytes], bytes]) -> None: ...

    def close(self) -> None: ...


class SendQueue:
    """A bounded queue of messages and the thread that sends them, so that ``put`` never blocks.

    ``send(item)`` runs on the queue's thread, one item at a time, and may block (a transport's back-pressure);
    meanwhile ``put`` goes on queueing, and past ``max_items`` drops the oldest item, calling ``on_drop(item)``
    (a publisher counts it). ``sent`` counts items handed to ``send``; ``close`` sends what is queued (for at most
    ``timeout_s``) and stops the thread.
    """

    def __init__(self, send: Callable[[object], None], *, max_items: int = 4096, name: str = "ros2-send",
                 on_drop: Callable[[object], None] | None = None) -> None:
        if max_items < 1:
            raise ValueError(f"max_items: expected >= 1, got {max_items}")
        self._send, self._on_drop = send, on_drop
        self._items: deque = deque()
        self._max = max_items
        self._cv = threading.Condition()
        self._closed = False
        self.sent = 0
        self.errors = 0
        self.last_error = ""
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item: object) -> None:
        """Queue ``item``; never blocks (beyond a lock held for microseconds)."""
        dropped = None
        with self._cv:
            if self._closed:
                dropped = item
            else:
                if len(self._items) >= self._max:
                    dropped = self._items.popleft()
                self._items.append(item)
                self._cv.notify()
        if dropped is not None and self._on_drop is not None:
            self._on_drop(dropped)

    def __len__(self) -> int:
        return len(self._items)

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._items and not self._closed:
                    self._cv.wait()
                if not self._items:
                    return
                item = self._items.popleft()
            try:
                self._send(item)
                self.sent += 1
            except Exception as e:  # noqa: BLE001 - a send that fails (a closing session) costs that message, not the thread
                self.errors += 1
                self.last_error = f"{type(e).__name__}: {e}"
                if self._on_drop is not None:
                    self._on_drop(item)

    def close(self, timeout_s: float = 2.0) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify()
        self._thread.join(timeout_s)


@dataclass
class MemoryMessage:
    """One message a :class:`MemoryTransport` publisher took."""

    topic: str
    type_name: str
    cdr: bytes
    stamp_ns: int
    seq: int


@dataclass
class _MemoryPublisher:
    transport: MemoryTransport
    topic: str
    type_name: str
    qos: Qos
    drops: int = 0

    def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
        t = self.transport
        if t.closed or (t.max_messages is not None and len(t.messages) >= t.max_messages):
            self.drops += 1
            return
        t.messages.append(MemoryMessage(self.topic, self.type_name, bytes(cdr), stamp_ns, seq))


@dataclass
class MemoryTransport:
    """Keeps every message in ``messages`` (up to ``max_messages``, then counts drops) and calls services in
    process (:meth:`call`): a transport for tests of anything that publishes."""

    max_messages: int | None = None
    name: str = "memory"
    messages: list[MemoryMessage] = field(default_factory=list)
    topics: dict[str, tuple[str, Qos]] = field(default_factory=dict)
    services: dict[str, tuple[str, Callable[[bytes], bytes]]] = field(default_factory=dict)
    closed: bool = False

    def advertise(self, topic: str, type_name: str, qos: Qos) -> _MemoryPublisher:
        if topic in self.topics:
            raise ValueError(f"topic {topic!r} is advertised already")
        self.topics[topic] = (type_name, qos)
        return _MemoryPublisher(self, topic, type_name, qos)

    def add_service(self, name: str, srv_type: str, handler: Callable[[bytes], bytes]) -> None:
        if name in self.services:
            raise ValueError(f"service {name!r} is served already")
        self.services[name] = (srv_type, handler)

    def call(self, name: str, request_cdr: bytes) -> bytes:
        """The response CDR of service ``name`` to ``request_cdr`` (KeyError for a service nobody serves)."""
        return self.services[name][1](request_cdr)

    def on(self, topic: str) -> list[MemoryMessage]:
        """The messages published on ``topic``, in order."""
        return [m for m in self.messages if m.topic == topic]

    def close(self) -> None:
        self.closed = True


@dataclass
class _TeePublisher:
    publishers: list[Publisher]

    @property
    def drops(self) -> int:
        return sum(p.drops for p in self.publishers)

    def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
        for p in self.publishers:
            p.publish(cdr, stamp_ns, seq)


@dataclass
class Tee:
    """Several transports as one (``serve --transport both``): each topic and service on every one."""

    transports: list
    name: str = "tee"

    def advertise(self, topic: str, type_name: str, qos: Qos) -> _TeePublisher:
        return _TeePublisher([t.advertise(topic, type_name, qos) for t in self.transports])

    def add_service(self, name: str, srv_type: str, handler: Callable[[bytes], bytes]) -> None:
        for t in self.transports:
            t.add_service(name, srv_type, handler)

    def close(self) -> None:
        for t in self.transports:
            t.close()
