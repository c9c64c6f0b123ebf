"""A dataset stored as shards: a folder of ordinary dataset files plus ``manifest.json``.

Layout of a shard folder ``D/``:

- ``shard-00000.npz``, ``shard-00001.npz``, ...: each a dataset file (:func:`~tactile_manip.data.io.save_dataset`)
  of at most the shard size, in sample order; every shard carries the whole dataset's object names, so
  ``object_index`` and ``groups`` mean the same in every shard;
- ``manifest.json``: ``{"format": "tactile_manip.shards", "format_version": 1, "samples": N, "splits": {...},
  "fingerprint": "...", "shards": [{"file", "samples", "splits", "fingerprint"}, ...], "provenance": {...}}``.

The manifest's fingerprint equals :meth:`~tactile_manip.data.dataset.PairedDataset.fingerprint` of the same
samples as one file: it hashes the same bytes, each array of every shard in turn, so it is computed with one
shard's array in memory at a time. A folder is written under a temporary name beside ``D`` and renamed when
its manifest is complete: no partial dataset is ever under the final name.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.data.dataset import FINGERPRINT_ARRAYS, SPLITS, PairedDataset, fingerprint_bytes
from tactile_manip.errors import DatasetError

MANIFEST = "manifest.json"
SHARD_FORMAT = "tactile_manip.shards"
SHARD_FORMAT_VERSION = 1
_SHARD_NAME = "shard-{:05d}.npz"


def is_shard_folder(path: str | Path) -> bool:
    """Whether ``path`` is a folder holding a shard manifest."""
    return (Path(path) / MANIFEST).is_file()


def split_counts(data: PairedDataset) -> dict[str, int]:
    """Samples per split of ``data``."""
    return {s: int(np.count_nonzero(data.split == s)) for s in SPLITS}


class ShardWriter:
    """Writes shards in sample order into a temporary folder and renames it to ``path`` on :meth:`finish`.

    Use it as a context manager: leaving the block without :meth:`finish` (an exception, an interrupt) removes
    the temporary folder, so nothing is left under ``path``. ``force`` replaces an existing ``path`` only once
    the new folder is complete.
    """

    def __init__(self, path: str | Path, *, shard_size: int, force: bool = False) -> None:
        if shard_size < 1:
            raise ValueError(f"--shard-size must be >= 1, got {shard_size}")
        self.path = Path(path)
        self.shard_size = shard_size
        self.force = force
        self.tmp = self.path.with_name(f".{self.path.name}.partial-{os.getpid()}")
        self.entries: list[dict[str, Any]] = []
        self.schema: tuple = ()

    def __enter__(self) -> ShardWriter:
        if (self.path.exists() or self.path.is_symlink()) and not self.force:
            raise DatasetError(f"{self.path} exists; pass --force to replace it")
        shutil.rmtree(self.tmp, ignore_errors=True)  # left by a killed run of this process id
        self.tmp.mkdir(parents=True)
        return self

    def __exit__(self, *exc: object) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)

    def write(self, data: PairedDataset) -> None:
        """Append ``data`` (the next samples, at most ``shard_size``) as one shard."""
        from tactile_manip.data.io import save_dataset

        if not 0 < len(data) <= self.shard_size:
            raise ValueError(f"a shard holds 1 to {self.shard_size} samples, got {len(data)}")
        if not self.entries:
            self.schema = _schema(data)
        elif _schema(data) != self.schema:  # the shards are joined as they are: they must mean the same
            raise DatasetError(f"shard {len(self.entries)} differs from shard 0 in its channels, image spec, "
                               f"shapes, targets, object names or extras: {_schema(data)} != {self.schema}")
        name = _SHARD_NAME.format(len(self.entries))
        save_dataset(self.tmp / name, data)
        self.entries.append({"file": name, "samples": len(data), "splits": split_counts(data),
                             "fingerprint": data.fingerprint()})

    def write_all(self, data: PairedDataset) -> None:
        """Append every sample of ``data`` as shards of ``shard_size`` (the last may be smaller)."""
        for start in range(0, len(data), self.shard_size):
            self.write(data.subset(np.arange(start, min(start + self.shard_size, len(data)))))

    def finish(self, provenance: dict[str, Any]) -> Path:
        """Write the manifest (with the whole dataset's fingerprint) and rename the folder to ``path``."""
        if not self.entries:
            raise DatasetError("a sharded dataset needs at least one sample")
        files = [self.tmp / e["file"] for e in self.entries]
        manifest = {"format": SHARD_FORMAT, "format_version": SHARD_FORMAT_VERSION,
                    "samples": sum(e["samples"] for e in self.entries),
                    "splits": {s: sum(e["splits"][s] for e in self.entries) for s in SPLITS},
                    "fingerprint": streamed_fingerprint(files), "shards": self.entries, "provenance": provenance}
        (self.tmp / MANIFEST).write_text(json.dumps(manifest, indent=1))
        old = self.path.with_name(f".{self.path.name}.replaced-{os.getpid()}")
        # force: the old dataset goes only once the new one is complete
        if self.path.exists() or self.path.is_symlink():
            self.path.rename(old)
        self.tmp.rename(self.path)
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)
        elif old.exists() or old.is_symlink():
            old.unlink()
        return self.path


