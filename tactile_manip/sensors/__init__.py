"""Magnetic tactile sensors behind one interface: the serial driver, the simulated and the replayed sensor.

- :class:`TactileSensor`: the contract (connect, ``read_latest``, ``wait_new``, ``window``, baseline, health);
- backends :class:`SerialSensor` (pyserial, imported on connect), :class:`SimulatedSensor`,
  :class:`ReplaySensor`, each built from its config dataclass or by :func:`make_sensor`;
- :class:`~tactile_manip.boards.Board`: where a board's chips feed the reading; :mod:`~tactile_manip.sensors.drift`: baseline tracking,
  temperature, stray fields; :mod:`~tactile_manip.sensors.simulated.emulator`: the firmware emulator on a pty;
  :mod:`~tactile_manip.sensors.recording`: recording a live sensor to a crash-safe file.

The wire formats the serial backend decodes (the SuperMag codec, supermag and anyskin decoders) live below this
layer in :mod:`tactile_manip.wire`, and the recording file format and its reader in
:mod:`tactile_manip.logs.recording`; ``sensors.protocol``, ``sensors.wire`` and ``sensors.framed_file`` name the
same objects.

Importing this package does not import pyserial or matplotlib, nor the simulator: :class:`SimulatedSensor` and
the press timeline (:class:`ContactTimeline`, :class:`Press`, :func:`parse_press`) drive it and load it when
first named. See ``docs/sensors.md``.
"""

import importlib
from typing import Any

from tactile_manip.logs.recording import Recording, RecordingWriter, read_recording
from tactile_manip.sensors.array import SensorArray
from tactile_manip.sensors.base import FrameSubscription, SensorFrame, SensorHealth, TactileSensor
from tactile_manip.sensors.baseline import Baseline
from tactile_manip.sensors.config import (
    BACKENDS,
    BaselineConfig,
    DriftConfig,
    ReplaySensorConfig,
    SerialSensorConfig,
    SimulatedSensorConfig,
    make_sensor,
)
from tactile_manip.sensors.recording import Recorder
from tactile_manip.sensors.replay import ReplaySensor
from tactile_manip.sensors.serial_sensor import SerialSensor

__all__ = [
    "BACKENDS",
    "Baseline",
    "BaselineConfig",
    "ContactTimeline",
    "DriftConfig",
    "FrameSubscription",
    "Press",
    "Recorder",
    "Recording",
    "RecordingWriter",
    "ReplaySensor",
    "ReplaySensorConfig",
    "SensorArray",
    "SensorFrame",
    "SensorHealth",
    "SerialSensor",
    "SerialSensorConfig",
    "SimulatedSensor",
    "SimulatedSensorConfig",
    "TactileSensor",
    "make_sensor",
    "parse_press",
    "read_recording",
]

# what drives the simulator, imported on first use so the drivers and recordings stay free of it
_SIMULATOR_DRIVEN = {
    "ContactTimeline": "tactile_manip.sensors.simulated.contacts",
    "Press": "tactile_manip.sensors.simulated.contacts",
    "parse_press": "tactile_manip.sensors.simulated.contacts",
    "SimulatedSensor": "tactile_manip.sensors.simulated",
}


def __getattr__(name: str) -> Any:
    if name in _SIMULATOR_DRIVEN:
        return getattr(importlib.import_module(_SIMULATOR_DRIVEN[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
