"""The sensor's exact symmetries, and a reconstructor that averages over them (test-time augmentation).

The chip grid, the magnetised skin and the pad are symmetric under the dihedral group of the square: quarter
turns about the pad normal and mirrors. A transformed reading is the reading of the transformed contact, so
a reconstructor ``f`` can be replaced by its group average ``mean_g g^-1 f(g x)``, which is exactly
equivariant and cancels the part of the model's error that is not (for the fast reference model on unseen rods the
orientation bias towards the grid axes mostly cancels; see docs/trials.md). It costs one batch of 8 readings
per reading (4 for a rectangular grid, whose group is the rectangle's: identity, half turn and two mirrors).

Conventions (docs/design.md, Conventions): readings (..., R, C, 3) with row 0 at +y and column 0 at -x, images
(..., H, W) in the same layout, so ``numpy.rot90`` on (row, column) is a counter-clockwise turn. The same
transforms as the training augmentation (:func:`tactile_manip.learning.cvae.data.dihedral`, a test checks it).
"""

from __future__ import annotations

import numpy as np

from tactile_manip.perception.reconstruct import Reconstructor

CHUNK = 64  # readings per inner batch (8 x 64 images at a time)


def transform_reading(field_ut: np.ndarray, quarter_turns: int, mirror: bool) -> np.ndarray:
    """Readings (..., R, C, 3) after ``mirror`` (x -> -x) and then ``quarter_turns`` counter-clockwise turns."""
    f = np.asarray(field_ut)
    if mirror:
        f = f[..., :, ::-1, :] * np.array([-1.0, 1.0, 1.0], dtype=f.dtype)
    for _ in range(quarter_turns % 4):
        f = np.rot90(f, 1, axes=(-3, -2))
        f = np.stack([-f[..., 1], f[..., 0], f[..., 2]], axis=-1)  # (Bx, By) -> (-By, Bx)
    return np.ascontiguousarray(f)


def transform_image(image: np.ndarray, quarter_turns: int, mirror: bool) -> np.ndarray:
    """Images (..., H, W) after the same symmetry as :func:`transform_reading`."""
    im = np.asarray(image)
    if mirror:
        im = im[..., ::-1]
    return np.ascontiguousarray(np.rot90(im, quarter_turns % 4, axes=(-2, -1)))


def inverse_transform_image(image: np.ndarray, quarter_turns: int, mirror: bool) -> np.ndarray:
    """Undo :func:`transform_image`."""
    im = np.rot90(np.asarray(image), -(quarter_turns % 4), axes=(-2, -1))
    if mirror:
        im = im[..., ::-1]
    return np.ascontiguousarray(im)


def symmetry_group(input_shape: tuple[int, ...], output_shape: tuple[int, int]) -> list[tuple[int, bool]]:
    """(quarter_turns, mirror) of every symmetry both the taxel grid and the image have."""
    square = input_shape[0] == input_shape[1] and output_shape[0] == output_shape[1]
    turns = (0, 1, 2, 3) if square else (0, 2)
    return [(k, m) for m in (False, True) for k in turns]


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
        self.group = symmetry_group(self.input_shape, self.output_shape)

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