def _schema(data: PairedDataset) -> tuple:
    """What every shard of one dataset shares: specs, per-sample shapes, targets, object names, extras."""
    names = None if data.object_names is None else tuple(data.object_names.tolist())
    return (data.channels, data.image if data.has_images else None, data.readings.shape[1:],
            None if data.images is None else data.images.shape[1:], data.target_names, names,
            data.groups is not None, tuple(sorted((k, v.shape[1:]) for k, v in data.extras.items())))


def save_sharded(path: str | Path, data: PairedDataset, *, shard_size: int, force: bool = False) -> Path:
    """Write ``data`` to the folder ``path`` as shards of ``shard_size`` samples and a manifest, atomically."""
    with ShardWriter(path, shard_size=shard_size, force=force) as writer:
        writer.write_all(data)
        return writer.finish(data.provenance)


def streamed_fingerprint(files: list[Path]) -> str:
    """The fingerprint of the shard files' samples as one dataset, one array of one shard in memory at a time."""
    h = hashlib.sha256()
    names: tuple[str, ...] | None = None
    for name in FINGERPRINT_ARRAYS:
        for path in files:
            with _npz(path) as z:
                if name in z.files:
                    h.update(fingerprint_bytes(name, z[name]))
                if name == "targets" and name in z.files and names is None:
                    names = tuple(json.loads(str(z["metadata"])).get("target_names", []))
    if names is not None:
        h.update(fingerprint_bytes("target_names", names))
    return h.hexdigest()[:16]


class ShardedDataset:
    """A shard folder, read lazily: the manifest at once, a shard when asked for.

    Opening checks that every shard the manifest names is there and that no shard file is there that it does
    not name; loading a shard checks its sample count and fingerprint. Each failure is a DatasetError that
    names the shard.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.manifest = _read_manifest(self.path)
        self.entries: list[dict[str, Any]] = self.manifest["shards"]
        named = {e["file"] for e in self.entries}
        missing = [e["file"] for e in self.entries if not (self.path / e["file"]).is_file()]
        if missing:
            raise DatasetError(f"{self.path}: shard {missing[0]} named in {MANIFEST} is missing"
                               + (f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""))
        unnamed = sorted(p.name for p in self.path.glob("shard-*.npz") if p.name not in named)
        if unnamed:
            raise DatasetError(f"{self.path}: shard {unnamed[0]} is not in {MANIFEST} (a folder mixed from two "
                               "runs?); write the dataset again")

    def __len__(self) -> int:
        return int(self.manifest["samples"])

    @property
    def shard_count(self) -> int:
        return len(self.entries)

    @property
    def splits(self) -> dict[str, int]:
        """Samples per split, from the manifest."""
        return {s: int(self.manifest["splits"].get(s, 0)) for s in SPLITS}

    @property
    def provenance(self) -> dict[str, Any]:
        return dict(self.manifest.get("provenance", {}))

    def fingerprint(self) -> str:
        """The whole dataset's fingerprint, as recorded in the manifest (the same as the one-file form's)."""
        return str(self.manifest["fingerprint"])

    def shard_splits(self, i: int) -> dict[str, int]:
        """Samples per split of shard ``i``, from the manifest."""
        return {s: int(self.entries[i]["splits"].get(s, 0)) for s in SPLITS}

    def load_shard(self, i: int, *, verify: bool = True) -> PairedDataset:
        """Shard ``i`` as a dataset; ``verify`` checks its fingerprint against the manifest's."""
        from tactile_manip.data.io import load_dataset

        entry = self.entries[i]
        data = load_dataset(self.path / entry["file"])
        if len(data) != entry["samples"]:
            raise DatasetError(f"{self.path}: shard {entry['file']} holds {len(data)} samples, {MANIFEST} says "
                               f"{entry['samples']}")
        if verify and data.fingerprint() != entry["fingerprint"]:
            raise DatasetError(f"{self.path}: shard {entry['file']} has fingerprint {data.fingerprint()}, "
                               f"{MANIFEST} says {entry['fingerprint']} (the file was changed or replaced)")
        return data

    def __iter__(self) -> Iterator[PairedDataset]:
        return (self.load_shard(i) for i in range(self.shard_count))

    def column(self, name: str) -> np.ndarray:
        """One per-sample array of every shard, joined (``split``, ``object_index``, an extra's name...): reads
        only that array of each shard."""
        key = name if name in ("readings", "images", "split", "targets", "object_index", "groups") else f"extra__{name}"
        parts = []
        for e in self.entries:
            with _npz(self.path / e["file"]) as z:
                if key not in z.files:
                    raise DatasetError(f"{self.path}: shard {e['file']} has no {name!r}")
                parts.append(z[key])
        return np.concatenate(parts)

    def has(self, name: str) -> bool:
        """Whether the shards store the per-sample extra ``name`` (asked of the first shard)."""
        with _npz(self.path / self.entries[0]["file"]) as z:
            return f"extra__{name}" in z.files

    def extra(self, name: str) -> np.ndarray:
        """The per-sample extra ``name`` of every shard, joined."""
        return self.column(name)

    def load(self) -> PairedDataset:
        """Every shard joined into one dataset in memory (arrays and fingerprint equal the one-file form's)."""
        data = join_shards([self.load_shard(i) for i in range(self.shard_count)], self.provenance)
        if data.fingerprint() != self.fingerprint():
            raise DatasetError(f"{self.path}: the shards' fingerprint {data.fingerprint()} is not the manifest's "
                               f"{self.fingerprint()}")
        return data


