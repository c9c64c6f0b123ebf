"""Episodes from the simulated sensor, written as a Rerun file and an MCAP bag with the Python API.

A hex bar is pressed into the simulated pad at 30 degrees and released, twice; every frame (125 Hz) becomes a
:class:`~tactile_manip.interop.frames.Frame` with its sensor-clock time, and the shipped model estimates the
angle (with its depth image) at about 10 Hz. The frames are one episode, written by ``write_rrd`` and
``write_mcap`` (what ``tactile-manip export --format rrd|mcap`` calls). Needs the extras ``onnx``, ``viz``
and ``mcap``.

Run: python examples/interop_demo.py --out-dir out/interop [--seconds 4] [--ros2]
Then: rerun out/interop/press.rrd, or open out/interop/press.mcap in Foxglove or Rerun.
"""

import argparse
import math
from pathlib import Path

from tactile_manip.interop.frames import Episode, Frame
from tactile_manip.interop.mcap_export import write_mcap
from tactile_manip.interop.rerun_export import write_rrd
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
from tactile_manip.sensors import parse_press
from tactile_manip.sensors.simulated import SimulatedSensor

ESTIMATE_EVERY = 12  # frames: 125 / 12 = 10.4 estimates per second


def record_episode(seconds: float, model: str) -> Episode:
    estimator = TactilePoseEstimator(load_reconstructor(model))
    presses = [parse_press("hex_bar,t=0.3,force=10,yaw=30,rise=0.3,hold=1.0,size=4")]
    frames = []
    with SimulatedSensor() as sensor:
        sensor.calibrate_baseline()
        sensor.play(presses, period_s=2.0)
        t0 = None
        with sensor.subscribe() as sub:
            while len(frames) < round(seconds * sensor.config.rate_hz):
                reading = sub.get(timeout_s=1.0).reading
                t0 = reading.t_device_s if t0 is None else t0
                frame = Frame(t_s=reading.t_device_s - t0, host_time_s=reading.t_host_s, field_ut=reading.field_ut)
                if len(frames) % ESTIMATE_EVERY == 0:
                    est, rec = estimator.estimate_with_image(reading)
                    frame.angle_rad = est.angle_rad if est.defined else math.nan
                    frame.confidence = est.confidence
                    frame.depth_mm = rec.depth_mm
                frames.append(frame)
        rate = sensor.config.rate_hz
    return Episode(index=0, task="press a 4 mm hex bar at 30 deg (simulated)", fps=rate, frames=frames,
                   meta={"layout": "supermag-4x4", "model": model})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out-dir", default="out/interop")
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--model", default="models/supermag.onnx")
    p.add_argument("--ros2", action="store_true", help="write the MCAP file with the rosbag2 profile")
    args = p.parse_args()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    episode = record_episode(args.seconds, args.model)
    print("rrd: ", write_rrd([episode], out / "press.rrd"))
    print("mcap:", write_mcap([episode], out / "press.mcap", ros2=args.ros2))


if __name__ == "__main__":
    main()
