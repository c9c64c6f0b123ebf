"""The sensor's exact symmetries, and a reconstructor that averages over them (test-time augmentation).

The chip grid, the magnetised skin and the pad are symmetric under the dihedral group of the square: quarter
turns about the pad normal and mirrors. A transformed reading is the reading of the transformed contact, so
a reconstructor ``f`` can be replaced by its group average ``mean_g g^-1 f(g x)``, which is exactly
equivariant and cancels the part of the model's error that is not (for the fast reference model on unseen rods the
orientation bias towards the grid axes mostly cancels; see docs/trials.md). It costs one batch of 8 readings
per reading (4 for a rectangular grid, whose group is the rectangle's: identity, half turn and two mirrors).
A model that already averages its images over part of the group (its ``image_symmetry``: the turns) is
averaged over the rest only, one copy per coset (a reading and its mirror): the same average, no pass twice.

Conventions (docs/design.md, Conventions): readings (..., R, C, 3) with row 0 at +y and column 0 at -x, images
(..., H, W) in the same layout, so ``numpy.rot90`` on (row, column) is a counter-clockwise turn. The same
transforms as the training augmentation (:func:`tactile_manip.learning.cvae.data.dihedral`, a test checks it).
"""

from __future__ import annotations

import numpy as np

from tactile_manip.perception.board_symmetry import (inverse_transform_image, symmetry_group, transform_image,
                                                     transform_reading)
from tactile_manip.perception.reconstruct import Reconstructor

__all__ = ["CHUNK", "SymmetrizedReconstructor", "inverse_transform_image", "symmetry_group", "transform_image",
           "transform_reading"]

CHUNK = 64  # readings per inner batch (8 x 64 images at a time)


class SymmetrizedReconstructor(Reconstructor):
    """``inner`` averaged over the sensor's symmetries: depth = mean over g of g^-1 inner(g reading).

    ``spread_mm`` is the per-pixel standard deviation over the symmetric copies (how far the model is from
    equivariant on this reading), or None with ``spread=False`` (the default: the estimator's confidence then
    stays the PCA's).
    """

    def __init__(self, inner: Reconstructor, *, spread: bool = False) -> None:
        if not isinstance(inner, Reconstructor):
            raise TypeError(f"inner must be a Reconstructor, got {type(inner).__name__}")
        self.inner, self.spread = inner, bool(spread)
        self.name = f"{inner.name}+sym"
        self.input_shape, self.output_shape, self.pixel_mm = inner.input_shape, inner.output_shape, inner.pixel_mm
        self.board_layout, self.magnetic_ut = inner.board_layout, inner.magnetic_ut
        self.angle_head = inner.angle_head
        self.deterministic = inner.deterministic
        self.group = _cosets(symmetry_group(self.input_shape, self.output_shape),
                             getattr(inner, "image_symmetry", "none"))

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        if len(fields_ut) > CHUNK:  # bound the memory of the 8x batch
            parts = [self._run(fields_ut[i:i + CHUNK]) for i in range(0, len(fields_ut), CHUNK)]
            spread = np.concatenate([p[1] for p in parts]) if self.spread else None
            return np.concatenate([p[0] for p in parts]), spread
        n, g = len(fields_ut), len(self.group)
        batch = np.concatenate([transform_reading(fields_ut, k, m) for k, m in self.group])  # (g*n, R, C, 3)
        images = self.inner.reconstruct_batch(batch).reshape(g, n, *self.output_shape)
        back = np.stack([inverse_transform_image(images[i], k, m) for i, (k, m) in enumerate(self.group)])
        spread = back.std(axis=0).astype(np.float32) if self.spread else None
        return back.mean(axis=0).astype(np.float32), spread


def _cosets(group: list[tuple[int, bool]], inner_symmetry: str) -> list[tuple[int, bool]]:
    """One symmetry of each coset of the subgroup the inner model already averages over (its
    ``image_symmetry``): an image that is exactly equivariant under the turns needs only itself and its mirror
    to be averaged over the whole group; one averaged over every symmetry needs itself alone."""
    if inner_symmetry == "all":
        return [(0, False)]
    if inner_symmetry == "rotations":
        return [(0, False), (0, True)]
    return group
