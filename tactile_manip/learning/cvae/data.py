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

import ctypes
import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tactile_manip.data import (SPLITS, PairedDataset, ShardedDataset, concatenate, is_shard_folder, load_dataset,
                                load_datasets)
from tactile_manip.errors import DatasetError

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

    @classmethod
    def for_stream(cls, pairs: StreamedPairs, *, clamp_ut: float, axes: str, clamp_std: float) -> InputSpec:
        """:meth:`for_data` for a streamed training split (moments over its parts, one part at a time)."""
        count = pairs.data.channels.count
        if pairs.data.channels.unit == "uT":
            return cls(clamp_ut=clamp_ut, axes=axes, channels=count, clamp_std=clamp_std)
        mean, std, absmax = pairs.reading_moments()
        std = np.maximum(std, 1e-12 * np.maximum(absmax, 1e-30))
        return cls(clamp_ut=clamp_ut, axes=axes, channels=count, offset=tuple(mean), spread=tuple(std),
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

    def images_from(self, stored: torch.Tensor) -> torch.Tensor:
        """Stored images -> float32 images in the target unit."""
        out = stored.float() * self.scale
        return out + self.offset if self.offset else out

    def batch_count(self, batch_size: int) -> int:
        """Full batches per epoch (the last partial one is dropped)."""
        return len(range(0, len(self) - batch_size + 1, batch_size))

    def batches(self, batch_size: int, gen: torch.Generator, *, rank: int = 0, world: int = 1
                ) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """One epoch in a random order: this process's share of each global batch, (readings, images)."""
        order = torch.randperm(len(self), generator=gen)
        per_rank = batch_size // world
        for b in range(0, len(order) - batch_size + 1, batch_size):
            batch = order[b:b + batch_size][rank * per_rank:(rank + 1) * per_rank]
            yield self.field[batch], self.images(batch)

    def chunks(self, size: int) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """Every sample once, in order, in chunks of at most ``size``: (readings, images)."""
        for b in range(0, len(self), size):
            yield self.field[b:b + size], self.images(slice(b, b + size))

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


def open_training_data(paths: list[Path]) -> PairedDataset | StreamedData:
    """The datasets ``paths`` for training: all in memory when every one is a file (as
    :func:`~tactile_manip.data.load_datasets` joins them), a :class:`StreamedData` view when any is a shard
    folder (shards are then loaded a few at a time, each epoch)."""
    if not any(is_shard_folder(p) for p in paths):
        return load_datasets(paths)
    resolved = [Path(p).resolve() for p in paths]
    twice = sorted({str(p) for p in paths if resolved.count(Path(p).resolve()) > 1})
    if twice:
        raise DatasetError(f"the same dataset is given more than once: {', '.join(twice)}")
    return StreamedData([ShardedDataset(p) if is_shard_folder(p) else load_dataset(p) for p in paths])


def _trim_heap() -> None:
    """Return the heap's free pages to the system (glibc's ``malloc_trim``; a no-op elsewhere).

    Streaming loads shard after shard of large arrays. glibc raises its mmap threshold each time such a block is
    freed, so later ones come from the heap, whose free space it keeps: resident memory grew with the number of
    shards read (by about 450 MB over one pass of 143 shards of 512 presses). Trimming once per shard keeps it
    flat; the training steps' own allocations are left alone (mapping them on their own cost 40 % of the steps).
    """
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


class StreamedData:
    """Several datasets, shard folders among them, seen as one without loading them: what training needs to know
    of the whole (specs, shapes, counts, fingerprint) from manifests and a one-sample head of each dataset.

    A dataset given as a file is held in memory as one part; a shard folder is one part per shard.
    """

    def __init__(self, sources: list[ShardedDataset | PairedDataset]) -> None:
        self.sources = sources
        heads = [s.load_shard(0) if isinstance(s, ShardedDataset) else s for s in sources]
        # concatenate checks that channels, grids and image specs agree, and merges object names
        self.head = concatenate([h.subset(np.arange(1)) for h in heads])
        self.parts: list[tuple[int, int]] = [(k, i) for k, s in enumerate(sources)
                                             for i in range(s.shard_count if isinstance(s, ShardedDataset) else 1)]
        self.channels, self.image = self.head.channels, self.head.image
        self.grid = self.head.grid
        first = sources[0]
        self.provenance = first.provenance if len(sources) == 1 else {
            "source": "concatenate", "dropped_extras": self.head.provenance["dropped_extras"],
            "parts": [dict(s.provenance, fingerprint=s.fingerprint(), samples=len(s)) for s in sources]}

    def __len__(self) -> int:
        return sum(len(s) for s in self.sources)

    @property
    def image_shape(self) -> tuple[int, int]:
        return self.head.image_shape

    @property
    def object_names(self) -> list[str]:
        return [] if self.head.object_names is None else self.head.object_names.tolist()

    def has(self, name: str) -> bool:
        return self.head.has(name)

    def require_images(self, what: str) -> np.ndarray:
        return self.head.require_images(what)

    def load_part(self, j: int) -> PairedDataset:
        """Part ``j``: a shard (loaded and checked now) or a whole dataset given as a file."""
        k, i = self.parts[j]
        source = self.sources[k]
        return source.load_shard(i) if isinstance(source, ShardedDataset) else source

    def part_splits(self, j: int) -> dict[str, int]:
        k, i = self.parts[j]
        source = self.sources[k]
        if isinstance(source, ShardedDataset):
            return source.shard_splits(i)
        return {s: int(np.count_nonzero(source.split == s)) for s in SPLITS}

    def fingerprint(self) -> str:
        """One dataset's own fingerprint (a shard folder's equals its one-file form's); for several, the SHA-256
        (first 16 hex) of their fingerprints joined by commas, in order."""
        if len(self.sources) == 1:
            return self.sources[0].fingerprint()
        return hashlib.sha256(",".join(s.fingerprint() for s in self.sources).encode()).hexdigest()[:16]

    def describe(self) -> dict[str, Any]:
        """As :meth:`~tactile_manip.data.PairedDataset.describe`, from the manifests."""
        splits = {s: sum(self.part_splits(j)[s] for j in range(len(self.parts))) for s in SPLITS}
        return dict(self.head.describe(), samples=len(self), splits=splits, fingerprint=self.fingerprint(),
                    source=self.provenance.get("source", "unknown"), shards=len(self.parts))


class StreamedPairs:
    """One split of :class:`StreamedData` for training: readings and images drawn from a few parts at a time.

    Each epoch visits the parts in a random order and shuffles within a buffer of ``buffer_parts`` parts, so at
    most ``buffer_parts`` times the largest part's selected samples are held (plus, with ``buffer_parts = 1``,
    fewer than one batch carried over; ``peak_samples`` records it, ``loads`` counts the parts loaded). The
    selection (split, objects, bottomed-out presses) is made per part as it is loaded. The same interface as
    :class:`TensorPairs` (``batches``, ``chunks``, ``images_from``, ``batch_count``).
    """

    def __init__(self, data: StreamedData, split: str, objects: tuple[str, ...] = (), *,
                 drop_bottomed_out: bool = False, output: OutputSpec | None = None, buffer_parts: int = 2) -> None:
        if buffer_parts < 1:
            raise ValueError(f"buffer_parts must be >= 1, got {buffer_parts}")
        unknown = set(objects) - set(data.object_names)
        if unknown:
            raise ValueError(f"objects {sorted(unknown)} are not in the dataset; it has {data.object_names}")
        self.data, self.split, self.objects, self.drop = data, split, tuple(objects), drop_bottomed_out
        self.buffer_parts = buffer_parts
        output = output or OutputSpec.for_data(data)
        self.scale = data.image.scale / output.scale
        self.offset = (data.image.offset - output.offset) / output.scale
        self.data_range = data.image.data_range / output.scale
        self.vector = data.channels.kind == "magnetic_vector"
        self.device = torch.device("cpu")
        self.loads, self.held, self.peak_samples = 0, 0, 0
        self.counts = self._counts()
        if sum(self.counts) == 0:
            raise ValueError(f"no samples in split {split!r}" + (f" for objects {list(objects)}" if objects else "")
                             + (" once the presses flagged bottomed_out are left out" if drop_bottomed_out else ""))

    def _counts(self) -> list[int]:
        """Selected samples per part: from the manifests, or by reading each part once when filtering."""
        if not self.objects and not self.drop:
            return [self.data.part_splits(j)[self.split] for j in range(len(self.data.parts))]
        return [len(self._index(self.data.load_part(j))) for j in range(len(self.data.parts))]

    def _index(self, part: PairedDataset) -> np.ndarray:
        idx = np.flatnonzero(part.split == self.split)
        if self.objects:
            idx = idx[np.isin(part.objects(idx), list(self.objects))]
        if self.drop and part.has("bottomed_out"):
            idx = idx[~part.extra("bottomed_out")[idx].astype(bool)]
        return idx

    def __len__(self) -> int:
        return sum(self.counts)

    def to(self, device: torch.device | str) -> StreamedPairs:
        """Batches are moved to ``device`` as they are drawn (the parts stay on the CPU)."""
        self.device = torch.device(device)
        return self

    def batch_count(self, batch_size: int) -> int:
        """Full batches per epoch (the last partial one is dropped, as for :class:`TensorPairs`)."""
        return len(self) // batch_size

    def images_from(self, stored: torch.Tensor) -> torch.Tensor:
        """Stored images -> float32 images in the target unit."""
        out = stored.float() * self.scale
        return out + self.offset if self.offset else out

    def _load(self, j: int) -> tuple[torch.Tensor, torch.Tensor]:
        _trim_heap()  # what the previous part left free goes back before the next is read
        part = self.data.load_part(j)
        idx = self._index(part)
        self.loads += 1
        field = torch.from_numpy(np.ascontiguousarray(part.readings[idx], dtype=np.float32))
        return field, torch.from_numpy(np.ascontiguousarray(part.require_images("image training pairs")[idx]))

    def _hold(self, samples: int) -> None:
        self.held = samples
        self.peak_samples = max(self.peak_samples, samples)

    def batches(self, batch_size: int, gen: torch.Generator, *, rank: int = 0, world: int = 1
                ) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """This process's share of each global batch of one epoch: (readings, images) on the device."""
        per_rank = batch_size // world
        keep_at_most = (self.buffer_parts - 1) * max(self.counts)
        parts = [j for j in range(len(self.counts)) if self.counts[j]]
        order = torch.randperm(len(parts), generator=gen).tolist()
        field, stored = None, None
        for step, p in enumerate(order):
            f, s = self._load(parts[p])
            field = f if field is None else torch.cat([field, f])
            stored = s if stored is None else torch.cat([stored, s])
            self._hold(len(field))
            # emit enough full batches to bring the buffer back to keep_at_most; the last part empties it
            keep = 0 if step == len(order) - 1 else keep_at_most
            n = min(len(field) // batch_size, -(-max(len(field) - keep, 0) // batch_size)) * batch_size
            perm = torch.randperm(len(field), generator=gen)
            for b in range(0, n, batch_size):
                batch = perm[b:b + batch_size][rank * per_rank:(rank + 1) * per_rank]
                yield field[batch].to(self.device), self.images_from(stored[batch].to(self.device))
            field, stored = field[perm[n:]], stored[perm[n:]]
        self._hold(0)

    def chunks(self, size: int) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """Every sample once, in order, in chunks of at most ``size``: (readings, images) on the device."""
        for j in range(len(self.counts)):
            if self.counts[j]:
                field, stored = self._load(j)
                self._hold(len(field))
                for b in range(0, len(field), size):
                    yield field[b:b + size].to(self.device), self.images_from(stored[b:b + size].to(self.device))
        self._hold(0)

    def reading_moments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-channel mean, standard deviation and largest magnitude (A,) of the split's readings (two passes)."""
        count = self.data.channels.count
        total, n = np.zeros(count), 0
        for field, _ in self.chunks(4096):
            x = field.reshape(-1, count).double().numpy()
            total, n = total + x.sum(axis=0), n + len(x)
        mean, sq, absmax = total / n, np.zeros(count), np.zeros(count)
        for field, _ in self.chunks(4096):
            x = field.reshape(-1, count).double().numpy()
            sq, absmax = sq + ((x - mean) ** 2).sum(axis=0), np.maximum(absmax, np.abs(x).max(axis=0))
        return mean, np.sqrt(sq / n), absmax
