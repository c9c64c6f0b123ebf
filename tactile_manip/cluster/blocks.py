"""Finished blocks of a distributed run, kept on disk so that a restarted run does only what is left.

A run's blocks live in ``<output>.blocks/`` beside the output: ``run.json`` (what the blocks belong to: a key
over the config, and the block size) and one ``block-<start>-<stop>.npz`` per finished block, written to a
temporary name and renamed, so a block file is whole or absent. A restart with another config or block size
refuses the folder rather than mix samples of two runs. The folder is removed once the output is written.

A block's results are the per-sample dicts of :func:`tactile_manip.sim.dataset.simulate_block` (arrays, numbers,
flags and one level of named numbers); they are stored as stacked arrays, without pickle.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.errors import ClusterError

_KEYS = "__keys__/"   # the key order of a nested dict (e.g. a drawn sensor's parameters), as a string array
_ORDER = "__order__"  # the results' key order
_NONE = "__none__"    # keys whose value is None in every result (e.g. no image in a targets-only dataset)


def blocks_folder(output: str | Path) -> Path:
    """Where the finished blocks of the run that writes ``output`` are kept."""
    return Path(str(output) + ".blocks")


def run_key(config: dict[str, Any], block_size: int) -> str:
    """A short hash identifying what a run's blocks are blocks of."""
    text = json.dumps({"config": config, "block_size": block_size}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class BlockStore:
    """The ``<output>.blocks/`` folder of one run (see the module docstring)."""

    def __init__(self, output: str | Path, key: str) -> None:
        self.folder = blocks_folder(output)
        self.key = key

    def open(self) -> dict[int, int]:
        """The finished blocks (start -> stop) after checking that an existing folder is this run's."""
        meta = self.folder / "run.json"
        if not self.folder.exists():
            return {}
        try:
            stored = json.loads(meta.read_text()).get("key")
        except (OSError, ValueError, AttributeError) as e:
            raise ClusterError(f"{self.folder} is not a block folder of a run ({e}); remove it") from e
        if stored != self.key:
            raise ClusterError(f"{self.folder} holds blocks of another config or block size; remove it, or "
                               "run the same command as before to finish that run")
        done = {}
        for f in self.folder.glob("block-*.npz"):
            start, stop = (int(x) for x in f.stem.split("-")[1:3])
            done[start] = stop
        return done

    def path(self, start: int, stop: int) -> Path:
        return self.folder / f"block-{start:09d}-{stop:09d}.npz"

    def save(self, start: int, stop: int, results: list[dict[str, Any]]) -> None:
        if not self.folder.exists():
            self.folder.mkdir(parents=True)
            (self.folder / "run.json").write_text(json.dumps({"key": self.key}))
        tmp = self.folder / f".block-{start:09d}.partial"
        with tmp.open("wb") as f:
            np.savez(f, **_stack(results))
        tmp.replace(self.path(start, stop))

    def load(self, start: int, stop: int) -> list[dict[str, Any]]:
        path = self.path(start, stop)
        try:
            with np.load(path, allow_pickle=False) as z:
                results = _unstack({k: z[k] for k in z.files})
        except (OSError, ValueError) as e:
            raise ClusterError(f"cannot read the finished block {path} ({e}); delete it to simulate it again") from e
        if len(results) != stop - start:
            raise ClusterError(f"{path} holds {len(results)} samples, expected {stop - start}; delete it")
        return results



def remove_blocks(output: str | Path) -> None:
    """Delete the finished blocks of the run that wrote ``output`` (once the output is safely written)."""
    shutil.rmtree(blocks_folder(output), ignore_errors=True)


def _stack(results: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    arrays: dict[str, np.ndarray] = {}
    none = [k for k in results[0] if all(r[k] is None for r in results)]
    arrays[_NONE] = np.array(none, dtype=str)
    arrays[_ORDER] = np.array(list(results[0]), dtype=str)
    for key, value in results[0].items():
        if key in none:
            continue
        if isinstance(value, dict):
            names = list(value)
            arrays[_KEYS + key] = np.array(names, dtype=str)
            arrays[key] = np.array([[r[key][n] for n in names] for r in results])
        else:
            arrays[key] = np.array([r[key] for r in results])
    return arrays


def _unstack(arrays: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    nested = {k[len(_KEYS):]: [str(n) for n in v] for k, v in arrays.items() if k.startswith(_KEYS)}
    none = [str(k) for k in arrays.get(_NONE, [])]
    plain = {k: v for k, v in arrays.items() if not k.startswith(_KEYS) and k not in (_NONE, _ORDER)}
    order = [str(k) for k in arrays[_ORDER]]
    count = len(next(iter(plain.values())))
    out: list[dict[str, Any]] = []
    for i in range(count):
        row: dict[str, Any] = {}
        for key, a in plain.items():
            row[key] = dict(zip(nested[key], a[i].tolist())) if key in nested else a[i]
        row.update(dict.fromkeys(none))
        out.append({k: row[k] for k in order})
    return out
