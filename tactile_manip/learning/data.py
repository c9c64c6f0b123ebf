"""Paired datasets as torch tensors: input scaling, variant selection and the sensor's symmetry group.

Readings in microtesla are clamped to +-clamp_ut and scaled to [-1, 1] (SuperMag Sec. IV-A: +-500). Readings
in any other unit are first normalised per channel by the training split's mean and standard deviation, then
clamped to +-clamp_std standard deviations and scaled to [-1, 1]. Images in mm are learnt as they are; images
in any other unit as ``(value - value_min) / data_range``, mapped back inside the exported graph. The z-axis-only
variant keeps the z channel; the Allen-key-only variant keeps the training samples of the named objects.

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

AXIS_SETS = ("xyz", "z")    # every channel, or the z channel of a magnetic reading (the paper's ablation)


@dataclass(frozen=True)
class InputSpec:
    """How a reading becomes the network's condition vector (stored in the exported model)."""

    clamp_ut: float = 500.0                # clamp of readings in uT
    axes: str = "xyz"                      # one of AXIS_SETS
    channels: int = 3                      # channels in a reading (A)
    offset: tuple[float, ...] = ()         # per-channel mean of the training split (readings not in uT)
    spread: tuple[float, ...] = ()         # per-channel standard deviation of the training split
    clamp_std: float = 5.0                 # clamp of normalised readings, standard deviations

    def __post_init__(self) -> None:
        object.__setattr__(self, "offset", tuple(float(v) for v in self.offset))
        object.__setattr__(self, "spread", tuple(float(v) for v in self.spread))
        if self.axes not in AXIS_SETS:
            raise ValueError(f"axes must be one of {list(AXIS_SETS)}, got {self.axes!r}")
        if self.axes == "z" and self.channels != 3:
            raise ValueError(f"axes 'z' needs 3-channel magnetic readings, got {self.channels} channels")
        for name in ("clamp_ut", "clamp_std"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if len(self.offset) != len(self.spread) or (self.offset and len(self.offset) != self.channels):
            raise ValueError(f"offset and spread need one value per channel ({self.channels}), got "
                             f"{len(self.offset)} and {len(self.spread)}")
        if not all(s > 0 for s in self.spread):
            raise ValueError(f"spread values must be > 0, got {self.spread}")

    @property
    def used(self) -> tuple[int, ...]:
        """Indices of the channels the network sees."""
        return (2,) if self.axes == "z" else tuple(range(self.channels))

    @property
    def clamp(self) -> float:
        """The clamp in the units the readings have after normalisation."""
        return self.clamp_std if self.offset else self.clamp_ut

    def scale(self, field: torch.Tensor) -> torch.Tensor:
        """(B, R, C, A) readings -> (B, R*C*len(used)) in [-1, 1]."""
        x = field[..., list(self.used)]
        if self.offset:
            idx = list(self.used)
            x = (x - x.new_tensor(self.offset)[idx]) / x.new_tensor(self.spread)[idx]
        return (x.clamp(-self.clamp, self.clamp) / self.clamp).flatten(1)

    @classmethod
    def for_data(cls, data: PairedDataset, train_index: np.ndarray, *, clamp_ut: float, axes: str,
                 clamp_std: float) -> InputSpec:
        """The spec for ``data``: readings in uT as they are, others normalised by the training split."""
        count = data.channels.count
        if data.channels.unit == "uT":
            return cls(clamp_ut=clamp_ut, axes=axes, channels=count, clamp_std=clamp_std)
        x = data.readings[train_index].reshape(-1, count).astype(np.float64)
        std = np.maximum(x.std(axis=0), 1e-12 * np.maximum(np.abs(x).max(axis=0), 1e-30))
        return cls(clamp_ut=clamp_ut, axes=axes, channels=count, offset=tuple(x.mean(axis=0)), spread=tuple(std),
                   clamp_std=clamp_std)


@dataclass(frozen=True)
class OutputSpec:
    """How the network's output maps to the image unit: ``value = offset + scale * output``."""

    offset: float = 0.0
    scale: float = 1.0

    @classmethod
    def for_data(cls, data: PairedDataset) -> OutputSpec:
        """Depth in mm is learnt as it is (the shipped recipe); any other unit as a fraction of its range."""
        if data.image.unit == "mm":
            return cls()
        return cls(offset=data.image.value_min, scale=data.image.data_range)


def select(data: PairedDataset, split: str, objects: tuple[str, ...] = (), *,
           drop_bottomed_out: bool = False) -> np.ndarray:
    """Indices of ``split``, restricted to ``objects`` (by name) when given.

    ``drop_bottomed_out`` leaves out presses the producer flagged as through the elastic layer (the extra
    ``bottomed_out``; data without it loses nothing): their images come from outside the layer model.
    """
    idx = data.indices(split, objects)
    if drop_bottomed_out and data.has("bottomed_out") and idx.size:
        kept = idx[~data.extra("bottomed_out")[idx].astype(bool)]
        if kept.size == 0:
            raise ValueError(f"all {idx.size} presses of split {split!r} are flagged bottomed_out "
                             "(drop_bottomed_out = true leaves none)")
        idx = kept
    if idx.size == 0:
        raise ValueError(f"no samples in split {split!r}" + (f" for objects {list(objects)}" if objects else ""))
    return idx


class TensorPairs(torch.utils.data.Dataset):
    """Readings (n, R, C, A) float32 and images (n, H, W) as stored (uint8 depth stays uint8 in memory).

    :meth:`images` gives the training targets: image values mapped by ``output`` (identity for depth in mm).
    ``data_range`` is the images' data range in those target units (PSNR's L), ``vector`` whether the
    channels turn with the pad (a magnetic field) under the symmetry augmentation.
    """

    def __init__(self, data: PairedDataset, index: np.ndarray, output: OutputSpec | None = None) -> None:
        output = output or OutputSpec.for_data(data)
        self.field = torch.from_numpy(np.ascontiguousarray(data.readings[index], dtype=np.float32))
        images = data.require_images("image training pairs")
        self.stored = torch.from_numpy(np.ascontiguousarray(images[index]))
        # stored -> target: (stored * image.scale + image.offset - output.offset) / output.scale
        self.scale = data.image.scale / output.scale
        self.offset = (data.image.offset - output.offset) / output.scale
        self.data_range = data.image.data_range / output.scale
        self.vector = data.channels.kind == "magnetic_vector"

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


def dihedral(field: torch.Tensor, image: torch.Tensor, k: int, mirror: bool, *, vector: bool = True
             ) -> tuple[torch.Tensor, torch.Tensor]:
    """Apply a symmetry of the square: ``mirror`` (x -> -x) first, then ``k`` quarter turns counter-clockwise.

    Args:
        field: (..., R, C, A) readings, row 0 at +y, column 0 at -x.
        image: (..., H, W) images in the same layout.
        vector: the channels are a magnetic field (x, y, z) that turns with the pad (A = 3); False: scalar
            channels that move with their taxel and keep their values.
    """
    f = field
    if mirror:
        f = torch.flip(f, dims=(-2,))
        if vector:
            f = f * f.new_tensor([-1.0, 1.0, 1.0])
        image = torch.flip(image, dims=(-1,))
    for _ in range(k % 4):
        f = torch.rot90(f, 1, dims=(-3, -2))
        if vector:
            f = torch.stack([-f[..., 1], f[..., 0], f[..., 2]], dim=-1)  # (Bx, By) -> (-By, Bx)
        image = torch.rot90(image, 1, dims=(-2, -1))
    return f, image


def augment_batch(field: torch.Tensor, image: torch.Tensor, generator: torch.Generator, *, vector: bool = True
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """One random symmetry per batch (applied batch-wise for speed).

    Square taxel grids and images use the whole dihedral group of the square (8 elements); rectangular
    ones only the symmetries of the rectangle (identity, half turn and the two mirrors). ``vector``: see
    :func:`dihedral`.
    """
    g = int(torch.randint(0, 8, (1,), generator=generator))
    square = field.shape[-3] == field.shape[-2] and image.shape[-2] == image.shape[-1]
    quarter_turns = g % 4 if square else 2 * (g % 2)
    return dihedral(field, image, quarter_turns, g >= 4, vector=vector)
