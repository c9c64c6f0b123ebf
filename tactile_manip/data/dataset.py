"""A dataset in memory: readings with named channels, and images with a unit, per-sample targets, or both.

Shapes (N samples):

- ``readings`` (N, R, C, A) float32: one reading per sample, R x C taxels of A channels (``channels``);
- ``images`` (N, H, W) or None: the stored image values (any real dtype; ``image`` maps them to its unit);
- ``targets`` (N, K) float32 or None, named by ``target_names`` (K,) with their unit as suffix (``x_mm``,
  ``y_mm``, ``depth_mm``, ``force_n``, ``shear_x_n``, ``shear_y_n``, ``in_contact`` 0/1; see
  :mod:`tactile_manip.data.targets`): labelled presses. A dataset holds images, targets or both;
- ``split`` (N,) str in ``SPLITS``, or ``unlabelled`` (readings of the training part whose targets are NaN);
- ``object_index`` (N,) int16 into ``object_names`` (K,) str, optional: what was pressed (per-object tables,
  training-object filters);
- ``groups`` (N,) int64, optional: samples that belong together (one contact, one participant, one recorded
  run); a random split never cuts a group, a chronological split of recorded runs cuts each run in time;
- ``extras``: optional per-sample arrays the producer has, e.g. ``pose`` (N, 5) ``[x_mm, y_mm, yaw_rad,
  tilt_x_rad, tilt_y_rad]``, ``force_n``, ``approach_mm``, ``skin_approach_mm``, ``contact`` (bool),
  ``field_raw_ut`` and ``saturated`` (N, R, C, A);
- ``provenance``: JSON-able dict (who made it, from what config, code version, time).

This module imports numpy only: the simulator, the collection pipeline and :func:`~tactile_manip.data.imports.
from_arrays` produce datasets; training, evaluation and the commands consume them.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_manip.boards.identity import check_same_board, record_of_provenance
from tactile_manip.data.spec import ChannelSpec, ImageSpec
from tactile_manip.data.targets import check_target_names, check_targets, target_unit
from tactile_manip.errors import DatasetError

SPLITS = ("train", "val", "test")
#: the split of training-part readings whose labels were held back (``import --labelled K``): their targets are NaN
UNLABELLED = "unlabelled"
# the per-sample arrays the fingerprint hashes, in this order (each whole, then the next); then the target names
FINGERPRINT_ARRAYS = ("readings", "images", "split", "object_index", "groups", "targets")


def fingerprint_bytes(name: str, value: np.ndarray | tuple[str, ...]) -> bytes:
    """The bytes :meth:`PairedDataset.fingerprint` hashes for the array ``name`` (one of
    :data:`FINGERPRINT_ARRAYS`, or ``"target_names"``); the hash of a dataset stored in shards feeds the same
    bytes, array by array and shard by shard."""
    if name == "target_names":
        return np.array(",".join(value)).tobytes()
    if name == "split":
        value = value.astype("U5")
    return np.ascontiguousarray(value).tobytes()


@dataclass(frozen=True, eq=False)
class PairedDataset:
    """Arrays of a dataset (see the module docstring for shapes and units)."""

    readings: np.ndarray
    images: np.ndarray | None
    split: np.ndarray
    channels: ChannelSpec = field(default_factory=ChannelSpec)
    image: ImageSpec = field(default_factory=ImageSpec)
    object_index: np.ndarray | None = None
    object_names: np.ndarray | None = None
    groups: np.ndarray | None = None
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    targets: np.ndarray | None = None
    target_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self)
        if self.readings.ndim != 4 or self.readings.shape[-1] != self.channels.count:
            raise DatasetError(f"readings: expected shape (N, rows, cols, {self.channels.count}) for channels "
                               f"{list(self.channels.names)}, got {self.readings.shape}")
        if self.images is None and self.targets is None:
            raise DatasetError("a dataset holds images, per-sample targets, or both; this one has neither")
        if self.images is not None and (self.images.ndim != 3 or self.images.shape[0] != n):
            raise DatasetError(f"images: expected shape ({n}, H, W), got {self.images.shape}")
        if self.targets is None:
            if self.target_names:
                raise DatasetError(f"target names {list(self.target_names)} without targets")
        else:
            names = check_target_names(self.target_names)
            object.__setattr__(self, "target_names", names)
            object.__setattr__(self, "targets", check_targets(self.targets, names, n,
                                                              unlabelled=np.asarray(self.split) == UNLABELLED))
        if self.split.shape != (n,):
            raise DatasetError(f"split: expected shape ({n},), got {self.split.shape}")
        if (self.object_index is None) != (self.object_names is None):
            raise DatasetError("object_index and object_names come together (both or neither)")
        if self.object_index is not None and self.object_index.shape != (n,):
            raise DatasetError(f"object_index: expected shape ({n},), got {self.object_index.shape}")
        if self.groups is not None and self.groups.shape != (n,):
            raise DatasetError(f"groups: expected shape ({n},), got {self.groups.shape}")
        bad = [k for k, a in self.extras.items() if a.shape[:1] != (n,)]
        if bad:
            raise DatasetError(f"extras {bad} do not have {n} samples like readings")

    def __len__(self) -> int:
        return int(self.readings.shape[0])

    # --- geometry ------------------------------------------------------------------------------------------
    @property
    def grid(self) -> tuple[int, int]:
        """Taxel rows and columns (R, C)."""
        return int(self.readings.shape[1]), int(self.readings.shape[2])

    @property
    def image_shape(self) -> tuple[int, int]:
        """Image height and width (H, W), pixels (DatasetError for a dataset without images)."""
        images = self.require_images("image_shape")
        return int(images.shape[1]), int(images.shape[2])

    @property
    def has_images(self) -> bool:
        """Whether the dataset holds images (a labelled-press dataset may hold only targets)."""
        return self.images is not None

    @property
    def has_targets(self) -> bool:
        """Whether the dataset holds per-sample targets (``target_names`` says which)."""
        return self.targets is not None

    def require_images(self, what: str) -> np.ndarray:
        """The stored images; for a dataset without them, DatasetError saying that ``what`` needs images.

        Every consumer of images calls it first, so a targets-only dataset is refused in one line that says
        what it holds and where labelled presses are trained instead.
        """
        if self.images is None:
            names = ", ".join(self.target_names)
            raise DatasetError(f"{what} needs images; this dataset holds targets only ({names}): labelled presses "
                               f"train and evaluate as contact models (docs/contact.md)")
        return self.images

    # --- values --------------------------------------------------------------------------------------------
    def target(self, name: str) -> np.ndarray:
        """Target ``name`` (N,) float32 in the unit its name carries; DatasetError naming the targets there are."""
        if self.targets is None or name not in self.target_names:
            have = ", ".join(self.target_names) or "none"
            raise DatasetError(f"the dataset has no target {name!r} (its targets: {have})")
        return self.targets[:, self.target_names.index(name)]

    def target_units(self) -> dict[str, str]:
        """Each target's unit, by name ("1" for the ``in_contact`` flag)."""
        return {n: target_unit(n) for n in self.target_names}

    def image_values(self, index: np.ndarray | slice | None = None) -> np.ndarray:
        """Images (n, H, W) float32 in the image unit for ``index`` (all samples when None)."""
        images = self.require_images("image_values()")
        stored = images if index is None else images[index]
        out = stored.astype(np.float32) * np.float32(self.image.scale)
        return out + np.float32(self.image.offset) if self.image.offset else out

    def depth_mm(self, index: np.ndarray | slice | None = None) -> np.ndarray:
        """Depth images (n, H, W) float32 in mm: :meth:`image_values` of a dataset whose images are in mm."""
        if self.image.unit != "mm":
            raise DatasetError(f"the images are in {self.image.unit!r}, not depth in mm: use image_values()")
        return self.image_values(index)

    @property
    def field_ut(self) -> np.ndarray:
        """Readings (N, R, C, 3) in microtesla, for a dataset of magnetic readings in uT."""
        if self.channels.kind != "magnetic_vector" or self.channels.unit != "uT":
            raise DatasetError(f"the readings are {self.channels.kind} in {self.channels.unit!r}, not a magnetic "
                               f"field in uT: use .readings")
        return self.readings

    def has(self, name: str) -> bool:
        """Whether the producer stored the per-sample extra ``name`` (e.g. ``"pose"``)."""
        return name in self.extras

    def extra(self, name: str) -> np.ndarray:
        """The per-sample extra ``name``; DatasetError naming what the dataset has when it is absent."""
        if name not in self.extras:
            have = ", ".join(sorted(self.extras)) or "none"
            raise DatasetError(f"the dataset has no {name!r} per sample (its extras: {have})")
        return self.extras[name]

    # --- selection -----------------------------------------------------------------------------------------
    def _split_counts(self) -> dict[str, int]:
        """Samples per split; ``unlabelled`` only where a dataset has such rows."""
        counts = {s: int(np.sum(self.split == s)) for s in SPLITS}
        unlabelled = int(np.sum(self.split == UNLABELLED))
        return {**counts, UNLABELLED: unlabelled} if unlabelled else counts

    def indices(self, split: str, objects: tuple[str, ...] | list[str] = ()) -> np.ndarray:
        """Sample indices of ``split`` ('train', 'val', 'test' or 'unlabelled': training-part readings without
        labels), ascending; only of ``objects`` (names) if given."""
        if split not in (*SPLITS, UNLABELLED):
            raise ValueError(f"split must be one of {(*SPLITS, UNLABELLED)}, got {split!r}")
        idx = np.flatnonzero(self.split == split)
        if len(objects):
            known = [] if self.object_names is None else self.object_names.tolist()
            unknown = set(objects) - set(known)
            if unknown:
                raise ValueError(f"objects {sorted(unknown)} are not in the dataset; it has {known}")
            idx = idx[np.isin(self.objects(idx), list(objects))]
        return idx

    def objects(self, index: np.ndarray | None = None) -> np.ndarray:
        """Object names (n,) of the samples at ``index`` (all when None); "all" when the data names none."""
        if self.object_index is None:
            n = len(self) if index is None else len(np.arange(len(self))[index])
            return np.full(n, "all")
        idx = self.object_index if index is None else self.object_index[index]
        return self.object_names[idx]

    def subset(self, index: np.ndarray) -> PairedDataset:
        """The samples ``index`` as a dataset of their own (same specs, object names and provenance)."""
        def take(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[index]

        return PairedDataset(readings=self.readings[index], images=take(self.images), split=self.split[index],
                             channels=self.channels, image=self.image, object_index=take(self.object_index),
                             object_names=self.object_names, groups=take(self.groups),
                             extras={k: v[index] for k, v in self.extras.items()}, provenance=self.provenance,
                             targets=take(self.targets), target_names=self.target_names)

    def fingerprint(self) -> str:
        """SHA-256 (first 16 hex) over readings, stored images, splits, objects, groups and targets: identifies
        training data.

        An image dataset hashes the same bytes as format version 1 did, so a file converted from it keeps its
        fingerprint; targets and their names are hashed after them.
        """
        h = hashlib.sha256()
        for name in FINGERPRINT_ARRAYS:
            if getattr(self, name) is not None:
                h.update(fingerprint_bytes(name, getattr(self, name)))
        if self.targets is not None:
            h.update(fingerprint_bytes("target_names", self.target_names))
        return h.hexdigest()[:16]

    def describe(self) -> dict[str, Any]:
        """What the data is, for model metadata and reports (JSON-able); image entries are None without images."""
        return {"samples": len(self), "grid": list(self.grid), "channels": self.channels.to_dict(),
                "image_shape": list(self.image_shape) if self.has_images else None,
                "image": self.image.to_dict() if self.has_images else None,
                "targets": self.target_units() if self.has_targets else None,
                "splits": self._split_counts(), "fingerprint": self.fingerprint(),
                "source": self.provenance.get("source", "unknown")}


def concatenate(datasets: list[PairedDataset] | tuple[PairedDataset, ...]) -> PairedDataset:
    """One dataset of several, in order: same channels and image spec; object names merged, groups kept apart.

    Splits are kept as each dataset has them. Either every dataset has images or none has; likewise targets,
    with the same names in the same order. Extras are kept when every dataset has them with the same
    per-sample shape; the others are left out and named in ``provenance["dropped_extras"]`` (a flag such as
    ``bottomed_out`` that one producer did not record is not invented for its samples). When any dataset has
    groups, one without gets one group per sample, so no group spans two datasets.
    """
    parts = list(datasets)
    if not parts:
        raise DatasetError("concatenate needs at least one dataset")
    first = parts[0]
    for i, d in enumerate(parts[1:], start=1):
        if d.channels != first.channels:
            raise DatasetError(f"dataset {i} has channels {d.channels.to_dict()}, dataset 0 has "
                               f"{first.channels.to_dict()}")
        if d.has_images != first.has_images:
            raise DatasetError(f"dataset {i} {'has' if d.has_images else 'has no'} images, dataset 0 "
                               f"{'has' if first.has_images else 'has none'}")
        if d.target_names != first.target_names:
            raise DatasetError(f"dataset {i} has targets {list(d.target_names)}, dataset 0 has "
                               f"{list(first.target_names)}")
        if d.grid != first.grid:
            raise DatasetError(f"dataset {i} has a {d.grid} grid, dataset 0 a {first.grid} grid")
        if first.has_images and d.image != first.image:
            raise DatasetError(f"dataset {i} has images {d.image.to_dict()}, dataset 0 has {first.image.to_dict()}")
        if first.has_images and d.image_shape != first.image_shape:
            raise DatasetError(f"dataset {i} has {d.image_shape} images, dataset 0 {first.image_shape} images")
    boards = [record_of_provenance(d.provenance) for d in parts]
    for i, board in enumerate(boards[1:], start=1):
        check_same_board(f"dataset {i}", board, "dataset 0", boards[0])
    object_index, names = None, None
    if any(d.object_names is not None for d in parts):  # a dataset that names none is the object "all"
        names = list(dict.fromkeys(name for d in parts
                                   for name in (["all"] if d.object_names is None else d.object_names.tolist())))
        lookup = {name: i for i, name in enumerate(names)}
        object_index = np.concatenate([np.full(len(d), lookup["all"], np.int16) if d.object_names is None else
                                       np.array([lookup[n] for n in d.object_names.tolist()], np.int16)[d.object_index]
                                       for d in parts])  # each part's own index, mapped onto the merged names
    groups = None
    if any(d.groups is not None for d in parts):
        chunks, start = [], 0
        for d in parts:
            g = np.arange(len(d), dtype=np.int64) if d.groups is None else np.unique(d.groups, return_inverse=True)[1]
            chunks.append(g.astype(np.int64) + start)
            start = int(chunks[-1].max(initial=start - 1)) + 1
        groups = np.concatenate(chunks)
    common = [k for k in first.extras if all(k in d.extras and d.extras[k].shape[1:] == first.extras[k].shape[1:]
                                            for d in parts)]
    dropped = sorted({k for d in parts for k in d.extras} - set(common))
    extras = {k: np.concatenate([d.extras[k] for d in parts]) for k in common}
    provenance = {"source": "concatenate", **({"board": boards[0]} if boards[0] is not None else {}), "parts": [dict(d.provenance, fingerprint=d.fingerprint(), samples=len(d))
                                                     for d in parts], "dropped_extras": dropped}
    def joined(name: str) -> np.ndarray | None:
        return None if getattr(first, name) is None else np.concatenate([getattr(d, name) for d in parts])

    return PairedDataset(readings=joined("readings"), images=joined("images"), split=joined("split"),
                         channels=first.channels, image=first.image, object_index=object_index,
                         object_names=None if names is None else np.array(names), groups=groups, extras=extras,
                         provenance=provenance, targets=joined("targets"), target_names=first.target_names)
