"""The SuperMag board's bank of press directions (tactile_manip/data/press_directions_supermag-4x4.npy), which
:mod:`tactile_manip.perception.press_check` compares a reading with to tell a press from noise or a uniform field.

    python -m benchmarks.press_bank                      # 3 x 2500 presses, about 10 CPU-minutes; writes the bank
    python -m benchmarks.press_bank --presses 300 --out /tmp/bank.npy

Presses of training families only, never the six test rods that ``benchmarks/no_contact.py`` measures on: two
batches of the contact model's families (the Allen key, the letter R, 90 procedural shapes of seeds 30000-30059
and 31000-31029 (wide), 30 sharp ones of seeds 40000-40029, knife-edge ridges of 60/90/120 deg and a 12 x 3 mm
flat bar) and one of the angle head's (150 procedural bars of seeds 20000-20149, 50 procedural prisms of seeds
24000-24049). Each press on its own drawn sensor (the simulator's full randomisation ranges), up to 6 mm off
centre, any yaw, tilted up to 5 deg, at a force log-uniform from 0.5 to 15 N; the noise-free field change
(``field_clean_ut``) of each press that touches the pad and stays within the layer is kept, scaled to unit
length (float16: the comparison is a cosine). The check compares each of a reading's 8 symmetric images with
the bank. Also prints, for the last tenth of each batch, held out of the bank, the likeness quantiles that
:data:`~tactile_manip.perception.press_check.MIN_LIKENESS` was chosen on, beside those of white-noise
directions.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from tactile_manip.boards import load_board
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.params import for_board, randomise
from tactile_manip.sim.shapes import make_indenter

SHAPES = ([("allen_key", {}), ("letter_r", {})]
          + [("procedural", {"seed": 30000 + i}) for i in range(60)]
          + [("procedural", {"seed": 31000 + i, "size_mm": 26.0}) for i in range(30)]
          + [("procedural_sharp", {"seed": 40000 + i}) for i in range(30)]
          + [("ridge", {"angle_deg": a}) for a in (60, 90, 120)]
          + [("flat_bar", {"width_mm": 12.0, "thickness_mm": 3.0})])
#: the angle head's training families: procedural bars and prisms (configs/dataset/bars*.toml, prisms.toml)
BARS = ([("procedural_bar", {"seed": 20000 + i}) for i in range(150)]
        + [("procedural_prism", {"seed": 24000 + i}) for i in range(50)])
SEEDS = {11: SHAPES, 12: SHAPES, 13: BARS}  # the seed of each batch of presses, and its shapes


def press_fields(seed: int, presses: int, shapes: list) -> np.ndarray:
    """(n, 48) float32 noise-free field changes (uT) of up to ``presses`` presses of ``shapes`` drawn from
    ``seed``."""
    rng = np.random.default_rng(seed)
    indenters = [make_indenter(name, **kwargs) for name, kwargs in shapes]
    fields = []
    for i in range(presses):
        pair = SensorPair(randomise(for_board(load_board("supermag-4x4")), rng), seed=seed * 100000 + i)
        pose = IndenterPose(x_mm=rng.uniform(-6, 6), y_mm=rng.uniform(-6, 6), yaw_rad=rng.uniform(-math.pi, math.pi),
                            tilt_x_rad=math.radians(rng.uniform(-5, 5)), tilt_y_rad=math.radians(rng.uniform(-5, 5)))
        indenter = indenters[rng.integers(len(indenters))]
        force = float(np.exp(rng.uniform(np.log(0.5), np.log(15.0))))
        sample = pair.press(indenter, pose, force, rng, render_depth=False)
        if sample.bottomed_out or not sample.contact:
            continue
        fields.append(sample.field_clean_ut.ravel())
    return np.array(fields, np.float32)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presses", type=int, default=2500, help="presses drawn per seed")
    parser.add_argument("--out", default="tactile_manip/data/press_directions_supermag-4x4.npy")
    args = parser.parse_args()
    batches = [press_fields(seed, args.presses, shapes) for seed, shapes in SEEDS.items()]
    units = [f / np.linalg.norm(f, axis=1, keepdims=True) for f in batches]
    held = [len(u) // 10 for u in units]   # the last tenth of each batch is held out of the bank
    bank = np.concatenate([u[:-h] for u, h in zip(units, held)])
    test = np.concatenate([u[-h:] for u, h in zip(units, held)])
    np.save(args.out, bank.reshape(-1, 4, 4, 3).astype(np.float16))
    print(f"wrote {args.out}: {len(bank)} press directions ({len(test)} held out)")

    from tactile_manip.perception.press_check import PressCheck, bank_of

    directions, symmetries = bank_of(bank.reshape(-1, 4, 4, 3))
    check = PressCheck(np.ones(3), directions=directions, symmetries=symmetries)
    noise = np.random.default_rng(0).standard_normal((2000, 4, 4, 3))
    held_like = [check.likeness(t.reshape(4, 4, 3)) for t in test]
    noise_like = [check.likeness(n) for n in noise]
    print("held-out presses, likeness quantiles 0.1/1/5 %:", np.percentile(held_like, [0.1, 1, 5]).round(3))
    print("white noise, likeness quantiles 99/99.9/100 %:", np.percentile(noise_like, [99, 99.9, 100]).round(3))


if __name__ == "__main__":
    main()
