"""The dataset file: one compressed ``.npz`` of arrays plus a JSON metadata string.

Format version 3 (written by :func:`save_dataset`):

- ``readings`` (N, R, C, A), ``split`` (N,) str;
- ``images`` (N, H, W), present when the dataset has images;
- ``targets`` (N, K) float32, present when it has per-sample targets (labelled presses);
- ``object_index`` (N,) int16 and ``object_names`` (K,) str, optional; ``groups`` (N,) int64, optional;
- ``extra__<name>``: one per-sample extra each (``pose``, ``force_n``, ``field_raw_ut``, ...);
- ``metadata`` () str: JSON ``{"format_version": 3, "channels": {...}, "image": {...} or null,
  "target_names": [...], "provenance": {...}}``.

Format version 2 (images always present, no targets) is read as it was written. Format version 1 (``tactile-manip simulate`` and ``collect`` before the dataset layer) is still read:
``field_ut`` -> magnetic readings in uT, ``depth_q`` -> depth images in mm (``depth_scale_mm`` per level, data
range 2 mm, the range every metric used then), its simulator fields -> extras. Files are data: they are read
with ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import replace
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.checks import npz_read_problem
from tactile_manip.data.dataset import PairedDataset, concatenate
from tactile_manip.data.shards import MANIFEST, ShardedDataset, is_shard_folder
from tactile_manip.data.spec import ChannelSpec, ImageSpec
from tactile_manip.errors import DatasetError
from tactile_manip.outputs import unfinished

FORMAT_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
DEPTH_SCALE_MM = 0.01       # the simulator's and collection's uint8 depth storage: 0.01 mm per level
DEPTH_RANGE_MM = 2.0        # data range of depth images in mm (DTact saturates near 1.9 mm)
_EXTRA = "extra__"
_V1_REQUIRED = ("field_ut", "field_raw_ut", "saturated", "depth_q", "object_index", "object_names", "split",
                "pose", "force_n", "approach_mm", "skin_approach_mm", "contact", "metadata")
_V1_EXTRAS = ("field_raw_ut", "saturated", "pose", "force_n", "approach_mm", "skin_approach_mm", "contact")


def depth_image_spec(pixel_mm: float | None = 0.1) -> ImageSpec:
    """The image spec of depth images stored as uint8 hundredths of a millimetre."""
    return ImageSpec(unit="mm", data_range=DEPTH_RANGE_MM, value_min=0.0, pixel_mm=pixel_mm, scale=DEPTH_SCALE_MM)


def quantise_depth(depth_mm: np.ndarray) -> np.ndarray:
    """Depth (mm) -> uint8 in units of ``DEPTH_SCALE_MM`` (saturating at 2.55 mm)."""
    return np.clip(np.rint(np.asarray(depth_mm) / DEPTH_SCALE_MM), 0, 255).astype(np.uint8)


def dataset_path(path: str | Path) -> Path:
    """The path :func:`save_dataset` writes for ``path`` (``.npz`` appended if missing)."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def dataset_source(path: str | Path) -> str | None:
    """What wrote the dataset file at ``path`` (its provenance's ``source``, e.g. "tactile-manip simulate"), or
    None when ``path`` is not a readable dataset file of this package."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["metadata"])) if "metadata" in z.files else None
    except Exception:  # noqa: BLE001 - any file that does not read as our dataset is simply not one
        return None
    provenance = meta.get("provenance") if isinstance(meta, dict) else None
    source = provenance.get("source") if isinstance(provenance, dict) else None
    return source if isinstance(source, str) else None


def written_by(*sources: str) -> Callable[[Path], bool]:
    """A check for :func:`~tactile_manip.outputs.check_output_file`'s ``ours``: the file is a dataset whose
    provenance names one of ``sources`` (a prefix of it)."""
    return lambda path: any((dataset_source(path) or "\0").startswith(s) for s in sources)


def save_dataset(path: str | Path, data: PairedDataset) -> Path:
    """Write ``data`` to ``path`` (``.npz`` appended if missing) atomically: a temp file, then rename."""
    path = dataset_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"readings": data.readings, "split": data.split}
    for name in ("images", "targets", "object_index", "object_names", "groups"):
        if getattr(data, name) is not None:
            arrays[name] = getattr(data, name)
    arrays.update({_EXTRA + k: v for k, v in data.extras.items()})
    meta = {"format_version": FORMAT_VERSION, "channels": data.channels.to_dict(),
            "image": data.image.to_dict() if data.has_images else None, "target_names": list(data.target_names),
            "provenance": data.provenance}
    arrays["metadata"] = np.array(json.dumps(meta))
    tmp = path.with_name(path.name + ".partial")
    with unfinished(tmp), tmp.open("wb") as f:
        np.savez_compressed(f, **arrays)
    tmp.replace(path)
    return path


def check_dataset_file(path: str | Path) -> Path:
    """``path`` after checking it is an existing dataset file or shard folder (DatasetError otherwise), before
    any long work; a shard folder's manifest is checked against the shard files there."""
    path = Path(path)
    if is_shard_folder(path):
        ShardedDataset(path)
        return path
    if path.is_dir():
        raise DatasetError(f"{path} is a directory without {MANIFEST}: neither a dataset file (.npz) nor a "
                           "sharded dataset (`tactile-manip simulate --shard-size N`)")
    if not path.is_file():
        raise DatasetError(f"dataset not found: {path} (make one with `tactile-manip simulate --out {path}` "
                           f"or `tactile-manip import ... --out {path}`)")
    return path


