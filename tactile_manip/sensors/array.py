"""Several sensors used together (e.g. one board per finger): connect, read and close them as one.

Each sensor keeps its own port and reader thread; this helper only makes the lifecycle all-or-nothing and
returns readings as tuples in the order the sensors were given.
"""

from __future__ import annotations

from collections.abc import Sequence

from tactile_manip.sensors.base import SensorHealth, TactileSensor
from tactile_manip.types import TactileReading


class SensorArray:
    """A fixed list of :class:`~tactile_manip.sensors.base.TactileSensor` handled together.

    ``connect()`` connects them in order and, if one fails, disconnects those already connected before
    re-raising. Reading methods raise what the first failing sensor raises.
    """

    def __init__(self, sensors: Sequence[TactileSensor]) -> None:
        if not sensors:
            raise ValueError("SensorArray needs at least one sensor")
        self.sensors = tuple(sensors)

    def __len__(self) -> int:
        return len(self.sensors)

    def __getitem__(self, i: int) -> TactileSensor:
        return self.sensors[i]

    def connect(self) -> None:
        done: list[TactileSensor] = []
        try:
            for s in self.sensors:
                s.connect()
                done.append(s)
        except BaseException:
            for s in reversed(done):
                s.disconnect()
            raise

    def disconnect(self) -> None:
        """Disconnect every sensor (idempotent); the first error, if any, is raised after all were tried."""
        first: BaseException | None = None
        for s in self.sensors:
            try:
                s.disconnect()
            except BaseException as e:  # noqa: BLE001 - close the others before reporting
                first = first or e
        if first is not None:
            raise first

    def __enter__(self) -> SensorArray:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    def read_latest(self, max_age_s: float = 0.1) -> tuple[TactileReading, ...]:
        """The newest reading of every sensor (each checked against ``max_age_s``)."""
        return tuple(s.read_latest(max_age_s) for s in self.sensors)

    def wait_new(self, timeout_s: float = 0.1) -> tuple[TactileReading, ...]:
        """An unseen reading from every sensor, each waited for up to ``timeout_s``."""
        return tuple(s.wait_new(timeout_s) for s in self.sensors)

    def calibrate_baseline(self, frames: int | None = None) -> None:
        """Take every sensor's baseline (the pads must all be free)."""
        for s in self.sensors:
            s.calibrate_baseline(frames)

    def health(self) -> list[SensorHealth]:
        return [s.health() for s in self.sensors]
