"""Make a paired dataset from plain arrays: a user's own sensor and images, no converter to write.

:func:`from_arrays` checks everything a training run would otherwise trip over later (ranks, sample
counts, NaN, images outside their stated range, splits that leave nothing to train on, groups cut by a split)
and raises :class:`~tactile_manip.errors.DatasetError` naming the array and the problem. :func:`read_array`
reads one array from ``.npy``, a named entry of ``.npz``, or a dataset of an HDF5 file (needs h5py: the
``hdf5`` extra).
"""

from __future__ import annotations

import time
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.data.dataset import SPLITS, PairedDataset
from tactile_manip.data.io import numpy_file_kind
from tactile_manip.data.spec import CHANNEL_KINDS, ChannelSpec, ImageSpec
from tactile_manip.data.targets import check_target_names
from tactile_manip.errors import DatasetError
from tactile_manip.version import code_version

HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")


def from_arrays(readings: np.ndarray, images: np.ndarray | None = None, *,
                targets: dict[str, np.ndarray] | None = None, split: np.ndarray | None = None,
                groups: np.ndarray | None = None, objects: np.ndarray | None = None,
                val_fraction: float = 0.1, test_fraction: float = 0.1, seed: int = 0,
                channel_names: Sequence[str] | None = None, channel_kind: str | None = None,
                reading_unit: str | None = None, image_unit: str = "mm", pixel_mm: float | None = None,
                data_range: float | None = None, value_min: float | None = None,
                extras: dict[str, np.ndarray] | None = None, provenance: dict[str, Any] | None = None
                ) -> PairedDataset:
    """A :class:`PairedDataset` from arrays (every argument after ``images`` is keyword-only).

    Args:
        readings: (N, R, C, A) or (N, R, C) (one channel), any real dtype; stored as float32.
        images: (N, H, W), any real dtype; stored as float32 (uint8 / uint16 are kept as they are). May be
            None when ``targets`` are given.
        targets: per-sample targets by name, each (N,) (``{"x_mm": x, "force_n": f}``; names carry their
            unit, see :mod:`tactile_manip.data.targets`); stored as one (N, K) float32 array.
        split: (N,) of 'train' / 'val' / 'test'; when None the samples (or whole ``groups``) are drawn at
            random into val and test by ``val_fraction`` and ``test_fraction`` with ``seed``.
        groups: (N,) ids of samples that belong together (one contact, one participant): never cut by a split.
        objects: (N,) names of what was pressed (per-object tables, training-object filters).
        channel_names / channel_kind / reading_unit: default to x, y, z magnetic_vector in uT for three
            channels, and to c0.. scalar in "1" otherwise.
        image_unit, pixel_mm: the images' unit and pixel pitch (mm, None when unknown).
        data_range, value_min: the images' value interval [value_min, value_min + data_range] (PSNR's L);
            by default the interval the images span (value_min 0 when no value is negative).
        extras: optional per-sample arrays (pose, force_n, contact, ...), each with N rows.

    Raises:
        DatasetError: one line naming the array and what is wrong with it.
    """
    if images is None and not targets:
        raise DatasetError("images or targets: a dataset needs one of them (or both); neither was given")
    readings = _as_real("readings", readings)
    if readings.ndim == 3:
        readings = readings[..., None]
    if readings.ndim != 4:
        raise DatasetError(f"readings: expected shape (N, rows, cols) or (N, rows, cols, channels), got "
                           f"{readings.shape} (rank {readings.ndim})")
    n = readings.shape[0]
    if n == 0:
        raise DatasetError("readings: no samples (N = 0)")
    channels = _channels(readings.shape[-1], channel_names, channel_kind, reading_unit)
    target_arr, target_names = _targets(targets, n)
    image, stored_images = ImageSpec(), None
    if images is not None:
        images = _as_real("images", images)
        if images.ndim != 3:
            raise DatasetError(f"images: expected shape (N, H, W), got {images.shape} (rank {images.ndim})")
        _same_n("images", images, n)
        image = _image_spec(images, image_unit, pixel_mm, data_range, value_min)
        stored_images = images if images.dtype in (np.uint8, np.uint16) else images.astype(np.float32)
    groups_arr = None if groups is None else _same_n("groups", _as_ids("groups", groups), n)
    split_arr = (_random_split(n, groups_arr, val_fraction, test_fraction, seed) if split is None
                 else _check_split(_same_n("split", np.asarray(split), n), groups_arr))
    object_index = object_names = None
    if objects is not None:
        names = _same_n("objects", np.asarray(objects).astype(str), n)
        object_names, inverse = np.unique(names, return_inverse=True)
        object_index = inverse.astype(np.int16 if len(object_names) < 2**15 else np.int32)
    extras = {k: _same_n(f"extras[{k!r}]", np.asarray(v), n) for k, v in (extras or {}).items()}
    prov = {"source": "tactile_manip.data.from_arrays", "code_version": code_version(),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **(provenance or {})}
    return PairedDataset(readings=readings.astype(np.float32), images=stored_images, split=split_arr,
                         channels=channels, image=image, object_index=object_index, object_names=object_names,
                         groups=groups_arr, extras=extras, provenance=prov, targets=target_arr,
                         target_names=target_names)