def load_dataset(path: str | Path, *, images: bool = True) -> PairedDataset:
    """Read a dataset written by :func:`save_dataset` (format 3) or by earlier versions (formats 1 and 2), or
    every shard of a shard folder (:mod:`tactile_manip.data.shards`) joined into one dataset in memory.

    ``images=False`` leaves the images of a labelled-press dataset unread (a file's image array is not
    decompressed; a shard folder's are read, then dropped): what a consumer of readings and targets needs, in
    a fraction of the memory. Its fingerprint is then that of the data without images. A dataset without
    targets keeps its images, since it would hold nothing else.

    Raises:
        DatasetError: missing file, not a numpy file, not a dataset of ours, missing arrays, inconsistent
            lengths, or a newer format; for a shard folder, a missing or unlisted shard or a fingerprint that
            does not match the manifest's.
    """
    if is_shard_folder(path):
        data = ShardedDataset(path).load()
        return data if images or data.targets is None else replace(data, images=None)
    path = check_dataset_file(path)
    if numpy_file_kind(path) == "other":  # np.load would call any other file a pickle
        raise DatasetError(f"{path} is not a tactile_manip dataset: it is not a numpy file (.npz); "
                           f"`tactile-manip import` makes a dataset from arrays or probe logs")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise DatasetError(f"{path}: holds a single array, not a dataset archive (.npz); "
                               f"`tactile-manip import` makes a dataset from arrays")
        with z:
            if "metadata" not in z.files:
                raise DatasetError(f"{path} is not a tactile_manip dataset (no 'metadata' entry; it holds "
                                   f"{sorted(z.files)[:8]}); `tactile-manip import` makes one from arrays")
            meta = _metadata(path, z["metadata"])
            version = meta.get("format_version")
            if version in READABLE_VERSIONS:
                try:
                    return _from_v1(path, z, meta) if version == 1 else _from_v2_or_v3(path, z, meta, version, images)
                except DatasetError as e:
                    raise e if str(path) in str(e) else DatasetError(f"{path}: {e}") from e
            raise DatasetError(f"{path}: dataset format version {version!r}, this code reads "
                               f"{', '.join(map(str, READABLE_VERSIONS))}")
    except DatasetError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as e:
        raise DatasetError(f"{path} is not a tactile_manip dataset: {npz_read_problem(e)}") from e


def load_datasets(paths: list[str | Path] | tuple[str | Path, ...], *, images: bool = True) -> PairedDataset:
    """One dataset (file or shard folder), or several concatenated
    (:func:`~tactile_manip.data.dataset.concatenate`; each part's provenance then records its path).

    ``images=False``: readings and targets only (see :func:`load_dataset`), so labelled presses with and
    without images join into one dataset.

    Raises:
        DatasetError: no path, or the same file given twice (its samples would count twice).
    """
    if not paths:
        raise DatasetError("no dataset file given")
    resolved = [Path(p).resolve() for p in paths]
    twice = sorted({str(p) for p in paths if resolved.count(Path(p).resolve()) > 1})
    if twice:
        raise DatasetError(f"the same dataset is given more than once: {', '.join(twice)}")
    parts = [load_dataset(p, images=images) for p in paths]
    if len(parts) == 1:
        return parts[0]
    both = concatenate(parts)
    for part, path in zip(both.provenance["parts"], paths):
        part["path"] = str(path)
    return both


