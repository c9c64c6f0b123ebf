"""A pad's readings and estimates as live ROS 2 topics: :class:`TactilePublisher`, attached to a
:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` from any behaviour or user loop.

::

    from tactile_manip import TactileEstimator
    from tactile_manip.interop.ros2.publisher import TactilePublisher
    from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport

    est = TactileEstimator.load()
    with ZenohTransport(namespace="/tactile") as zt:
        pub = TactilePublisher(est, zt, namespace="/tactile")
        for reading in readings:                # your loop
            e = pub.estimate(reading)           # as est.estimate(reading), and every topic published

Topics and types: :mod:`tactile_manip.interop.ros2.messages`. Each topic's messages carry a sequence number
that starts at 1 and has no gap while the publisher runs (a subscriber sees a gap only where a message was
dropped, and the publisher counts each drop in :attr:`TactilePublisher.drops`); stamps are the reading's arrival
time on the system clock. Services (``tare``, ``describe_board``) and ``/diagnostics`` are what
:mod:`tactile_manip.interop.ros2.serve` adds around it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.interop import cdr
from tactile_manip.interop.ros2 import messages as m
from tactile_manip.interop.ros2.names import check_namespace, fully_qualified
from tactile_manip.interop.ros2.transport import (
    DEFAULT,
    SENSOR_DATA,
    Publisher,
    Transport,
)
from tactile_manip.interop.ros_msgs import MESSAGES


@dataclass
class _Topic:
    name: str           # fully qualified
    type_name: str      # pkg/Type
    publisher: Publisher
    seq: int = 0

    def send(self, msg: dict[str, Any], stamp_ns: int) -> None:
        self.send_cdr(cdr.encode(MESSAGES, self.type_name, msg), stamp_ns)

    def send_cdr(self, data: bytes, stamp_ns: int) -> None:
        self.seq += 1
        self.publisher.publish(data, stamp_ns, self.seq)


class TactilePublisher:
    """Publishes every reading it is given, and its estimate, on ``transport`` under ``namespace``.

    Args:
        estimator: the pad's estimator (:class:`TactileEstimator` or anything with its ``estimate``).
        transport: where the messages go (:class:`~tactile_manip.interop.ros2.transport.Transport`).
        namespace: the pad's ROS 2 namespace (``/tactile``); topics are ``<namespace>/field`` and so on.
        depth_hz: depth images per second on ``<namespace>/depth`` (None: no depth topic). The image is decoded
            from the reading by the estimator's pose model, at most this often.
        frame_id: the frame of stamped messages (``<last namespace token>_pad`` by default).

    Raises ValueError for a namespace ROS 2 would refuse, a non-positive ``depth_hz``, or ``depth_hz`` with an
    estimator whose pose part decodes no image.
    """

    def __init__(self, estimator, transport: Transport, *, namespace: str = "/tactile",
                 depth_hz: float | None = None, frame_id: str | None = None) -> None:
        self.estimator, self.transport = estimator, transport
        self.namespace = check_namespace(namespace)
        self.frame_id = frame_id or f"{self.namespace.rsplit('/', 1)[-1] or 'tactile'}_pad"
        if depth_hz is not None and not (depth_hz > 0 and math.isfinite(depth_hz)):
            raise ValueError(f"depth_hz: expected a positive rate, got {depth_hz}")
        self._reconstructor = None
        if depth_hz is not None:
            self._reconstructor = getattr(getattr(estimator, "pose", None), "reconstructor", None)
            if self._reconstructor is None:
                raise ValueError("depth_hz: this estimator's pose part decodes no depth image (load a pose model, "
                                 "or leave the depth topic off)")
        self.depth_period_s = None if depth_hz is None else 1.0 / depth_hz
        self._next_depth_s = -math.inf
        names = [n for n in m.TOPICS if n != "depth" or depth_hz is not None]
        self.topics: dict[str, _Topic] = {}
        for name in names:
            full = fully_qualified(self.namespace, name)
            type_name = m.TOPICS[name]
            self.topics[name] = _Topic(full, type_name, transport.advertise(full, m.ros2_type(type_name), SENSOR_DATA))
        # the messages of every reading, each encoded in one step (the same bytes as cdr.encode: a test holds it)
        self._angle = m.StampedEncoder(self.frame_id, m.ANGLE_BODY)
        self._contact = m.StampedEncoder(self.frame_id, m.CONTACT_BODY)
        self._field: m.FieldEncoder | None = None
        self._wall_minus_mono_ns = time.time_ns() - time.monotonic_ns()
        self.readings = 0
        self.last_publish_s = math.nan   # monotonic time the last reading's messages were handed over
        self.latencies_s: list[float] | None = None  # set to [] to record reading -> published, s, per reading

    @property
    def drops(self) -> int:
        """Messages of this pad's topics that the transport dropped unsent."""
        return sum(t.publisher.drops for t in self.topics.values())

    def stamp_ns(self, t_host_s: float) -> int:
        """A reading's monotonic arrival time on the system clock, ns since the epoch."""
        return round(t_host_s * 1e9) + self._wall_minus_mono_ns

    def warm_up(self, reading) -> None:
        """Run what publishing ``reading`` would run the first time (the depth image's decoder), publishing
        nothing: a model's first run is slow."""
        if self._reconstructor is not None:
            self._reconstructor.reconstruct(np.asarray(reading.field_ut, np.float32))

    def estimate(self, reading):
        """The estimator's estimate of ``reading`` (:func:`estimate_readings`), with the reading and the
        estimate published; returns the estimate."""
        estimate = estimate_readings(self.estimator, [reading])[0]
        self.publish(reading, estimate)
        return estimate

    def publish(self, reading, estimate) -> None:
        """Publish one reading (a :class:`~tactile_manip.types.TactileReading`) and its estimate."""
        stamp_ns = self.stamp_ns(reading.t_host_s)
        t = self.topics
        shape = np.shape(reading.field_ut)
        if self._field is None or self._field.shape != shape:
            self._field = m.FieldEncoder(shape)
        t["field_raw"].send_cdr(self._field.encode(reading.field_raw_ut), stamp_ns)
        t["field"].send_cdr(self._field.encode(reading.field_ut), stamp_ns)
        t["angle"].send_cdr(self._angle.encode(stamp_ns, *m.angle_values(estimate)), stamp_ns)
        t["contact"].send_cdr(self._contact.encode(stamp_ns, *m.contact_values(estimate)), stamp_ns)
        if self.depth_period_s is not None and reading.t_host_s >= self._next_depth_s:
            self._next_depth_s = reading.t_host_s + self.depth_period_s
            depth = self._reconstructor.reconstruct(np.asarray(reading.field_ut, np.float32)).depth_mm
            t["depth"].send(m.depth_message(depth, stamp_ns, self.frame_id), stamp_ns)
        self.readings += 1
        self.last_publish_s = time.monotonic()
        if self.latencies_s is not None:
            self.latencies_s.append(self.last_publish_s - reading.t_host_s)


