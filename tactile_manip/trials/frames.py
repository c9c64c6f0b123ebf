"""Per-frame streams of a trial: every sensor frame with the arm, gripper, estimate and phase at that moment.

One file per (trial, method): ``RUN_DIR/frames/<method>-<trial:04d>.tmframes``, an append-only framed file
(``tactile_manip.logs.framed_file``) that survives a crash as the trial log does::

    line 1   b"tactile_manip trial frames\\n"
    line 2   one JSON object + b"\\n": format version, trial, method, seed, object, rate_hz, grid, target, ...
    records  tag (2 bytes) | payload length u32 | t_host_s f64 | payload | crc32 u32, little-endian

Tag ``TF`` is one frame; its payload is one row of :data:`frame_dtype` for the header's grid (sequence
number, device time, phase, the latest estimate, joints, gripper width, target, baseline-subtracted and raw
field). The writer fsyncs at least every 0.5 s and when the trial ends; the reader keeps every intact record
and reports a torn tail or damage in the middle (as recordings do). A resumed run writes a re-run trial's
file anew.

What the streams hold: every frame the sensor published from the start of the grasp until one frame after
the gripper opened (at most :data:`RELEASE_S` after the release began), at the sensor rate. The behaviour
announces each phase (grasp, estimate, turn; the cell announces release) and each estimate; the frames that
arrived before an announcement are stamped with the state that held until it: the arm's joints and the
gripper's width are read at each announcement and once more when the trial ends (a twin moves in one step;
a real arm's joints are held between announcements). The estimate of a frame is the latest one of the trial
so far (NaN before the first).

Events (tag ``EV``, a JSON object each, read back in ``TrialFrames.events``): with a scene's contact model,
one ``{"event": "grip_force", "force_n", "force_sigma_n", "in_contact"}`` when the model read the grip force
at the estimate step, written after the frames that came before it.
"""

from __future__ import annotations

import json
import math
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.errors import RecordingError, RobotError, SensorError
from tactile_manip.logs.framed_file import CRC32, TAG_EVENT, FramedWriter, read_header, scan_records

MAGIC = b"tactile_manip trial frames\n"
FORMAT_VERSION = 1
RECORD = struct.Struct("<2sId")
TAG_FRAME = b"TF"
FRAMES_DIR = "frames"
SUFFIX = ".tmframes"
PHASES = ("", "grasp", "estimate", "turn", "release")
N_JOINTS = 7
RELEASE_S = 0.25  # frames kept after the release starts, s (an operator cell waits for a person meanwhile)


def frame_dtype(grid: tuple[int, int]) -> np.dtype:
    """Little-endian record layout of one frame for a ``grid`` = (rows, cols) board."""
    rows, cols = grid
    return np.dtype([("seq", "<i8"), ("t_device_s", "<f8"), ("phase", "u1"), ("angle_rad", "<f8"),
                     ("confidence", "<f8"), ("joints_rad", "<f8", (N_JOINTS,)), ("gripper_width_m", "<f8"),
                     ("target_angle_rad", "<f8"), ("field_ut", "<f4", (rows, cols, 3)),
                     ("field_raw_ut", "<f4", (rows, cols, 3))])


def frames_path(run_dir: str | Path, trial: int, method: str) -> Path:
    """``RUN_DIR/frames/<method>-<trial:04d>.tmframes``."""
    return Path(run_dir) / FRAMES_DIR / f"{method}-{trial:04d}{SUFFIX}"