def _metadata(path: Path, entry: np.ndarray) -> dict[str, Any]:
    try:
        meta = json.loads(str(entry))
    except json.JSONDecodeError as e:
        raise DatasetError(f"{path}: metadata is not valid JSON: {e}") from e
    if not isinstance(meta, dict):
        raise DatasetError(f"{path}: metadata is not a JSON object")
    return meta


def numpy_file_kind(path: str | Path) -> str:
    """``"npy"``, ``"npz"`` (a zip archive) or ``"other"``, from the file's first bytes (nothing is unpickled)."""
    with Path(path).open("rb") as f:
        head = f.read(6)
    if head == b"\x93NUMPY":
        return "npy"
    return "npz" if head[:4] in (b"PK\x03\x04", b"PK\x05\x06") else "other"


def _from_v2_or_v3(path: Path, z: np.lib.npyio.NpzFile, meta: dict[str, Any], version: int,
                   images: bool = True) -> PairedDataset:
    names = meta.get("target_names", []) if version >= 3 else []
    with_images = version == 2 or meta.get("image") is not None
    required = ["readings", "split"] + (["images"] if with_images and (images or not names) else []) \
        + (["targets"] if names else [])
    missing = [k for k in required if k not in z.files]
    if missing:
        raise DatasetError(f"{path}: not a tactile_manip dataset, missing arrays {missing}")
    optional = {k: (z[k] if k in z.files else None) for k in ("object_index", "object_names", "groups")}
    extras = {k[len(_EXTRA):]: z[k] for k in z.files if k.startswith(_EXTRA)}
    try:
        channels = ChannelSpec.from_dict(meta["channels"])
        image = ImageSpec() if meta.get("image") is None else ImageSpec.from_dict(meta["image"])
    except (KeyError, TypeError, ValueError) as e:
        raise DatasetError(f"{path}: metadata does not describe channels and images: {e}") from e
    if not isinstance(names, list):
        raise DatasetError(f"{path}: metadata target_names is not a list of names")
    return PairedDataset(readings=z["readings"], images=z["images"] if "images" in required else None,
                         split=z["split"], channels=channels, image=image, extras=extras,
                         provenance=dict(meta.get("provenance", {})), targets=z["targets"] if names else None,
                         target_names=tuple(names), **optional)


def _from_v1(path: Path, z: np.lib.npyio.NpzFile, meta: dict[str, Any]) -> PairedDataset:
    missing = [k for k in _V1_REQUIRED if k not in z.files]
    if missing:
        raise DatasetError(f"{path}: not a tactile_manip dataset, missing arrays {missing}")
    arrays = {k: z[k] for k in _V1_REQUIRED if k != "metadata"}
    n = arrays["field_ut"].shape[0]
    bad = [k for k, a in arrays.items() if k != "object_names" and a.shape[:1] != (n,)]
    if bad:
        raise DatasetError(f"{path}: arrays {bad} do not have {n} samples like field_ut")
    image = ImageSpec(unit="mm", data_range=DEPTH_RANGE_MM, pixel_mm=float(meta.get("pixel_mm", 0.1)),
                      scale=float(meta.get("depth_scale_mm", DEPTH_SCALE_MM)))
    provenance = {k: v for k, v in meta.items() if k not in ("format_version", "depth_scale_mm", "pixel_mm",
                                                              "field_axes", "field_unit")}
    provenance["read_from_format"] = 1
    return PairedDataset(
        readings=arrays["field_ut"], images=arrays["depth_q"], split=arrays["split"],
        channels=ChannelSpec(names=tuple(meta.get("field_axes", ("x", "y", "z")))), image=image,
        object_index=arrays["object_index"], object_names=arrays["object_names"],
        extras={k: arrays[k] for k in _V1_EXTRAS}, provenance=provenance)
