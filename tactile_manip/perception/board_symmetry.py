"""The board's exact symmetries as maps of readings and images: quarter turns about the pad normal and mirrors.

The chip grid, the magnetised skin and the pad are symmetric under the dihedral group of the square (of the
rectangle for a rectangular grid: identity, half turn and two mirrors). A transformed reading is the reading of
the transformed contact, which is what test-time averaging over the symmetries rests on
(:class:`~tactile_manip.perception.symmetry.SymmetrizedReconstructor`, and an exported model's own
``image_symmetry``, :class:`~tactile_manip.perception.reconstruct.OnnxReconstructor`).

Conventions (docs/design.md, Conventions): readings (..., R, C, 3) with row 0 at +y and column 0 at -x, images
(..., H, W) in the same layout, so ``numpy.rot90`` on (row, column) is a counter-clockwise turn. The same
transforms as the training augmentation (:func:`tactile_manip.learning.cvae.data.dihedral`, a test checks it).
"""

from __future__ import annotations

import numpy as np

#: what an exported image model averages its images over: nothing, the board's turns, or every symmetry
IMAGE_SYMMETRIES = ("none", "rotations", "all")


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


def image_subgroup(input_shape: tuple[int, ...], output_shape: tuple[int, int], which: str) -> list[tuple[int, bool]]:
    """The symmetries of :data:`IMAGE_SYMMETRIES` entry ``which`` that the board and the image share:
    ``"none"`` the identity alone, ``"rotations"`` the turns, ``"all"`` the whole :func:`symmetry_group`."""
    if which not in IMAGE_SYMMETRIES:
        raise ValueError(f"image_symmetry must be one of {', '.join(IMAGE_SYMMETRIES)}, got {which!r}")
    group = symmetry_group(input_shape, output_shape)
    if which == "none":
        return [(0, False)]
    return group if which == "all" else [g for g in group if not g[1]]


def average_images(run, fields_ut: np.ndarray, group: list[tuple[int, bool]]
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """``mean_g g^-1 run(g reading)`` over ``group`` in one batched ``run`` ((M, R, C, 3) -> (M, H, W) depth
    and spread or None); the spread, where there is one, is averaged the same way. The batch holds each
    reading's copies together, in reading order, so that a model drawing prior noise per batch row gives a
    reading the same draws in a batch as alone."""
    n, g = len(fields_ut), len(group)
    copies = np.stack([transform_reading(fields_ut, k, m) for k, m in group], axis=1)  # (n, g, R, C, 3)
    depth, spread = run(copies.reshape(n * g, *copies.shape[2:]))

    def back(images: np.ndarray) -> np.ndarray:
        images = images.reshape(n, g, *images.shape[1:])
        return np.mean([inverse_transform_image(images[:, i], k, m) for i, (k, m) in enumerate(group)],
                       axis=0).astype(np.float32)

    return back(depth), None if spread is None else back(spread)