class TrialFrameStream:
    """Record one trial's frames to ``path`` (see the module docstring); the behaviour's observer.

    Use as a context manager around the trial: entering creates the file and subscribes to ``sensor``;
    :meth:`phase` and :meth:`estimate` are called by the behaviour; leaving keeps the release frames and
    closes the file. Frames published before the first :meth:`phase` are not kept.

    Args:
        path: file to create (an existing one is replaced).
        sensor: the trial's connected :class:`~tactile_manip.sensors.base.TactileSensor`.
        arm, gripper: read at each announcement (None: NaN joints / width).
        header: JSON-serialisable facts of the trial (trial, method, seed, object, ...), stored in the file;
            give ``code_version`` (computed once per run) or each file runs git for it.
        target_angle_rad: the commanded in-hand angle of the trial.
    """

    def __init__(self, path: str | Path, *, sensor, arm=None, gripper=None, header: dict[str, Any],
                 target_angle_rad: float, sync_every_s: float = 0.5) -> None:
        self.path = Path(path)
        self._sensor, self._arm, self._gripper = sensor, arm, gripper
        self._header, self._sync_every_s = header, sync_every_s
        self._target = float(target_angle_rad)
        self._phase: str | None = None
        self._angle = self._confidence = math.nan
        self._release_t: float | None = None
        self._row: np.ndarray | None = None  # the state since the last change, as a frame row
        self._sub = self._writer = None
        self.frames = 0

    def __enter__(self) -> TrialFrameStream:
        grid = tuple(int(n) for n in self._sensor.layout.grid)
        self._dtype = frame_dtype(grid)
        head = {"format": "tactile_manip.trial_frames", "format_version": FORMAT_VERSION, **self._header,
                "rate_hz": float(self._sensor.chip.rate_hz), "grid": list(grid), "layout": self._sensor.layout.name,
                "target_angle_rad": self._target, "phases": list(PHASES),
                "host_clock": "time.monotonic() of the trial host, s"}
        # the header is not synced on its own: a trial's frames matter once the trial is logged, and the close
        # syncs them before the runner appends its record (a killed trial is run again on resume)
        self._writer = FramedWriter(self.path, MAGIC, head, RECORD, sync_every_s=self._sync_every_s,
                                    sync_header=False)
        try:
            self._sub = self._sensor.subscribe(max_frames=1 << 14)
        except BaseException:
            self._writer.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._phase is not None:
                self._drain()
                if exc[0] is None:
                    self._row = self._state_row()  # the gripper has opened
                    self._wait_for_frame_after(time.monotonic())
                    self._drain()
        finally:
            self._sub.close()
            self._writer.close()

    # ------------------------------------------------------------------ the behaviour's observer

    def phase(self, name: str) -> None:
        """From now on the trial is in phase ``name`` (one of PHASES but "")."""
        if name not in PHASES[1:]:
            raise ValueError(f"phase: expected one of {PHASES[1:]}, got {name!r}")
        if self._phase is None:
            self._sub.drain()  # before the trial: not kept
        else:
            self._drain()
        self._phase = name
        self._row = self._state_row()
        if name == "release":
            self._release_t = time.monotonic()

    def estimate(self, est) -> None:
        """An estimate was made (an :class:`~tactile_manip.types.AngleEstimate`); later frames carry it."""
        self._drain()
        self._angle = float(est.angle_rad) if est.defined else math.nan
        self._confidence = float(est.confidence)
        if self._phase is not None:
            self._row = self._state_row()

    def contact(self, state) -> None:
        """The contact model's grip force (a :class:`~tactile_manip.perception.contact.ContactState`): an event."""
        self._drain()
        self._writer.write_event(time.monotonic(), {"event": "grip_force", "force_n": state.force_n,
                                                    "force_sigma_n": state.force_sigma_n,
                                                    "in_contact": bool(state.in_contact)})

    # ------------------------------------------------------------------ internals

    def _wait_for_frame_after(self, t_end: float) -> None:
        """Keep frames until one newer than ``t_end`` (the gripper has opened) or 3 frame periods passed."""
        deadline = t_end + 3.0 / self._sensor.chip.rate_hz
        try:
            while True:
                item = self._sub.get(deadline - time.monotonic())
                self._write(item)
                if item.reading.t_host_s >= t_end:
                    return
        except SensorError:  # no frame in time (a stalled sensor): keep what came
            return

    def _drain(self) -> None:
        """Write the frames queued now with the state that held while they came (taken at the last change)."""
        for item in self._sub.drain():
            self._write(item)

    def _state_row(self) -> np.ndarray:
        """A frame row holding the state now (phase, latest estimate, joints, width, target)."""
        row = np.zeros((), self._dtype)
        row["phase"] = PHASES.index(self._phase)
        row["angle_rad"], row["confidence"] = self._angle, self._confidence
        row["joints_rad"], row["gripper_width_m"] = self._joints(), self._width()
        row["target_angle_rad"] = self._target
        return row

    def _write(self, item) -> None:
        r = item.reading
        if self._release_t is not None and r.t_host_s > self._release_t + RELEASE_S:
            return
        row = self._row
        row["seq"], row["t_device_s"] = r.seq, r.t_device_s
        row["field_ut"], row["field_raw_ut"] = r.field_ut, r.field_raw_ut
        self._writer.write_record(TAG_FRAME, r.t_host_s, row.tobytes())
        self.frames += 1

    def _joints(self) -> np.ndarray:
        if self._arm is None:
            return np.full(N_JOINTS, np.nan)
        try:
            return np.asarray(self._arm.state().q_rad, np.float64)
        except RobotError:
            return np.full(N_JOINTS, np.nan)

    def _width(self) -> float:
        if self._gripper is None:
            return math.nan
        try:
            return float(self._gripper.state().width_m)
        except RobotError:
            return math.nan