def estimate_readings(estimator, readings: list) -> list:
    """The estimates of ``readings`` (one pad's in order, or several pads' newest): one ``estimate_many`` call,
    which leaves each estimate's ``position_mm`` unmeasured until read (``estimate`` measures it at once, decoding
    the image: about three times the cost of the rest here, for a value the published messages use only without
    a contact model); or ``estimate`` per reading where the contact model reads a history of frames
    (``context_frames`` > 1), which ``estimate_many`` does not keep."""
    contact = getattr(estimator, "contact", None)
    if not hasattr(estimator, "estimate_many") or getattr(contact, "context_frames", 1) > 1:
        return [estimator.estimate(r) for r in readings]
    return estimator.estimate_many(readings)


class Diagnostics:
    """``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``, reliable) for a set of pads: one status each."""

    def __init__(self, transport: Transport) -> None:
        self.topic = _Topic(m.DIAGNOSTICS_TOPIC, m.DIAGNOSTICS_TYPE,
                            transport.advertise(m.DIAGNOSTICS_TOPIC, m.ros2_type(m.DIAGNOSTICS_TYPE), DEFAULT))

    def publish(self, statuses: list[dict[str, Any]]) -> None:
        self.topic.send(m.diagnostic_array(statuses, time.time_ns()), time.time_ns())


def trigger_service(action: Callable[[], tuple[bool, str]]) -> Callable[[bytes], bytes]:
    """A ``std_srvs/Trigger`` handler (request CDR -> response CDR) running ``action`` -> (success, message)."""
    def handle(_request: bytes) -> bytes:
        try:
            ok, message = action()
        except Exception as e:  # noqa: BLE001 - the caller gets the failure as the response says it
            ok, message = False, f"{type(e).__name__}: {e}"
        return cdr.encode(MESSAGES, "std_srvs/Trigger_Response", m.trigger_response(ok, message))

    return handle
