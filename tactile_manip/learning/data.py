"""Paired datasets as torch tensors: input scaling, variant selection and the sensor's symmetry group.

Readings are clamped to +-clamp_ut and scaled to [-1, 1] (SuperMag Sec. IV-A: +-500). The z-axis-only
variant keeps axis 2; the Allen-key-only variant keeps the training samples of the named objects.

Augmentation uses the exact symmetries of the sensor: the 4x4 chip grid, the square pad and the
z-polarised skin are invariant under the dihedral group of the square, so rotating the whole scene by 90
degrees rotates the (x, y) field components and the image, and mirroring x -> -x flips Bx and the image
columns (B is a pseudovector, but so is the magnetisation, so the signs work out as for a polar vector;
the simulator test proves it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tactile_manip.data import PairedDataset

AXIS_SETS = {"xyz": (0, 1, 2), "z": (2,)}


@dataclass(frozen=True)
class InputSpec:
    """How a reading becomes the network's condition vector (stored in the exported model)."""

    clamp_ut: float = 500.0
    axes: str = "xyz"

    def __post_init__(self) -> None:
        if self.axes not in AXIS_SETS:
            raise ValueError(f"axes must be one of {list(AXIS_SETS)}, got {self.axes!r}")
        if not self.clamp_ut > 0:
            raise ValueError(f"clamp_ut must be > 0, got {self.clamp_ut}")

    def scale(self, field_ut: torch.Tensor) -> torch.Tensor:
        """(B, R, C, 3) microtesla -> (B, R*C*A) in [-1, 1]."""
        x = field_ut[..., list(AXIS_SETS[self.axes])]
        return (x.clamp(-self.clamp_ut, self.clamp_ut) / self.clamp_ut).flatten(1)


def select(data: PairedDataset, split: str, objects: tuple[str, ...] = ()) -> np.ndarray:
    """Indices of ``split``, restricted to ``objects`` (by name) when given."""
    idx = data.indices(split, objects)
    if idx.size == 0:
        raise ValueError(f"no samples in split {split!r}" + (f" for objects {list(objects)}" if objects else ""))
    return idx


class TensorPairs(torch.utils.data.Dataset):
    """Readings (n, R, C, A) float32 and images (n, H, W) as stored (uint8 depth stays uint8 in memory)."""

    def __init__(self, data: PairedDataset, index: np.ndarray) -> None:
        self.field = torch.from_numpy(np.ascontiguousarray(data.readings[index], dtype=np.float32))
        self.stored = torch.from_numpy(np.ascontiguousarray(data.images[index]))
        self.scale, self.offset = data.image.scale, data.image.offset

    def to(self, device: torch.device | str) -> TensorPairs:
        """Move the split to ``device`` (once, before training: batches are then sliced there)."""
        self.field = self.field.to(device)
        self.stored = self.stored.to(device)
        return self

    def images(self, index: torch.Tensor | slice | int) -> torch.Tensor:
        """Images at ``index`` in the image unit, float32."""
        out = self.stored[index].float() * self.scale
        return out + self.offset if self.offset else out

    def __len__(self) -> int:
        return self.field.shape[0]

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.field[i], self.images(i)


def dihedral(field_ut: torch.Tensor, image: torch.Tensor, k: int, mirror: bool
             ) -> tuple[torch.Tensor, torch.Tensor]:
    """Apply a symmetry of the square: ``mirror`` (x -> -x) first, then ``k`` quarter turns counter-clockwise.

    Args:
        field_ut: (..., R, C, 3) readings, row 0 at +y, column 0 at -x.
        image: (..., H, W) depth images in the same layout.
    """
    f = field_ut
    if mirror:
        f = torch.flip(f, dims=(-2,)) * f.new_tensor([-1.0, 1.0, 1.0])
        image = torch.flip(image, dims=(-1,))
    for _ in range(k % 4):
        f = torch.rot90(f, 1, dims=(-3, -2))
        f = torch.stack([-f[..., 1], f[..., 0], f[..., 2]], dim=-1)  # (Bx, By) -> (-By, Bx)
        image = torch.rot90(image, 1, dims=(-2, -1))
    return f, image


def augment_batch(field_ut: torch.Tensor, image: torch.Tensor, generator: torch.Generator
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """One random symmetry per batch (applied batch-wise for speed).

    Square taxel grids and images use the whole dihedral group of the square (8 elements); rectangular
    ones only the symmetries of the rectangle (identity, half turn and the two mirrors).
    """
    g = int(torch.randint(0, 8, (1,), generator=generator))
    square = field_ut.shape[-3] == field_ut.shape[-2] and image.shape[-2] == image.shape[-1]
    quarter_turns = g % 4 if square else 2 * (g % 2)
    return dihedral(field_ut, image, quarter_turns, g >= 4)