@dataclass(frozen=True, eq=False)
class TrialFrames:
    """A trial's frames read back; arrays have one entry per frame, in file order.

    Attributes:
        path: the file.
        header: trial, method, seed, object, rate_hz, grid, layout, target_angle_rad, ...
        t_host_s: (N,) host monotonic time of each frame, s.
        rows: (N,) structured array of :func:`frame_dtype` (seq, t_device_s, phase, angle_rad, confidence,
            joints_rad, gripper_width_m, target_angle_rad, field_ut, field_raw_ut).
        events: the file's events in order, each with its ``t_host_s`` (see the module docstring).
        truncated_bytes, skipped_bytes, damaged_records: what was lost (see ``framed_file.Scan``).
    """

    path: Path
    header: dict[str, Any]
    t_host_s: np.ndarray
    rows: np.ndarray
    events: list[dict[str, Any]] = field(default_factory=list)
    truncated_bytes: int = 0
    skipped_bytes: int = 0
    damaged_records: int = 0

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def phases(self) -> list[str]:
        return [PHASES[int(k)] for k in self.rows["phase"]]


def read_trial_frames(path: str | Path) -> TrialFrames:
    """Read a trial's frames, keeping every intact record (a torn tail and damaged records are counted).

    Raises:
        RecordingError: missing file, not a trial frames file, a newer format, or a header without a grid.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError as e:
        raise RecordingError(f"trial frames not found: {path}") from e
    header, pos = read_header(data, path, MAGIC, "trial frames file", FORMAT_VERSION)
    try:
        dtype = frame_dtype(tuple(int(n) for n in header["grid"]))
    except (KeyError, TypeError, ValueError) as e:
        raise RecordingError(f"{path}: the header has no valid grid: {e}") from None
    scan = scan_records(data, pos, RECORD, (TAG_FRAME, TAG_EVENT))
    times, payloads, events = [], [], []
    for tag, t_host, payload in scan.records:
        if tag == TAG_FRAME and len(payload) == dtype.itemsize:
            times.append(t_host)
            payloads.append(payload)
        elif tag == TAG_EVENT:
            try:
                events.append({"t_host_s": t_host, **json.loads(payload)})
            except (ValueError, TypeError):
                scan.skip(RECORD.size + len(payload) + CRC32.size)
        elif tag == TAG_FRAME:  # intact on disk but not a frame of this grid
            scan.skip(RECORD.size + len(payload) + CRC32.size)
    rows = np.frombuffer(b"".join(payloads), dtype) if payloads else np.zeros(0, dtype)
    return TrialFrames(path, header, np.array(times, np.float64), rows, events, truncated_bytes=scan.truncated_bytes,
                       skipped_bytes=scan.skipped_bytes, damaged_records=scan.damaged_records)
