"""The paired dataset file: one compressed ``.npz`` of arrays plus a JSON metadata string.

Layout (N samples; the taxel grid and image size are whatever the producer wrote):

- ``field_ut`` (N, R, C, 3) float32: baseline-subtracted magnetic readings, microtesla;
- ``field_raw_ut`` (N, R, C, 3) float32 and ``saturated`` (N, R, C, 3) bool;
- ``depth_q`` (N, H, W) uint8: depth in units of ``metadata["depth_scale_mm"]`` (0.01 mm; DTact resolves
  ~0.03 mm per grey level, so this loses nothing the sensor can see);
- ``object_index`` (N,) int16 into ``object_names`` (K,) str; ``split`` (N,) str in train/val/test;
- ``pose`` (N, 5) float32 ``[x_mm, y_mm, yaw_rad, tilt_x_rad, tilt_y_rad]``; ``force_n``, ``approach_mm``,
  ``skin_approach_mm`` (N,) float32; ``contact`` (N,) bool;
- ``metadata`` () str: JSON with the format version, the generating config and parameters, the code
  version and creation time.

Files are data: they are read with ``allow_pickle=False``.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.checks import npz_read_problem
from tactile_manip.errors import DatasetError

FORMAT_VERSION = 1
DEPTH_SCALE_MM = 0.01
SPLITS = ("train", "val", "test")
_REQUIRED = ("field_ut", "field_raw_ut", "saturated", "depth_q", "object_index", "object_names", "split",
             "pose", "force_n", "approach_mm", "skin_approach_mm", "contact", "metadata")


@dataclass(frozen=True, eq=False)
class PairedDataset:
    """Arrays of a paired dataset in memory (see the module docstring for shapes and units)."""

    field_ut: np.ndarray
    field_raw_ut: np.ndarray
    saturated: np.ndarray
    depth_q: np.ndarray
    object_index: np.ndarray
    object_names: np.ndarray
    split: np.ndarray
    pose: np.ndarray
    force_n: np.ndarray
    approach_mm: np.ndarray
    skin_approach_mm: np.ndarray
    contact: np.ndarray
    metadata: dict[str, Any]

    def __len__(self) -> int:
        return int(self.field_ut.shape[0])

    @property
    def depth_scale_mm(self) -> float:
        """Millimetres per unit of ``depth_q``."""
        return float(self.metadata.get("depth_scale_mm", DEPTH_SCALE_MM))

    def depth_mm(self, index: np.ndarray | slice | None = None) -> np.ndarray:
        """Depth images (n, H, W) float32 in mm for ``index`` (all samples when None)."""
        q = self.depth_q if index is None else self.depth_q[index]
        return q.astype(np.float32) * np.float32(self.depth_scale_mm)

    def indices(self, split: str, objects: tuple[str, ...] | list[str] = ()) -> np.ndarray:
        """Sample indices of ``split`` ('train', 'val' or 'test'), ascending; only of ``objects`` (names) if given."""
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        idx = np.flatnonzero(self.split == split)
        if len(objects):
            unknown = set(objects) - set(self.object_names.tolist())
            if unknown:
                raise ValueError(f"objects {sorted(unknown)} are not in the dataset; it has "
                                 f"{self.object_names.tolist()}")
            idx = idx[np.isin(self.objects(idx), list(objects))]
        return idx

    def objects(self, index: np.ndarray | None = None) -> np.ndarray:
        """Object names (n,) of the samples at ``index`` (all when None)."""
        idx = self.object_index if index is None else self.object_index[index]
        return self.object_names[idx]

    def fingerprint(self) -> str:
        """SHA-256 (first 16 hex) over the readings, depths and splits: identifies the training data."""
        h = hashlib.sha256()
        for a in (self.field_ut, self.depth_q, self.split.astype("U5"), self.object_index):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]


def dataset_path(path: str | Path) -> Path:
    """The file :func:`save_dataset` writes for ``path``: ``path`` itself, with ``.npz`` appended if missing."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def save_dataset(path: str | Path, data: PairedDataset) -> Path:
    """Write ``data`` to :func:`dataset_path` of ``path`` atomically (a temp file, then rename); return it."""
    path = dataset_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {name: getattr(data, name) for name in _REQUIRED if name != "metadata"}
    arrays["metadata"] = np.array(json.dumps(data.metadata))
    tmp = path.with_name(path.name + ".partial")
    with tmp.open("wb") as f:
        np.savez_compressed(f, **arrays)
    tmp.replace(path)
    return path


def check_dataset_file(path: str | Path) -> Path:
    """``path`` after checking it is an existing file (DatasetError otherwise), before any long work."""
    path = Path(path)
    if path.is_dir():
        raise DatasetError(f"{path} is a directory; give a dataset .npz file")
    if not path.is_file():
        raise DatasetError(f"dataset not found: {path} (make one with `tactile-manip simulate --out {path}`)")
    return path


def load_dataset(path: str | Path) -> PairedDataset:
    """Read a dataset written by :func:`save_dataset` (or ``tactile-manip simulate`` / ``collect``).

    Raises:
        DatasetError: missing file, not an npz, missing arrays, inconsistent lengths, or a newer format.
    """
    path = check_dataset_file(path)
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise DatasetError(f"{path}: holds a single array, not a dataset archive (.npz)")
        with z:
            missing = [k for k in _REQUIRED if k not in z.files]
            if missing:
                raise DatasetError(f"{path} is not a tactile_manip dataset (no arrays {', '.join(missing[:4])}"
                                   f"{', ...' if len(missing) > 4 else ''}); make one with `tactile-manip simulate`"
                                   " or `tactile-manip collect`")
            arrays = {k: z[k] for k in _REQUIRED}
    except DatasetError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise DatasetError(f"{path} is not a tactile_manip dataset: {npz_read_problem(e)}") from e
    try:
        meta = json.loads(str(arrays.pop("metadata")))
    except json.JSONDecodeError as e:
        raise DatasetError(f"{path}: metadata is not valid JSON: {e}") from e
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        raise DatasetError(f"{path}: format version {version!r}, this code reads {FORMAT_VERSION}")
    n = arrays["field_ut"].shape[0]
    bad = [k for k, a in arrays.items() if k != "object_names" and a.shape[0] != n]
    if bad:
        raise DatasetError(f"{path}: arrays {bad} do not have {n} samples like field_ut")
    return PairedDataset(**arrays, metadata=meta)


def quantise_depth(depth_mm: np.ndarray) -> np.ndarray:
    """Depth (mm) -> uint8 in units of ``DEPTH_SCALE_MM`` (saturating at 2.55 mm)."""
    return np.clip(np.rint(np.asarray(depth_mm) / DEPTH_SCALE_MM), 0, 255).astype(np.uint8)