def iter_shards(path: str | Path) -> Iterator[PairedDataset]:
    """The shards of the folder ``path`` in order, each loaded (and checked) when reached."""
    return iter(ShardedDataset(path))


def join_shards(shards: list[PairedDataset], provenance: dict[str, Any]) -> PairedDataset:
    """Shards of one dataset joined in order: arrays concatenated as they are (object names and groups are the
    whole dataset's in every shard, so nothing is renumbered, unlike :func:`~tactile_manip.data.concatenate`)."""
    first = shards[0]

    def joined(name: str) -> np.ndarray | None:
        return None if getattr(first, name) is None else np.concatenate([getattr(d, name) for d in shards])

    extras = {k: np.concatenate([d.extras[k] for d in shards]) for k in first.extras}
    return PairedDataset(readings=joined("readings"), images=joined("images"), split=joined("split"),
                         channels=first.channels, image=first.image, object_index=joined("object_index"),
                         object_names=first.object_names, groups=joined("groups"), extras=extras,
                         provenance=provenance, targets=joined("targets"), target_names=first.target_names)


def _read_manifest(path: Path) -> dict[str, Any]:
    try:
        manifest = json.loads((path / MANIFEST).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: cannot read {MANIFEST}: {e}") from e
    if not isinstance(manifest, dict) or manifest.get("format") != SHARD_FORMAT:
        raise DatasetError(f"{path}: {MANIFEST} is not a tactile_manip shard manifest")
    if manifest.get("format_version") != SHARD_FORMAT_VERSION:
        raise DatasetError(f"{path}: shard format version {manifest.get('format_version')!r}, this code reads "
                           f"{SHARD_FORMAT_VERSION}")
    shards = manifest.get("shards")
    if not isinstance(shards, list) or not shards or not all(
            isinstance(e, dict) and {"file", "samples", "fingerprint", "splits"} <= set(e) for e in shards):
        raise DatasetError(f"{path}: {MANIFEST} lists no shards, or shards without file, samples, splits and "
                           "fingerprint")
    if sum(e["samples"] for e in shards) != manifest.get("samples"):
        raise DatasetError(f"{path}: {MANIFEST} says {manifest.get('samples')} samples, its shards hold "
                           f"{sum(e['samples'] for e in shards)}")
    return manifest


@contextlib.contextmanager
def _npz(path: Path) -> Iterator[np.lib.npyio.NpzFile]:
    """A shard opened for reading single arrays; an unreadable one is a DatasetError naming it."""
    from tactile_manip.checks import npz_read_problem

    try:
        with np.load(path, allow_pickle=False) as z:
            yield z
    except DatasetError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as e:
        raise DatasetError(f"{path.parent}: shard {path.name} cannot be read: {npz_read_problem(e)}") from e
