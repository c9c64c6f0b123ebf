"""Typed configs of the sensor backends and the explicit backend table (docs/design.md, Scenes and Wire protocol).

Each backend is a config dataclass plus a ``"module:Class"`` entry in :data:`BACKENDS`, imported only when
chosen by :func:`make_sensor`. Every field carries its unit in a comment; ``__post_init__`` refuses bad values
with a ``ValueError`` naming the field, the value and what is allowed.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Literal

from tactile_manip.chips import ChipModelSpec, as_chip_spec

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
class DriftConfig:
    """Opt-in slow tracking of the baseline while the pad is unloaded, and the stray-field warning.

    Tracking rule: after a baseline is set, a frame counts as *quiet* when every channel of its field
    (``raw - offset``) is within ``quiet_ut``; once ``quiet_frames`` consecutive frames were quiet, each
    further quiet frame moves the offset towards the raw field by ``rate`` (an exponential average). Any
    loud frame stops tracking until ``quiet_frames`` quiet frames have passed again, so a press is never
    learnt into the baseline. Common-mode warning: when the median over chips of each axis has moved more than
    ``common_mode_ut`` from the baseline (all chips shifted together: a magnet or steel nearby, not a press),
    ``health().stray_field`` is set.
    """

    track: bool = False                # update the baseline while the pad is quiet (off: the baseline is fixed)
    quiet_ut: float = 15.0             # a frame is quiet when every |field| channel is below this, uT
    quiet_frames: int = 125            # quiet frames in a row before tracking starts (125 = 1 s at 125 Hz)
    rate: float = 0.002                # fraction of the way to the raw field per quiet frame (~4 s time constant)
    common_mode_ut: float = 30.0       # warn when the median field of every chip moved this much together, uT
    temperature_coeff_ut_per_c: tuple[float, ...] = ()  # per-chip field drift with temperature (x, y, z per
    # chip in firmware order, flattened; uT/degC), subtracted relative to the baseline's temperature; () = off

    def __post_init__(self) -> None:
        _positive(self, "quiet_ut", "common_mode_ut")
        if not isinstance(self.quiet_frames, int) or self.quiet_frames < 1:
            raise ValueError(f"DriftConfig.quiet_frames must be an integer >= 1, got {self.quiet_frames!r}")
        if not isinstance(self.rate, (int, float)) or not 0.0 < self.rate <= 1.0:
            raise ValueError(f"DriftConfig.rate must be in (0, 1], got {self.rate!r}")
        object.__setattr__(self, "temperature_coeff_ut_per_c", tuple(float(c) for c in self.temperature_coeff_ut_per_c))
        if len(self.temperature_coeff_ut_per_c) % 3:
            raise ValueError("DriftConfig.temperature_coeff_ut_per_c must hold 3 values (x, y, z) per chip, got "
                             f"{len(self.temperature_coeff_ut_per_c)}")


@dataclass(frozen=True)
class SerialSensorConfig:
    """The real sensor (or the firmware emulator) on a serial port.

    The board is named by ``port`` (a device path) or by ``serial_number`` (its USB serial number, looked up
    among the connected ports on every (re)open, so a pad keeps its name across replugs and reboots).
    """

    backend: ClassVar[str] = "serial"
    port: str = ""                     # device path, e.g. /dev/ttyUSB0 or the emulator's pty
    serial_number: str = ""            # USB serial number of the board, instead of port
    baudrate: int = 921600             # bit/s; 115200 cannot carry 125 Hz x 16 chips
    wire_format: str = "supermag"      # byte format: "supermag" (firmware/) or "anyskin" (ReSkin/AnySkin sketch)
    layout: str = ""                   # board layout (chip order, positions, rotations); "" = the format's default
    dtr: bool = False                  # DTR level held while open: low for ESP32 boards behind a USB bridge
    rts: bool = False                  # RTS level held while open (high on both for native-USB boards, e.g. SAMD21)
    read_timeout_s: float = 0.05       # a blocking read returns after this long without bytes, s
    exclusive: bool = True             # lock the port so a second program cannot read half the bytes
    drop_first_frames: int = 3         # frames discarded after every (re)open (stale or mid-reset data)
    connect_timeout_s: float = 2.0     # connect() fails when no valid frame arrives within this, s
    reconnect: bool = True             # reopen the port after an error, with exponential back-off
    reconnect_min_s: float = 0.05      # first back-off delay, s
    reconnect_max_s: float = 2.0       # back-off ceiling, s
    buffer_frames: int = 512           # ring buffer length, frames (~4 s at 125 Hz)
    chip: ChipModelSpec = field(default_factory=ChipModelSpec)  # LSBs and rail for counts -> uT, rated noise
    baseline: BaselineConfig = field(default_factory=BaselineConfig)
    drift: DriftConfig = field(default_factory=DriftConfig)

    def __post_init__(self) -> None:
        from tactile_manip.boards import load_board
        from tactile_manip.wire import DEFAULT_LAYOUTS, WIRE_FORMATS

        for name in ("port", "serial_number"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(f"SerialSensorConfig.{name} must be a string, got {getattr(self, name)!r}")
        if bool(self.port.strip()) == bool(self.serial_number.strip()):  # whitespace names no port either
            raise ValueError(f"SerialSensorConfig needs exactly one of port (a device path) and serial_number, got "
                             f"port={self.port!r}, serial_number={self.serial_number!r}; "
                             "run `tactile-manip find-port` to list candidates")
        if self.wire_format not in WIRE_FORMATS:
            raise ValueError(f"SerialSensorConfig.wire_format must be one of {', '.join(WIRE_FORMATS)}, "
                             f"got {self.wire_format!r}")
        if not self.layout:
            object.__setattr__(self, "layout", DEFAULT_LAYOUTS[self.wire_format])
        # a chip given as the simulator's ChipParams keeps only its hardware part, what the driver reads
        object.__setattr__(self, "chip", as_chip_spec(self.chip))
        try:
            n_chips = load_board(self.layout).n_chips
        except ValueError as e:
            raise ValueError(f"SerialSensorConfig.layout: {e}") from None
        n_coeff = len(self.drift.temperature_coeff_ut_per_c)
        if n_coeff and n_coeff != 3 * n_chips:
            raise ValueError(f"SerialSensorConfig.drift.temperature_coeff_ut_per_c has {n_coeff} values; the "
                             f"{self.layout} board needs 3 per chip ({3 * n_chips})")
        for name in ("dtr", "rts", "exclusive", "reconnect"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"SerialSensorConfig.{name} must be true or false, got {getattr(self, name)!r}")
        _positive(self, "baudrate", "read_timeout_s", "connect_timeout_s", "reconnect_min_s", "reconnect_max_s",
                  "buffer_frames")
        _positive(self, "drop_first_frames", allow_zero=True)
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError(f"SerialSensorConfig.reconnect_max_s ({self.reconnect_max_s}) must be >= "
                             f"reconnect_min_s ({self.reconnect_min_s})")

    @property
    def source(self) -> str:
        """What the sensor is called in messages and recordings: the port, or ``usb-serial:NUMBER``."""
        return self.port or f"usb-serial:{self.serial_number}"


@dataclass(frozen=True)
class SimulatedSensorConfig:
    """The simulator in process: readings at the chip rate from a :class:`~tactile_manip.sim.pair.SensorPair`."""

    backend: ClassVar[str] = "simulated"
    board: str = "supermag-4x4"        # the simulated board: a shipped name or a board file with [body] and [layer]
    seed: int = 0                      # noise seed (the frame noise sequence is fixed by it)
    rate_hz: float = 125.0             # frame clock, Hz
    buffer_frames: int = 512           # ring buffer length, frames
    baseline: BaselineConfig = field(default_factory=BaselineConfig)

    def __post_init__(self) -> None:
        from tactile_manip.boards import load_board

        _positive(self, "rate_hz", "buffer_frames")
        try:
            load_board(self.board).require_simulation()
        except ValueError as e:
            raise ValueError(f"SimulatedSensorConfig.board: {e}") from None


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
