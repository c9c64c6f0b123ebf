"""A connected sensor streamed to Rerun frame by frame: what ``tactile-manip view --rerun`` runs.

Every frame the sensor publishes is logged (a subscription, so none is skipped while an estimate runs);
the estimator runs on the newest frame at most ``estimate_hz`` times a second and its depth image, angle
and confidence are logged at that frame's time.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from tactile_manip.interop.rerun_sink import DEFAULT_PORT, LOCALHOST, open_live


def load_estimator(model: str, layout_name: str):
    """A :class:`~tactile_manip.perception.estimator.TactilePoseEstimator` for ``model`` ("none": None)."""
    if model.lower() == "none":
        return None
    from tactile_manip.perception.estimator import TactilePoseEstimator
    from tactile_manip.perception.reconstruct import load_reconstructor

    reconstructor = load_reconstructor(model)
    reconstructor.check_layout(layout_name)
    return TactilePoseEstimator(reconstructor)


def stream_to_rerun(sensor, *, save: str | Path | None = None, spawn: bool = False, serve: bool = False,
                    bind: str = LOCALHOST, port: int = DEFAULT_PORT, model: str = "bilinear",
                    estimate_hz: float = 10.0, seconds: float | None = None, name: str = "mbts") -> int:
    """Log ``sensor``'s frames (and estimates from ``model``) until ``seconds`` pass or Ctrl-C; returns 0 when
    frames were logged, 1 when none came. With no sink given, a viewer is spawned. A server started here is
    stopped on the way out, whatever ends the stream."""
    from tactile_manip.interop.rerun_log import EntityPaths, RerunLogger, blueprint

    estimator = load_estimator(model, sensor.layout.name)  # a bad model fails before a viewer starts
    if save is None and not serve:
        spawn = True
    logger, interrupted = None, None
    with open_live(save=save, spawn=spawn, serve=serve, bind=bind, port=port, recording_name=f"view {sensor.source}",
                   default_blueprint=blueprint(EntityPaths(name))) as sink:  # closed (a server stopped) however we end
        print(f"view: {sensor.source} -> Rerun, {sink.description}" + "".join(f"\nview: {n}" for n in sink.notes),
              file=sys.stderr, flush=True)
        try:
            logger = RerunLogger(sink.recording, name=name, grid=sensor.layout.grid, layout=sensor.layout)
            _log_frames(sensor, logger, estimator, estimate_hz=estimate_hz, seconds=seconds)
        except KeyboardInterrupt as e:  # Ctrl-C (or SIGTERM, raised as one by the CLI) ends the stream
            interrupted = e
        finally:
            if logger is not None:
                logger.flush()
    frames = 0 if logger is None else logger.frames
    print(f"view: logged {frames} frames to Rerun ({sink.description})", file=sys.stderr)
    if interrupted is not None:  # the file finished and the server stopped: the CLI exits 130 (143 for SIGTERM)
        raise interrupted
    return 0 if frames else 1


def _log_frames(sensor, logger, estimator, *, estimate_hz: float, seconds: float | None) -> None:
    """Every frame of ``sensor`` to ``logger``, the estimate at most ``estimate_hz`` times a second, for
    ``seconds`` (None: until interrupted)."""
    from tactile_manip.errors import SensorTimeoutError

    period = 1.0 / estimate_hz
    next_estimate = -math.inf
    end = math.inf if seconds is None else time.monotonic() + seconds
    with sensor.subscribe() as frames:
        while time.monotonic() < end:
            try:
                reading = frames.get(timeout_s=min(0.5, max(end - time.monotonic(), 0.0))).reading
            except SensorTimeoutError:
                continue
            logger.log_reading(reading)
            if estimator is not None and reading.t_host_s >= next_estimate:
                next_estimate = reading.t_host_s + period
                est, rec = estimator.estimate_with_image(reading)
                logger.log_estimate(angle_rad=est.angle_rad if est.defined else math.nan,
                                    confidence=est.confidence, depth_mm=rec.depth_mm)
