"""``tactile-manip view``: the 4x4x3 field of a sensor, live (z as a heat map, x-y as arrows).

``--port`` reads the board (or the emulator), ``--sim`` the simulated sensor pressing an object again and
again, ``--replay`` a recording. ``--snapshot out.png --seconds N`` runs headless for N seconds and saves the
last frame, so the view works (and is tested) without a display.

``--rerun`` streams every frame to Rerun instead (extra ``viz``): the field as arrows at the taxels, a Bz heat
map, and, from ``--model`` at ``--estimate-hz``, the reconstructed depth and the angle and confidence, on the
sensor clock. It goes to a file (``--save F.rrd``), a viewer it starts (``--spawn``, the default) or a gRPC
server (``--serve``), both listening on 127.0.0.1 unless ``--bind`` names another address. It ends after
``--seconds``, at Ctrl-C or at SIGTERM (which the CLI raises as a KeyboardInterrupt), each time finishing the
file or stopping the server it started.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from tactile_manip.commands.rerun_options import add_rerun_options, check_rerun_options
from tactile_manip.commands.serial_options import add_serial_options, check_sim_board, serial_config

DEFAULT_SIM_PRESS = "letter_r,t=0.3,force=10,yaw=20,rise=0.4,hold=0.6"
RANGE_FLOOR_UT = 20.0  # the colour and arrow scales never zoom in below this, so idle noise looks like noise


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="serial port of the board (or the emulator's path)")
    src.add_argument("--sim", action="store_true", help="the simulated sensor, pressing --press in a loop")
    src.add_argument("--replay", metavar="FILE", help="a recording from `tactile-manip record`")
    p.add_argument("--press", action="append", default=[], metavar="SPEC",
                   help=f"with --sim: scripted press (repeatable; default {DEFAULT_SIM_PRESS!r})")
    zero = p.add_mutually_exclusive_group()
    zero.add_argument("--no-baseline", action="store_true", help="show raw fields (no baseline at start)")
    zero.add_argument("--baseline-from", metavar="FILE",
                      help="subtract the mean of the first --baseline-frames frames of this recording (of the free "
                           "pad) instead of a baseline taken at start: for a source that starts under load")
    p.add_argument("--baseline-frames", type=int, default=125, help="frames averaged for the baseline (125)")
    p.add_argument("--fps", type=float, default=20.0, help="display refresh rate (default 20)")
    p.add_argument("--snapshot", metavar="PNG", help="run headless and save the last frame to this PNG")
    p.add_argument("--seconds", type=float, default=None,
                   help="with --snapshot: how long to read first, s (default 2); with --rerun: stop after this long "
                        "(default: at Ctrl-C)")
    add_serial_options(p, src)
    p.add_argument("--force", action="store_true", help="with --snapshot or --save: overwrite an existing file")
    add_rerun_options(p, what="every frame (instead of a matplotlib window)")
    rr = p.add_argument_group("estimates in Rerun")
    rr.add_argument("--model", default="bilinear",
                    help="with --rerun: reconstructor for depth, angle and confidence: bilinear (default), bicubic, "
                         "an .onnx model, or none")
    rr.add_argument("--estimate-hz", type=float, default=10.0,
                    help="with --rerun: estimates (and depth images) per second (default 10; the field is logged at "
                         "the sensor rate)")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.checks import check_nonblank
    from tactile_manip.sensors import (
        ReplaySensor,
        ReplaySensorConfig,
        SerialSensor,
        SimulatedSensor,
        parse_press,
    )

    from tactile_manip.errors import CalibrationError
    from tactile_manip.extras import require
    from tactile_manip.outputs import check_output_file
    from tactile_manip.plots import figure_path

    if args.port:
        require("serial", "viewing a serial port")
    _check_view_options(args)
    check_sim_board(args)
    check_rerun_options(args)
    if args.rerun:
        plt = None
    elif args.snapshot is None:
        plt = _interactive_pyplot()  # fail before connecting when there is no display
    else:
        args.snapshot = check_output_file(figure_path(args.snapshot), force=args.force)
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    offset_ut = _baseline_from(args.baseline_from, args.baseline_frames) if args.baseline_from else None
    # dispatch on which flag was given, not on truthiness: an empty --port or --replay is an error, not --sim
    if args.sim:
        sensor = SimulatedSensor()
    elif args.replay is not None:
        sensor = ReplaySensor(ReplaySensorConfig(path=check_nonblank("--replay", args.replay), loop=True))
    else:  # --port or --serial-number: an empty one is refused by serial_config
        sensor = SerialSensor(serial_config(args))
    with sensor:
        rec = getattr(sensor, "recording", None)
        if rec is not None and rec.skipped_bytes:
            print(f"view: {rec.path}: skipped {rec.skipped_bytes} damaged bytes in {rec.damaged_records} place(s); "
                  f"replaying the {len(rec)} intact frames", file=sys.stderr)
        if offset_ut is not None:
            sensor.set_baseline(offset_ut)
        elif not args.no_baseline:
            try:
                sensor.calibrate_baseline(args.baseline_frames)
            except CalibrationError as e:
                raise CalibrationError(f"{e} (a source that starts under load: view it with --no-baseline, or "
                                       "--baseline-from FILE, a recording of the free pad)") from e
        if args.sim:
            presses = [parse_press(s) for s in args.press or [DEFAULT_SIM_PRESS]]
            sensor.play(presses, period_s=max(p.end_s for p in presses) + 0.5)
        if args.rerun:
            from tactile_manip.interop.rerun_view import stream_to_rerun

            return stream_to_rerun(sensor, save=args.save, spawn=args.spawn, serve=args.serve, bind=args.bind,
                                   port=args.rerun_port, model=args.model, estimate_hz=args.estimate_hz,
                                   seconds=args.seconds)
        view = FieldView(plt, sensor)
        if args.snapshot:
            return view.snapshot(args.snapshot, seconds=2.0 if args.seconds is None else args.seconds)
        return view.live(fps=args.fps)


def _check_view_options(args: argparse.Namespace) -> None:
    """--rerun not with --snapshot, positive durations and rates (checked before any device is opened)."""
    if args.rerun and args.snapshot:
        raise ValueError("--snapshot draws a matplotlib figure; it does not go with --rerun")
    if args.seconds is not None and not (args.seconds > 0 and math.isfinite(args.seconds)):
        raise ValueError(f"--seconds: expected a positive duration, got {args.seconds}")
    if not (args.estimate_hz > 0 and math.isfinite(args.estimate_hz)):
        raise ValueError(f"--estimate-hz: expected a positive rate, got {args.estimate_hz}")


def _baseline_from(path: str, frames: int):
    """(4, 4, 3) uT: the mean raw field of the first ``frames`` frames of the recording at ``path``."""
    from tactile_manip.sensors import read_recording

    rec = read_recording(path)
    if len(rec) < 2:
        raise ValueError(f"--baseline-from {path}: holds {len(rec)} frame(s); a baseline needs at least 2")
    return rec.field_raw_ut()[:max(2, frames)].mean(axis=0)


def _interactive_pyplot():
    import matplotlib.pyplot as plt

    if plt.get_backend().lower() in ("agg", "pdf", "svg", "ps", "cairo", "template"):
        raise ValueError(f"no display for a live view (matplotlib backend {plt.get_backend()!r}); "
                         "use --snapshot out.png --seconds N")
    return plt


class FieldView:
    """One figure updated in place from a sensor's newest reading (drawn first by ``plots.plot_field``)."""

    def __init__(self, plt, sensor) -> None:
        import numpy as np

        from tactile_manip.plots import plot_field

        self.plt, self.sensor = plt, sensor
        self.fig, self.ax = plt.subplots(figsize=(6.4, 5.6), constrained_layout=True)
        self.pitch_mm = sensor.layout.pitch_mm
        self.artists = plot_field(self.ax, np.zeros(sensor.layout.shape), pitch_mm=self.pitch_mm)
        self.z_range = self.xy_range = RANGE_FLOOR_UT
        self.frames = 0
        self.last = None

    def update(self) -> None:
        """Redraw from the newest reading, or say in the title why there is none."""
        import numpy as np

        from tactile_manip.errors import SensorTimeoutError
        from tactile_manip.plots import set_field_ranges

        try:
            r = self.sensor.read_latest(max_age_s=0.5)
        except SensorTimeoutError as e:
            self.ax.set_title(f"stale: {str(e)[:70]}...", fontsize=8, color="red")
            return
        self.last = r
        f = np.asarray(r.field_ut, dtype=np.float64)
        # ranges follow the field up at once and relax slowly, so the scale does not flicker
        self.z_range = max(RANGE_FLOOR_UT, float(np.abs(f[..., 2]).max()), 0.97 * self.z_range)
        self.xy_range = max(RANGE_FLOOR_UT, float(np.hypot(f[..., 0], f[..., 1]).max()), 0.97 * self.xy_range)
        self.artists.image.set_data(f[..., 2])
        self.artists.arrows.set_UVC(f[..., 0], f[..., 1])
        set_field_ranges(self.artists, z_range_ut=self.z_range, xy_range_ut=self.xy_range)  # colours, arrows, key
        h = self.sensor.health()
        kind = "field" if self.sensor.baseline is not None else "raw field"
        self.ax.set_title(f"{self.sensor.source}: {kind}, seq {r.seq}, {h.rate_hz:.0f} Hz, "
                          f"|Bz| <= {np.abs(f[..., 2]).max():.0f} uT, crc {h.crc_errors}, gaps {h.seq_gaps}",
                          fontsize=9, color="black")

    def snapshot(self, path: str, *, seconds: float) -> int:
        """Read for ``seconds`` (updating as live), then save the figure; returns the exit status."""
        from tactile_manip.errors import SensorTimeoutError
        from tactile_manip.plots import figure_path

        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                self.sensor.wait_new(timeout_s=0.5)
                self.frames += 1
            except SensorTimeoutError:
                pass
            if self.frames % 10 == 0:
                self.update()
        self.update()
        path = figure_path(path)  # the file savefig writes (.png added to a bare name), and the one printed
        path.parent.mkdir(parents=True, exist_ok=True)
        self.fig.savefig(path, dpi=90)
        seq = "none" if self.last is None else self.last.seq
        print(f"wrote {path} (last frame seq {seq}; {self.frames} readings taken in {seconds:g} s)")
        return 0 if self.last is not None else 1

    def live(self, *, fps: float) -> int:
        from matplotlib.animation import FuncAnimation

        interval_ms = max(1, int(math.ceil(1000.0 / fps)))
        self._animation = FuncAnimation(self.fig, lambda _: self.update(), interval=interval_ms,
                                        cache_frame_data=False)
        self.plt.show()
        return 0
