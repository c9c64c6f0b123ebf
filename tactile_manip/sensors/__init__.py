"""Magnetic tactile sensors behind one interface: the serial driver, the simulated and the replayed sensor.

- :class:`TactileSensor`: the contract (connect, ``read_latest``, ``wait_new``, ``window``, baseline, health);
- backends :class:`SerialSensor` (pyserial, imported on connect), :class:`SimulatedSensor`,
  :class:`ReplaySensor`, each built from its config dataclass or by :func:`make_sensor`;
- :mod:`~tactile_manip.sensors.protocol`: the SuperMag wire codec; :mod:`~tactile_manip.sensors.wire`: the
  wire formats of the serial backend (supermag, anyskin); :mod:`~tactile_manip.sensors.layout`: board layouts;
  :mod:`~tactile_manip.sensors.drift`: baseline tracking, temperature, stray fields;
  :mod:`~tactile_manip.sensors.emulator`: the firmware emulator on a pty; :mod:`~tactile_manip.sensors.recording`:
  crash-safe recordings.

Importing this package does not import pyserial or matplotlib. See ``docs/sensors.md``.
"""

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
from tactile_manip.sensors.contacts import ContactTimeline, Press, parse_press
from tactile_manip.sensors.layout import LAYOUTS, BoardLayout, ChipPlacement, get_layout
from tactile_manip.sensors.recording import Recorder, Recording, RecordingWriter, read_recording
from tactile_manip.sensors.replay import ReplaySensor
from tactile_manip.sensors.serial_sensor import SerialSensor
from tactile_manip.sensors.simulated import SimulatedSensor

__all__ = [
    "BACKENDS",
    "Baseline",
    "BaselineConfig",
    "BoardLayout",
    "ChipPlacement",
    "ContactTimeline",
    "DriftConfig",
    "LAYOUTS",
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
    "get_layout",
    "make_sensor",
    "parse_press",
    "read_recording",
]
