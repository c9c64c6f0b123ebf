"""Crash-safe log files: the append-only framed file (:mod:`~tactile_manip.logs.framed_file`) under recordings,
pair logs and trial frame logs, and the sensor recording format with its writer and reader
(:mod:`~tactile_manip.logs.recording`).

Numpy and the core only (plus :mod:`tactile_manip.wire` to decode recorded frames), so the data layer reads
recordings without importing the sensors layer (docs/design.md, Layers).
"""
