"""The loop of ``tactile-manip serve``: connected sensors' readings and estimates out as ROS 2 topics, with the
pads' services and diagnostics, until a time is up or the process is told to stop.

Each pad (one sensor and its :class:`~tactile_manip.interop.ros2.publisher.TactilePublisher`) publishes every
frame its sensor delivers, in order, with the frame's estimate; with several pads the frames that arrived since
the last pass are estimated in one batch (``estimate_many``). Per pad:

- services ``<ns>/tare`` (``std_srvs/srv/Trigger``: a new baseline from the free pad, ~1 s of frames; the noise
  floor of the estimates follows it) and ``<ns>/describe_board`` (``std_srvs/srv/Trigger``: the board, the
  models and the topics, as JSON in ``message``);
- a status on ``/diagnostics`` once a second, and at once when a pad goes stale or comes back: OK; WARN while
  frames are lost on the wire or messages are dropped; ERROR while the link is down; STALE when no frame came
  for ``stale_s`` (a sensor that stops: nothing else is published for it meanwhile, so no estimate is stale).
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from tactile_manip.interop.ros2 import messages as m
from tactile_manip.interop.ros2.names import fully_qualified
from tactile_manip.interop.ros2.publisher import (
    Diagnostics,
    TactilePublisher,
    estimate_readings,
    trigger_service,
)

DIAGNOSTICS_PERIOD_S = 1.0
STALE_S = 0.25  # about 30 frames at 125 Hz
BATCH_PER_PAD = 2  # readings per pad estimated in one call at most


@dataclass
class Pad:
    """One served sensor: its publisher, its frame subscription and what its diagnostics report."""

    sensor: Any
    publisher: TactilePublisher
    subscription: Any = None
    last_frame_s: float = field(default_factory=time.monotonic)
    level: int = m.OK
    message: str = "starting"
    reported_drops: int = 0
    reported_lost: int = 0

    @property
    def namespace(self) -> str:
        return self.publisher.namespace


def pad_namespaces(namespace: str, pads: int) -> list[str]:
    """One pad: ``namespace``; several: ``namespace/pad0``, ``namespace/pad1``, ..."""
    if pads == 1:
        return [namespace]
    return [fully_qualified(namespace, f"pad{i}", what="namespace") for i in range(pads)]


def describe(pad: Pad, estimator) -> str:
    """The board, the models and the topics of ``pad``, as JSON."""
    board = pad.sensor.layout
    return json.dumps({
        "source": pad.sensor.source, "wire_format": getattr(pad.sensor, "wire_format", ""),
        "board": board.name, "shape": list(board.shape), "pitch_mm": board.pitch_mm,
        "rate_hz": pad.sensor.chip.rate_hz, "estimator": repr(estimator),
        "frame_id": pad.publisher.frame_id,
        "topics": {t.name: m.ros2_type(t.type_name) for t in pad.publisher.topics.values()},
        "services": {fully_qualified(pad.namespace, s): "std_srvs/srv/Trigger" for s in ("tare", "describe_board")},
    })


def tare(pad: Pad, estimator) -> tuple[bool, str]:
    """A new baseline of ``pad``'s sensor (its estimator's noise floor follows); (success, message)."""
    from tactile_manip.errors import SensorError

    try:
        baseline = pad.sensor.calibrate_baseline()
    except SensorError as e:
        return False, str(e)
    if getattr(baseline, "noise_ut", None) is not None and hasattr(estimator, "set_noise_floor"):
        estimator.set_noise_floor(baseline.noise_ut)
    return True, f"new baseline of {pad.sensor.source} ({pad.namespace})"


def slow_client_events(transport) -> int:
    """The slow-client events of ``transport`` (or of each transport of a Tee) so far: the Foxglove server's
    "client outbox full" reports (its SDK drops that client's oldest messages without counting them)."""
    return sum(getattr(t, "slow_client_events", 0) for t in getattr(transport, "transports", [transport]))


def status(pad: Pad, now_s: float, stale_s: float, *, slow_clients: tuple[int, int] = (0, 0)) -> dict[str, Any]:
    """The pad's diagnostic status now (and its level kept on ``pad``); ``slow_clients``: the transport's
    slow-client events (new since the last report, in all)."""
    h = pad.sensor.health()
    age = now_s - pad.last_frame_s
    drops, lost = pad.publisher.drops, h.frames_missed
    overflow = getattr(pad.subscription, "overflowed", 0)
    if age > stale_s:
        link = "" if h.link_up else f"; link down: {h.last_error or 'reconnecting'}"
        level, message = m.STALE, (f"no frame for {age:.2f} s{link}: no estimates are published until frames "
                                   "resume")
    elif not h.link_up:
        level, message = m.ERROR, f"link down: {h.last_error or 'reconnecting'}"
    elif drops > pad.reported_drops or lost > pad.reported_lost or overflow:
        level, message = m.WARN, (f"{drops - pad.reported_drops} messages dropped, {lost - pad.reported_lost} "
                                  f"frames lost on the wire since the last report")
    elif slow_clients[0]:
        level, message = m.WARN, ("a Foxglove client fell behind and lost messages since the last report (its "
                                  "server drops them uncounted)")
    else:
        level, message = m.OK, "streaming"
    pad.level, pad.message = level, message
    pad.reported_drops, pad.reported_lost = drops, lost
    values = {"rate_hz": h.rate_hz, "frames": h.frames, "last_frame_age_s": age, "published_readings":
              pad.publisher.readings, "dropped_messages": drops, "frames_missed": lost, "seq_gaps": h.seq_gaps,
              "crc_errors": h.crc_errors, "reconnects": h.reconnects, "unread_frames_dropped": overflow,
              "slow_client_events": slow_clients[1]}
    return m.diagnostic_status(level=level, name=f"tactile_manip: {pad.namespace}", message=message,
                               hardware_id=pad.sensor.source, values=values)


class Server:
    """Serves ``pads`` through ``transport`` (one Transport; see ``transport.Tee`` for several)."""

    def __init__(self, pads: list[Pad], estimator, transport, *, stale_s: float = STALE_S) -> None:
        self.pads, self.estimator, self.transport, self.stale_s = pads, estimator, transport, stale_s
        self.diagnostics = Diagnostics(transport)
        for pad in pads:
            transport.add_service(fully_qualified(pad.namespace, "tare", what="service name"), "std_srvs/srv/Trigger",
                                  trigger_service(lambda pad=pad: tare(pad, estimator)))
            transport.add_service(fully_qualified(pad.namespace, "describe_board", what="service name"),
                                  "std_srvs/srv/Trigger",
                                  trigger_service(lambda pad=pad: (True, describe(pad, estimator))))
        self._next_diag_s = -math.inf
        self._reported_slow = 0
        self.streaming_since_s = math.nan  # monotonic time the loop started taking frames

    def run(self, *, seconds: float | None = None) -> int:
        """Publish until ``seconds`` pass (None: until interrupted); returns readings published."""
        self._warm_up()
        self.streaming_since_s = time.monotonic()
        end = math.inf if seconds is None else self.streaming_since_s + seconds
        subs = [pad.sensor.subscribe() for pad in self.pads]
        for pad, sub in zip(self.pads, subs):
            pad.subscription, pad.last_frame_s = sub, time.monotonic()
        try:
            while time.monotonic() < end:
                self._pass(min(0.05, max(end - time.monotonic(), 0.0)))
                self._diagnose()
        finally:
            for sub in subs:
                sub.close()
        return sum(pad.publisher.readings for pad in self.pads)

    def _warm_up(self) -> None:
        """One estimate of each pad's newest reading, unpublished: a model's first run is slow, and frames that
        queue meanwhile would make the first batches large."""
        from tactile_manip.errors import SensorError

        try:
            readings = [pad.sensor.read_latest(max_age_s=1.0) for pad in self.pads]
        except SensorError:
            return
        estimate_readings(self.estimator, readings)
        for pad, reading in zip(self.pads, readings):
            pad.publisher.warm_up(reading)

    def _pass(self, timeout_s: float) -> None:
        """Wait for frames (at most ``timeout_s``), then estimate and publish every frame that came."""
        from tactile_manip.errors import SensorTimeoutError

        batch: list[tuple[Pad, Any]] = []
        if len(self.pads) == 1:
            pad = self.pads[0]
            try:
                batch.append((pad, pad.subscription.get(timeout_s).reading))
            except SensorTimeoutError:
                return
            batch += [(pad, f.reading) for f in pad.subscription.drain()]
        else:
            batch = [(pad, f.reading) for pad in self.pads for f in pad.subscription.drain()]
            if not batch:
                time.sleep(min(0.001, timeout_s))
                return
        chunk = BATCH_PER_PAD * len(self.pads)  # a backlog is worked off in batches of the usual size
        for start in range(0, len(batch), chunk):
            part = batch[start:start + chunk]
            estimates = estimate_readings(self.estimator, [r for _, r in part])
            for (pad, reading), estimate in zip(part, estimates):
                pad.publisher.publish(reading, estimate)
                # when the frame came, not when the loop took it: a busy loop is not a sensor that stopped
                pad.last_frame_s = max(pad.last_frame_s, reading.t_host_s)

    def _diagnose(self) -> None:
        now = time.monotonic()
        changed = False
        for pad in self.pads:  # a pad going stale, or coming back, is reported at once, not at the next second
            stale = now - pad.last_frame_s > self.stale_s
            changed |= stale != (pad.level == m.STALE)
        if now < self._next_diag_s and not changed:
            return
        self._next_diag_s = now + DIAGNOSTICS_PERIOD_S
        slow = slow_client_events(self.transport)
        slow_clients, self._reported_slow = (slow - self._reported_slow, slow), slow
        self.diagnostics.publish([status(pad, now, self.stale_s, slow_clients=slow_clients) for pad in self.pads])


def summary(server: Server, transport_description: str, elapsed_s: float) -> str:
    readings = sum(p.publisher.readings for p in server.pads)
    drops = sum(p.publisher.drops for p in server.pads)
    rate = readings / len(server.pads) / elapsed_s if elapsed_s > 0 else 0.0
    slow = slow_client_events(server.transport)
    slow_text = f" ({slow} slow-client events: clients that fell behind lost messages)" if slow else ""
    return (f"serve: published {readings} readings from {len(server.pads)} pad(s) in {elapsed_s:.1f} s "
            f"({rate:.1f} per pad per s), {drops} messages dropped{slow_text}; {transport_description}")


def say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)
