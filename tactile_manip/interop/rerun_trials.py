"""Watching a trial run in Rerun (``tactile-manip trials --rerun``): every sensor frame, the arm, each outcome.

:class:`RerunTrialObserver` is handed to the trial runner. On the first trial it subscribes to the cell's
sensor and logs every frame from a thread of its own (the field as arrows and the Bz heat map, the arm's joints
and the gripper's width at ``robot_hz``), so the behaviour's own code and timing loop are untouched (the
thread does take CPU time: ``benchmarks/bench_rerun.py``). At each trial's start it logs a line naming the
trial, object, presented angle and force, and that angle as a scalar; at its end the estimate (angle,
confidence), the target and the outcome. Everything sits on the sensor clock of the whole run (entity paths and timelines of
:mod:`tactile_manip.interop.rerun_log`).
"""

from __future__ import annotations

import math
import threading

from tactile_manip.interop.rerun_log import EPISODE, TRUE_ANGLE, RerunLogger


class RerunTrialObserver:
    """Logs a trial run to the recording of ``sink`` (a :class:`~tactile_manip.interop.rerun_sink.LiveSink`).

    Args:
        sink: where the recording goes; closed by :meth:`close`.
        robot_hz: arm and gripper samples per second (the sensor's frames are all logged).
    """

    def __init__(self, sink, *, robot_hz: float = 25.0) -> None:
        if not (robot_hz > 0 and math.isfinite(robot_hz)):
            raise ValueError(f"robot_hz: expected a positive rate, got {robot_hz}")
        self.sink, self.robot_period_s = sink, 1.0 / robot_hz
        self.logger: RerunLogger | None = None
        self._cell = None
        self._stop = threading.Event()
        self._first_frame = threading.Event()
        self._thread: threading.Thread | None = None
        self.trials = 0

    def trial_started(self, p, method: str, cell) -> None:
        if self._thread is None:
            self._start(cell)
        self.logger.log_text(EPISODE, f"trial {p.trial} ({method}): {p.obj.display_name} at "
                                      f"{math.degrees(p.angle_rad):.1f} deg, {p.force_n:.1f} N")
        self.logger.log_scalar(TRUE_ANGLE, math.degrees(p.angle_rad))

    def trial_finished(self, record) -> None:
        angle = record.estimated_angle_rad
        self.logger.log_estimate(angle_rad=math.nan if angle is None else angle, confidence=record.confidence)
        self.logger.log_robot(target_angle_rad=record.target_angle_rad)
        error = "" if record.error_rad is None else f", error {math.degrees(record.error_rad):.1f} deg"
        self.logger.log_text(EPISODE, f"trial {record.trial} ({record.method}): {record.outcome}{error}")
        self.trials += 1

    def close(self) -> None:
        """Stop the frame thread and close the sink (the file is complete, a server this process started stops,
        even when the last flush fails)."""
        self._stop.set()
        try:
            if self._thread is not None:
                self._thread.join(timeout=5.0)
                self.logger.flush()
        finally:
            self.sink.close()

    def __enter__(self) -> RerunTrialObserver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------- the frame thread

    def _start(self, cell) -> None:
        sensor = cell.sensor
        self._cell = cell
        self.logger = RerunLogger(self.sink.recording, grid=sensor.layout.grid, layout=sensor.layout)
        rr = self.logger.rr
        rr.log(TRUE_ANGLE, rr.SeriesLines(names="true angle (deg)"), static=True, recording=self.sink.recording)
        subscription = sensor.subscribe()
        self._thread = threading.Thread(target=self._run, args=(subscription,), name="rerun-trials", daemon=True)
        self._thread.start()
        self._first_frame.wait(timeout=1.0)  # so the first trial's line lands on the sensor clock too

    def _run(self, subscription) -> None:
        from tactile_manip.errors import SensorTimeoutError

        next_robot = -math.inf
        with subscription:
            while not self._stop.is_set():
                try:
                    reading = subscription.get(timeout_s=0.2).reading
                except SensorTimeoutError:
                    continue
                self.logger.log_reading(reading)
                self._first_frame.set()
                if reading.t_host_s >= next_robot:
                    next_robot = reading.t_host_s + self.robot_period_s
                    self._log_robot()

    def _log_robot(self) -> None:
        try:  # the arm or gripper may be between connections: a missed sample is not an error
            q = self._cell.arm.state().q_rad
            width = self._cell.gripper.state().width_m
        except Exception:  # noqa: BLE001 - watching must never stop the run
            return
        self.logger.log_robot(joints_rad=q, gripper_width_m=width)