def read_array(path: str | Path, key: str | None = None) -> np.ndarray:
    """One array from ``.npy``, entry ``key`` of ``.npz``, or dataset ``key`` of an HDF5 file.

    Raises:
        DatasetError: missing file or entry, not an array file, or an object (pickled) array.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such file" if not path.is_dir() else f"{path} is a directory, not an array file")
    if path.suffix.lower() in HDF5_SUFFIXES:
        return _read_hdf5(path, key)
    if numpy_file_kind(path) == "other":  # np.load would take it for a pickle and say so: say what it is
        raise DatasetError(f"{path}: not a numpy file (.npy or .npz); for CSV probe logs use --readings-csv and "
                           f"--labels-csv")
    try:
        loaded = np.load(path, allow_pickle=False)
    except ValueError as e:  # object arrays need pickle: refused, files are data
        raise DatasetError(f"{path}: holds Python objects, not plain numbers; save it as a numeric array") from e
    except (OSError, EOFError, zipfile.BadZipFile) as e:
        raise DatasetError(f"{path}: not a .npy/.npz array file ({e})") from e
    if isinstance(loaded, np.lib.npyio.NpzFile):
        with loaded:
            if key is None:
                raise DatasetError(f"{path}: an .npz holds several arrays {sorted(loaded.files)}; name one")
            if key not in loaded.files:
                raise DatasetError(f"{path}: no array {key!r}; it holds {sorted(loaded.files)}")
            try:
                return loaded[key]
            except ValueError as e:
                raise DatasetError(f"{path}[{key}]: holds Python objects, not plain numbers") from e
    if key is not None:
        raise DatasetError(f"{path}: a .npy holds one array; it has no entry {key!r}")
    return loaded


def array_names(path: str | Path) -> list[str]:
    """Names of the arrays in an ``.npz`` or HDF5 file (top level)."""
    path = Path(path)
    if path.suffix.lower() in HDF5_SUFFIXES:
        h5py = _h5py()
        with h5py.File(path, "r") as f:
            return sorted(k for k, v in f.items() if isinstance(v, h5py.Dataset))
    try:
        with np.load(path, allow_pickle=False) as z:
            return sorted(z.files)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, AttributeError) as e:
        raise DatasetError(f"{path}: not an .npz archive of named arrays ({e})") from e


# --- checks ------------------------------------------------------------------------------------------------
def _as_real(name: str, a: Any) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise DatasetError(f"{name}: expected real numbers, got dtype {a.dtype}")
    if np.issubdtype(a.dtype, np.floating):
        bad = ~np.isfinite(a)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise DatasetError(f"{name}: {int(bad.sum())} NaN or infinite values (first at index {first})")
        big = np.abs(a) > np.finfo(np.float32).max  # stored as float32: these would become inf
        if big.any():
            first = tuple(int(i) for i in np.argwhere(big)[0])
            raise DatasetError(f"{name}: {int(big.sum())} values beyond float32's range (+-3.4e38), which the dataset "
                               f"stores (first at index {first}: {a[first]:.3g}); they would become inf")
    return a


def _as_ids(name: str, a: Any) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 1:
        raise DatasetError(f"{name}: expected one id per sample, shape (N,), got {a.shape}")
    if a.dtype.kind in "US" or a.dtype == object:
        _, inverse = np.unique(a.astype(str), return_inverse=True)
        return inverse.astype(np.int64)
    if not np.issubdtype(a.dtype, np.integer):
        raise DatasetError(f"{name}: expected integer or string ids, got dtype {a.dtype}")
    return a.astype(np.int64)


def _targets(targets: dict[str, np.ndarray] | None, n: int) -> tuple[np.ndarray | None, tuple[str, ...]]:
    if not targets:
        return None, ()
    names = check_target_names(list(targets))
    columns = [_same_n(f"targets[{k!r}]", _as_real(f"targets[{k!r}]", np.asarray(targets[k]).reshape(-1)), n)
               for k in names]
    return np.stack(columns, axis=1).astype(np.float32), names


def _same_n(name: str, a: np.ndarray, n: int) -> np.ndarray:
    if a.ndim == 0 or a.shape[0] != n:
        raise DatasetError(f"{name}: {a.shape[0] if a.ndim else 'a scalar, no'} samples, readings have {n}")
    return a


def _channels(count: int, names: Sequence[str] | None, kind: str | None, unit: str | None) -> ChannelSpec:
    if kind is not None and kind not in CHANNEL_KINDS:
        raise DatasetError(f"channel kind: {kind!r} is not one of {', '.join(CHANNEL_KINDS)}")
    magnetic = kind == "magnetic_vector" or (kind is None and count == 3)
    names = tuple(names) if names else (("x", "y", "z") if magnetic else tuple(f"c{i}" for i in range(count)))
    if len(names) != count:
        raise DatasetError(f"channel names: {len(names)} names {list(names)} for {count} channels in readings")
    try:
        return ChannelSpec(names=names, kind="magnetic_vector" if magnetic else "scalar",
                           unit=unit or ("uT" if magnetic else "1"))
    except ValueError as e:
        raise DatasetError(f"channels: {e}") from e


def _image_spec(images: np.ndarray, unit: str, pixel_mm: float | None, data_range: float | None,
                value_min: float | None) -> ImageSpec:
    lo, hi = float(images.min()), float(images.max())
    vmin = float(value_min) if value_min is not None else min(0.0, lo)
    rng = float(data_range) if data_range is not None else max(hi - vmin, 1e-12)
    try:
        spec = ImageSpec(unit=unit, data_range=rng, value_min=vmin, pixel_mm=pixel_mm)
    except ValueError as e:
        raise DatasetError(f"images: {e}") from e
    tol = 1e-6 * spec.data_range
    if lo < spec.value_min - tol or hi > spec.value_max + tol:
        raise DatasetError(f"images: values span [{lo:g}, {hi:g}] {unit}, outside their stated range "
                           f"[{spec.value_min:g}, {spec.value_max:g}] (set the data range and value min to match)")
    return spec


def _check_split(split: np.ndarray, groups: np.ndarray | None) -> np.ndarray:
    split = split.astype(str)
    unknown = sorted(set(np.unique(split).tolist()) - set(SPLITS))
    if unknown:
        raise DatasetError(f"split: values {unknown[:5]} are not one of {', '.join(SPLITS)}")
    if not np.any(split == "train"):
        raise DatasetError("split: no sample is 'train': nothing to train on")
    if groups is not None:
        for g in np.unique(groups):
            parts = np.unique(split[groups == g])
            if len(parts) > 1:
                raise DatasetError(f"groups: group {g} is in several splits ({', '.join(parts)}); a split may "
                                   f"not cut a group")
    return split.astype("U5")


def _random_split(n: int, groups: np.ndarray | None, val_fraction: float, test_fraction: float,
                  seed: int) -> np.ndarray:
    for name, f in (("val_fraction", val_fraction), ("test_fraction", test_fraction)):
        if not 0.0 <= f < 1.0:
            raise DatasetError(f"{name}: must be in [0, 1), got {f}")
    if val_fraction + test_fraction >= 1.0:
        raise DatasetError(f"val_fraction + test_fraction = {val_fraction + test_fraction:g} leaves nothing "
                           f"to train on (must be < 1)")
    ids = np.arange(n) if groups is None else groups
    unique, counts = np.unique(ids, return_counts=True)
    order = np.random.default_rng(seed).permutation(len(unique))
    # whole groups in random order: test until it holds its share, then val, the rest train
    targets, filled = {"test": test_fraction * n, "val": val_fraction * n}, {"test": 0, "val": 0}
    lookup = {}
    for u, c in zip(unique[order].tolist(), counts[order].tolist()):
        part = next((s for s in ("test", "val") if filled[s] < targets[s]), "train")
        filled[part] = filled.get(part, 0) + c
        lookup[u] = part
    out = np.array([lookup[u] for u in ids.tolist()], dtype="U5")
    if not np.any(out == "train"):
        raise DatasetError(f"groups: {len(unique)} groups leave none for training at val_fraction "
                           f"{val_fraction:g} and test_fraction {test_fraction:g} (a split never cuts a group)")
    return out


def _h5py() -> Any:
    from tactile_manip.extras import require

    return require("h5py", "reading HDF5")


def _read_hdf5(path: Path, key: str | None) -> np.ndarray:
    h5py = _h5py()
    try:
        with h5py.File(path, "r") as f:
            names = sorted(k for k, v in f.items() if isinstance(v, h5py.Dataset))
            if key is None:
                raise DatasetError(f"{path}: an HDF5 file holds several datasets {names}; name one")
            if key not in f or not isinstance(f[key], h5py.Dataset):
                raise DatasetError(f"{path}: no dataset {key!r}; it holds {names}")
            return np.asarray(f[key][()])
    except OSError as e:
        raise DatasetError(f"{path}: not an HDF5 file ({e})") from e
