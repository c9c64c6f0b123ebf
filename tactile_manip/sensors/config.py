"""Typed configs of the sensor backends and the explicit backend table (DESIGN.md sections 3 and 6).

Each backend is a config dataclass plus a ``"module:Class"`` entry in :data:`BACKENDS`, imported only when
chosen by :func:`make_sensor`. Every field carries its unit in a comment; ``__post_init__`` refuses bad values
with a ``ValueError`` naming the field, the value and what is allowed.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Literal

from tactile_manip.sim.params import ChipParams

if TYPE_CHECKING:
    from tactile_manip.sensors.base import TactileSensor

BACKENDS: dict[str, str] = {
    "serial": "tactile_manip.sensors.serial_sensor:SerialSensor",
    "simulated": "tactile_manip.sensors.simulated:SimulatedSensor",
    "replay": "tactile_manip.sensors.replay:ReplaySensor",
}


def _positive(obj: object, *names: str, allow_zero: bool = False) -> None:
    for name in names:
        v = getattr(obj, name)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not (v >= 0 if allow_zero else v > 0):
            want = ">= 0" if allow_zero else "> 0"
            raise ValueError(f"{type(obj).__name__}.{name} must be a number {want}, got {v!r}")


@dataclass(frozen=True)
class BaselineConfig:
    """How a baseline is taken and when it is refused."""

    frames: int = 125                  # frames averaged (125 = 1 s at 125 Hz)
    noise_factor: float = 6.0          # refuse when a channel's std exceeds this times the chip's rated noise
    max_noise_ut: float | None = None  # absolute std threshold for every channel instead, uT
    timeout_s: float = 5.0             # give up collecting the frames after this long, s

    def __post_init__(self) -> None:
        if not isinstance(self.frames, int) or self.frames < 2:
            raise ValueError(f"BaselineConfig.frames must be an integer >= 2, got {self.frames!r}")
        _positive(self, "noise_factor", "timeout_s")
        if self.max_noise_ut is not None:
            _positive(self, "max_noise_ut")


@dataclass(frozen=True)
class SerialSensorConfig:
    """The real sensor (or the firmware emulator) on a serial port."""

    backend: ClassVar[str] = "serial"
    port: str = ""                     # device path, e.g. /dev/ttyUSB0 or the emulator's pty
    baudrate: int = 921600             # bit/s; 115200 cannot carry 125 Hz x 16 chips
    read_timeout_s: float = 0.05       # a blocking read returns after this long without bytes, s
    exclusive: bool = True             # lock the port so a second program cannot read half the bytes
    drop_first_frames: int = 3         # frames discarded after every (re)open (stale or mid-reset data)
    connect_timeout_s: float = 2.0     # connect() fails when no valid frame arrives within this, s
    reconnect: bool = True             # reopen the port after an error, with exponential back-off
    reconnect_min_s: float = 0.05      # first back-off delay, s
    reconnect_max_s: float = 2.0       # back-off ceiling, s
    buffer_frames: int = 512           # ring buffer length, frames (~4 s at 125 Hz)
    chip: ChipParams = field(default_factory=ChipParams)  # LSBs and rail for counts -> uT, rated noise
    baseline: BaselineConfig = field(default_factory=BaselineConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.port, str) or not self.port.strip():
            raise ValueError(f"SerialSensorConfig.port must be a device path, got {self.port!r}; "
                             "run `tactile-manip find-port` to list candidates")
        _positive(self, "baudrate", "read_timeout_s", "connect_timeout_s", "reconnect_min_s", "reconnect_max_s",
                  "buffer_frames")
        _positive(self, "drop_first_frames", allow_zero=True)
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError(f"SerialSensorConfig.reconnect_max_s ({self.reconnect_max_s}) must be >= "
                             f"reconnect_min_s ({self.reconnect_min_s})")


@dataclass(frozen=True)
class SimulatedSensorConfig:
    """The simulator in process: readings at the chip rate from a :class:`~tactile_manip.sim.pair.SensorPair`."""

    backend: ClassVar[str] = "simulated"
    seed: int = 0                      # noise seed (the frame noise sequence is fixed by it)
    rate_hz: float = 125.0             # frame clock, Hz
    buffer_frames: int = 512           # ring buffer length, frames
    baseline: BaselineConfig = field(default_factory=BaselineConfig)

    def __post_init__(self) -> None:
        _positive(self, "rate_hz", "buffer_frames")


@dataclass(frozen=True)
class ReplaySensorConfig:
    """A recording played back through the sensor interface."""

    backend: ClassVar[str] = "replay"
    path: str = ""                     # recording written by `tactile-manip record`
    pace: Literal["recorded", "on_demand"] = "recorded"  # recorded timing, or one frame per read
    speed: float = 1.0                 # playback speed factor with pace="recorded"
    loop: bool = False                 # start again at the end instead of going stale
    buffer_frames: int = 512           # ring buffer length, frames
    baseline: BaselineConfig = field(default_factory=BaselineConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.path, str) or not self.path.strip():
            raise ValueError(f"ReplaySensorConfig.path must name a recording file, got {self.path!r}")
        if self.pace not in ("recorded", "on_demand"):
            raise ValueError(f"ReplaySensorConfig.pace must be 'recorded' or 'on_demand', got {self.pace!r}")
        _positive(self, "speed", "buffer_frames")


SensorConfig = SerialSensorConfig | SimulatedSensorConfig | ReplaySensorConfig


def make_sensor(config: SensorConfig, **kwargs: object) -> TactileSensor:
    """Build (not connect) the backend named by ``config.backend``; ``kwargs`` go to its constructor."""
    if not dataclasses.is_dataclass(config) or getattr(config, "backend", None) not in BACKENDS:
        raise ValueError(f"config must be one of the sensor config classes ({', '.join(BACKENDS)}), "
                         f"got {type(config).__name__}")
    module, _, name = BACKENDS[config.backend].partition(":")
    return getattr(importlib.import_module(module), name)(config, **kwargs)
