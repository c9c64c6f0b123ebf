"""Press your own object on the simulated sensor pair and look at both sensors.

Run: python examples/simulate_press.py  (writes examples_out/press.png)
"""

import numpy as np

from tactile_manip.plots import sample_figure
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.pair import SensorPair


def ring_heightmap(pixel_mm: float = 0.05) -> np.ndarray:
    """A 1 mm high ring of 8 mm diameter on a plate: protrusion in mm, NaN outside the part."""
    c = (np.arange(400) - 199.5) * pixel_mm
    x, y = np.meshgrid(c, -c)
    r = np.hypot(x, y)
    height = np.where(np.abs(r - 4.0) < 0.75, 1.0, 0.0)
    return np.where(r < 9.5, height, np.nan)


def main() -> None:
    pair = SensorPair()
    ring = Indenter.from_heightmap(ring_heightmap(), pixel_mm=0.05, name="ring")
    sample = pair.press(ring, IndenterPose(x_mm=1.0, y_mm=-0.5), 8.0, np.random.default_rng(0))
    print(f"contact {sample.contact}: approach {sample.approach_mm:.2f} mm into the gel, "
          f"peak |dB| {np.abs(sample.field_ut).max():.0f} uT, peak pressure {sample.pressure.peak_kpa:.0f} kPa")
    sample_figure(sample.field_ut, sample.depth_mm, title="ring, 8 N", path="examples_out/press.png")
    print("wrote examples_out/press.png")


if __name__ == "__main__":
    main()
