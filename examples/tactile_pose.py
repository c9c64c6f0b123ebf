"""The estimator in your own task: stream in-hand angles, contact positions and forces from a sensor at its rate.

Here the sensor is the simulated one with a 4 mm hex bar pressed at 30 degrees; swap in
``SerialSensor(SerialSensorConfig(port="/dev/ttyUSB0"))`` for the real board, nothing else changes.

An estimate whose ``defined`` is False (no contact on the pad, or a contact too small or too round to have an
axis) carries angle 0.0 and confidence 0.0 and says why in ``reason``: never act on its angle.

The contact model's quantities carry a sigma each; ``contact`` is None for an estimator loaded without one
(``TactileEstimator.load(contact_model=None)``).

Run: python examples/tactile_pose.py (from any folder: the shipped models are found from the package)
"""

import math

from tactile_manip import TactileEstimate, TactileEstimator
from tactile_manip.sensors.simulated import SimulatedSensor
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.shapes import make_indenter


def describe(est: TactileEstimate) -> str:
    """One line for an estimate; an undefined angle is flagged as such, with its reason, and shows no angle."""
    angle, contact = est.angle, est.contact
    if not angle.defined:
        return f"angle UNDEFINED ({angle.reason}): no angle to act on"
    line = (f"angle {math.degrees(angle.angle_rad):+6.2f} deg  confidence {angle.confidence:.2f}  "
            f"from the {angle.source}")  # "image", or "head": the model's angle head, where it was the more likely
    if est.position_mm is not None:
        line += f"  at ({est.position_mm[0]:+.2f}, {est.position_mm[1]:+.2f}) mm"
    if contact is not None and contact.plausible and contact.force_n is not None:
        line += f"  force {contact.force_n:.1f} +- {contact.force_sigma_n:.1f} N"
    return line


def main() -> None:
    estimator = TactileEstimator.load()  # models/supermag.onnx and models/contact_supermag.onnx
    bar = make_indenter("hex_bar", size_mm=4.0)
    with SimulatedSensor() as sensor:
        sensor.calibrate_baseline()                       # nothing on the pad: 1 s of frames
        sensor.set_contact(bar, IndenterPose(x_mm=1.0, y_mm=-0.5, yaw_rad=math.radians(30.0)), force_n=10.0)

        # one estimate per new frame (125 Hz), as a control loop would consume them; a frame taken before the
        # contact reached the pad gives an undefined estimate
        for est in estimator.stream(sensor, max_estimates=5):
            print(f"{describe(est)}  latency {est.angle.timings_s['total'] * 1e3:.1f} ms")

        # a steadier estimate for a decision: the mean of the next 8 frames (64 ms)
        est = estimator.read(sensor, frames=8)
        print(f"8-frame estimate: {describe(est)} (true +30.00 deg)")

        sensor.clear_contact()
        est = estimator.read(sensor)
        print(f"empty pad: {describe(est)}")


if __name__ == "__main__":
    main()
