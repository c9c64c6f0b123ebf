"""The tactile pose API in your own task: stream in-hand angles from a sensor at its rate.

Here the sensor is the simulated one with a 4 mm hex bar pressed at 30 degrees; swap in
``SerialSensor(SerialSensorConfig(port="/dev/ttyUSB0"))`` for the real board, nothing else changes.

An estimate whose ``defined`` is False (no contact on the pad, or a contact too small or too round to have an
axis) carries angle 0.0 and confidence 0.0 and says why in ``reason``: never act on its angle.

Run: python examples/tactile_pose.py
"""

import math
from pathlib import Path

from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
from tactile_manip.sensors.simulated import SimulatedSensor
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.shapes import make_indenter
from tactile_manip.types import AngleEstimate

MODEL = Path(__file__).resolve().parents[1] / "models" / "supermag.onnx"  # the default model, from any working folder


def describe(est: AngleEstimate) -> str:
    """One line for an estimate; an undefined one is flagged as such, with its reason, and shows no angle."""
    if not est.defined:
        return f"angle UNDEFINED ({est.reason}): no angle to act on"
    return (f"angle {math.degrees(est.angle_rad):+6.2f} deg  confidence {est.confidence:.2f}  "
            f"centroid ({est.centroid_mm[0]:+.2f}, {est.centroid_mm[1]:+.2f}) mm  area {est.area_mm2:5.1f} mm^2  "
            f"from the {est.source}")  # "image", or "head": the model's angle head, where it was the more likely


def main() -> None:
    estimator = TactilePoseEstimator(load_reconstructor(MODEL))
    bar = make_indenter("hex_bar", size_mm=4.0)
    with SimulatedSensor() as sensor:
        sensor.calibrate_baseline()                       # nothing on the pad: 1 s of frames
        sensor.set_contact(bar, IndenterPose(x_mm=1.0, y_mm=-0.5, yaw_rad=math.radians(30.0)), force_n=10.0)

        # one estimate per new frame (125 Hz), as a control loop would consume them; a frame taken before the
        # contact reached the pad gives an undefined estimate
        for est in estimator.stream(sensor, max_estimates=5):
            print(f"{describe(est)}  latency {est.timings_s['total'] * 1e3:.1f} ms")

        # a steadier estimate for a decision: the mean of the next 8 frames (64 ms)
        est = estimator.read(sensor, frames=8)
        print(f"8-frame estimate: {describe(est)} (true +30.00 deg)")

        sensor.clear_contact()
        est = estimator.read(sensor)
        print(f"empty pad: {describe(est)}")


if __name__ == "__main__":
    main()
