"""Generate a paired dataset from a config: presses of named objects at random poses, in parallel.

Each press is stored with its magnetic reading, its depth image (unless ``images = false``) and its targets
(:data:`SIM_TARGETS`): the centre of pressure of the contact patch on the magnetic skin (``x_mm``, ``y_mm``,
pad frame; where the pressure acts, not the object's origin), the skin's indentation depth (``depth_mm``,
the rigid approach into it), the normal force (``force_n``) and ``in_contact``; a press that misses the pad
has 0 for all of them. Extras beside them include the contact area (``contact_area_mm2``) and the centroid of
the contact patch, unweighted by pressure (``contact_centroid_mm``, (N, 2) mm, pad frame), and the reading
without drift, noise and quantisation (``field_clean_ut``, (N, rows, cols, 3) uT), from which training can draw
the chips' noise afresh (``redraw_noise`` of the angle head).

The magnetic sensor is the config's ``board`` (default ``supermag-4x4``, whose readings are (4, 4, 3)); the
dataset's readings have that board's grid and its provenance names it (``layout``).

Every sample ``i`` draws everything (pose, force, optional parameter randomisation, sensor noise) from
``np.random.default_rng([seed, i])``, and results are assembled in index order, so the output does not
depend on the number of worker processes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from tactile_manip.boards import DEFAULT_BOARD, Board, load_board
from tactile_manip.config import from_dict, load_config, to_dict
from tactile_manip.data import PairedDataset, ShardWriter, depth_image_spec, quantise_depth
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.shapes import SHAPES, check_shape_arguments, make_indenter
from tactile_manip.sim.pair import PairedSample, SensorPair
from tactile_manip.sim.params import SimParams, for_board, randomise, randomised_values
from tactile_manip.version import code_version


@dataclass(frozen=True)
class ObjectSpec:
    """One object family of a dataset."""

    name: str                                   # registry name (see tactile_manip.sim.shapes.SHAPES)
    count: int                                  # number of presses
    split: Literal["trainval", "test"] = "trainval"
    label: str = ""                             # name stored in the dataset (default: name)
    kwargs: dict[str, Any] = field(default_factory=dict)  # shape arguments, e.g. {size_mm = 3.0}
    variants: int = 1                           # >1: cycle kwargs["seed"] over this many shapes

    def __post_init__(self) -> None:
        if self.count < 0:
            raise ValueError(f"objects.count must be >= 0, got {self.count}")
        if self.variants < 1:
            raise ValueError(f"objects.variants must be >= 1, got {self.variants}")
        if self.name not in SHAPES:
            raise ValueError(f"objects.name: unknown object {self.name!r}; known: {', '.join(sorted(SHAPES))}")
        check_shape_arguments(self.name, {"seed": 0, **self.kwargs} if self.variants > 1 else self.kwargs,
                              where="objects.kwargs")

    @property
    def display_name(self) -> str:
        return self.label or self.name


@dataclass(frozen=True)
class PoseRanges:
    """Where presses land: uniform offsets, yaw, small tilt and force."""

    offset_mm: float = 5.0                      # x and y uniform in [-offset, offset], mm
    yaw_deg: tuple[float, float] = (-180.0, 180.0)
    tilt_deg: float = 2.0                       # each tilt uniform in [-tilt, tilt], deg
    force_n: tuple[float, float] = (10.0, 11.0)  # 10 N threshold plus up to 1 N overshoot

    def __post_init__(self) -> None:
        if not (math.isfinite(self.offset_mm) and self.offset_mm >= 0):
            raise ValueError(f"poses.offset_mm must be finite and >= 0, got {self.offset_mm}")
        if not 0 <= self.tilt_deg <= 20:
            raise ValueError(f"poses.tilt_deg must be in [0, 20], got {self.tilt_deg}")
        lo, hi = self.force_n
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"poses.force_n must be 0 < low <= high, got {self.force_n}")
        if not all(math.isfinite(v) for v in self.yaw_deg) or not self.yaw_deg[0] <= self.yaw_deg[1]:
            raise ValueError(f"poses.yaw_deg must be [low, high] with low <= high, got {self.yaw_deg}")


@dataclass(frozen=True)
class DatasetConfig:
    """A whole dataset: mirrors ``configs/dataset/*.toml``."""

    seed: int = 0                     # base of the per-sample seeds
    board: str = DEFAULT_BOARD        # the magnetic sensor's board: a shipped name or a board file (simulatable)
    sensor_seed: int = 0              # per-sensor constants (Earth field, chip misalignment)
    validation_fraction: float = 0.1  # of each trainval object, the last fraction goes to 'val'
    randomise_spread: float = 0.0     # 0: one fixed sensor pair; 1: full domain randomisation per sample
    bottomed_out: Literal["keep", "redraw"] = "keep"  # a press through the layer: keep it (flagged), or draw
                                      # the sample's pose, force and sensor again (up to MAX_REDRAWS times)
    images: bool = True               # render depth images; false: targets only (contact models need none)
    poses: PoseRanges = field(default_factory=PoseRanges)
    objects: list[ObjectSpec] = field(default_factory=list)
    sim: SimParams = field(default_factory=SimParams)

    def __post_init__(self) -> None:
        if not 0 <= self.validation_fraction < 1:
            raise ValueError(f"validation_fraction must be in [0, 1), got {self.validation_fraction}")
        if not 0 <= self.randomise_spread <= 1:
            raise ValueError(f"randomise_spread must be in [0, 1], got {self.randomise_spread}")
        if not self.objects:
            raise ValueError("objects: a dataset needs at least one [[objects]] entry")
        if self.bottomed_out not in ("keep", "redraw"):
            raise ValueError(f"bottomed_out must be 'keep' or 'redraw', got {self.bottomed_out!r}")
        board = self.sensor_board()
        board.require_simulation()
        half_pad_mm = min(board.layer.size_mm) / 2.0
        if self.poses.offset_mm > half_pad_mm:
            raise ValueError(f"poses.offset_mm = {self.poses.offset_mm:g} puts object centres off the "
                             f"{min(board.layer.size_mm):g} mm pad (empty presses); it must be <= {half_pad_mm:g}")

    def sensor_board(self) -> Board:
        """The board named by ``board`` (ConfigError naming it when unknown or a bad file)."""
        return load_board(self.board)

    def scaled(self, factor: float) -> DatasetConfig:
        """The same dataset with every object count multiplied by ``factor``: at least 1 for an object that had
        presses, and still 0 for one that had none (``count = 0`` switches an object off at any scale)."""
        objs = [dataclasses.replace(o, count=max(1, int(round(o.count * factor))) if o.count else 0)
                for o in self.objects]
        return dataclasses.replace(self, objects=objs)


def load_dataset_config(path: str | Path) -> DatasetConfig:
    """Parse a dataset TOML file (raises :class:`~tactile_manip.errors.ConfigError`)."""
    return load_config(path, DatasetConfig)


# the SuperMag pad's geometry, which [sim] held before the board file stated it (datasets made then record it)
_BOARD_KEYS = {"layer": ("size_mm", "thickness_mm"), "chip": ("pitch_mm",)}


def recorded_sim_params(config: dict[str, Any], *, where: str = "the dataset's provenance") -> SimParams:
    """The simulator's parameters a dataset's provenance ``config`` recorded, the board's figures filled in.

    A dataset made before the board file stated the pad's geometry records it under ``[sim]``
    (``layer.size_mm``, ``layer.thickness_mm``, ``chip.pitch_mm``: the SuperMag pad's); those keys are left out.

    Raises:
        ConfigError: a config that is not a dataset config (the message names ``where``).
    """
    config = dict(config)
    sim = {group: dict(values) for group, values in config.get("sim", {}).items()}
    for group, keys in _BOARD_KEYS.items():
        for key in keys:
            sim.get(group, {}).pop(key, None)
    cfg = from_dict(DatasetConfig, {**config, "sim": sim}, where=where)
    return for_board(cfg.sensor_board(), cfg.sim)


@dataclass(frozen=True)
class _Task:
    index: int
    spec: int
    variant: int


def _tasks(cfg: DatasetConfig) -> list[_Task]:
    tasks: list[_Task] = []
    for s, spec in enumerate(cfg.objects):
        tasks += [_Task(len(tasks) + i, s, i % spec.variants) for i in range(spec.count)]
    return tasks


def _splits(cfg: DatasetConfig) -> np.ndarray:
    """Split label per sample: trainval objects end with a validation tail, test objects are 'test'."""
    out = []
    for spec in cfg.objects:
        if spec.split == "test":
            out += ["test"] * spec.count
        else:
            n_train = int(math.floor(spec.count * (1.0 - cfg.validation_fraction)))
            out += ["train"] * n_train + ["val"] * (spec.count - n_train)
    return np.array(out, dtype="U5")


SIM_TARGETS = ("x_mm", "y_mm", "depth_mm", "force_n", "in_contact")
_WORKER: dict[str, Any] = {}
MAX_REDRAWS = 20   # bottomed_out = "redraw": draws per sample before a press through the layer is kept (flagged)


def _init_worker(cfg: DatasetConfig) -> None:
    _WORKER.clear()
    _WORKER["cfg"] = cfg
    _WORKER["board"] = board = cfg.sensor_board()
    _WORKER["sim"] = for_board(board, cfg.sim)
    _WORKER["pair"] = SensorPair(cfg.sim, board=board, seed=cfg.sensor_seed)
    _WORKER["objects"] = {}


def _indenter(spec: ObjectSpec, variant: int) -> Indenter:
    key = (spec.name, repr(sorted(spec.kwargs.items())), variant)
    cache = _WORKER["objects"]
    if key not in cache:
        kwargs = dict(spec.kwargs)
        if spec.variants > 1:
            kwargs["seed"] = int(kwargs.get("seed", 0)) + variant
        cache[key] = make_indenter(spec.name, **kwargs)
    return cache[key]


def _simulate(task: _Task) -> dict[str, Any]:
    cfg: DatasetConfig = _WORKER["cfg"]
    rng = np.random.default_rng([cfg.seed, task.index])
    pr = cfg.poses
    for _ in range(MAX_REDRAWS + 1):  # one pass unless bottomed_out = "redraw" meets a press through the layer
        pose = IndenterPose(
            x_mm=rng.uniform(-pr.offset_mm, pr.offset_mm), y_mm=rng.uniform(-pr.offset_mm, pr.offset_mm),
            yaw_rad=math.radians(rng.uniform(*pr.yaw_deg)),
            tilt_x_rad=math.radians(rng.uniform(-pr.tilt_deg, pr.tilt_deg)),
            tilt_y_rad=math.radians(rng.uniform(-pr.tilt_deg, pr.tilt_deg)))
        force = rng.uniform(*pr.force_n)
        pair, drawn = _WORKER["pair"], {}
        if cfg.randomise_spread > 0:
            params = randomise(_WORKER["sim"], rng, spread=cfg.randomise_spread)
            pair = SensorPair(params, board=_WORKER["board"], seed=cfg.sensor_seed)
            drawn = {"sensor_params": randomised_values(params)}
        s = pair.press(_indenter(cfg.objects[task.spec], task.variant), pose, force, rng, render_depth=cfg.images)
        if not (s.bottomed_out and cfg.bottomed_out == "redraw"):
            break
    return {**drawn, "bottomed_out": s.bottomed_out, "field_ut": s.field_ut, "field_raw_ut": s.field_raw_ut,
            "field_clean_ut": s.field_clean_ut, "saturated": s.saturated,
            "depth_q": None if s.depth_mm is None else quantise_depth(s.depth_mm),
            "pose": [pose.x_mm, pose.y_mm, pose.yaw_rad, pose.tilt_x_rad, pose.tilt_y_rad],
            "force_n": s.force_n, "approach_mm": s.approach_mm, "skin_approach_mm": s.skin_approach_mm,
            "contact": s.contact, "targets": sample_targets(s), "contact_area_mm2": s.pressure.area_mm2,
            "contact_centroid_mm": s.pressure.area_centroid_mm}


def sample_targets(s: PairedSample) -> list[float]:
    """The :data:`SIM_TARGETS` of one press: centre of pressure on the magnetic skin (mm, pad frame), its
    indentation depth (mm), normal force (N) and the contact flag; zeros for a press that misses the pad.

    A press that bottoms out (``bottomed_out``) indents the skin by its whole thickness, where the rigid base
    stops it: its depth is that thickness, not the elastic model's extrapolation past it (which reaches tens
    of millimetres on narrow shapes).
    """
    if not (s.contact and s.pressure.area_mm2 > 0):
        return [0.0, 0.0, 0.0, 0.0, 0.0]
    x, y = s.pressure.centroid_mm
    return [x, y, min(s.skin_approach_mm, s.board.layer.thickness_mm), s.force_n, 1.0]


def generate(cfg: DatasetConfig, *, workers: int = 0,
             progress: Callable[[int], None] | None = None) -> PairedDataset:
    """Simulate every sample of ``cfg``; ``workers=0`` uses all cores, 1 runs in this process.

    ``progress`` is called with the number of samples finished since the last call.
    """
    tasks = _tasks(cfg)
    workers = workers or os.cpu_count() or 1
    start = time.perf_counter()
    results = list(_results(cfg, tasks, workers, progress))
    return _assemble(cfg, tasks, results, seconds=time.perf_counter() - start, workers=workers)


def _results(cfg: DatasetConfig, tasks: list[_Task], workers: int,
             progress: Callable[[int], None] | None) -> Iterator[dict[str, Any]]:
    """Each task's result in task order, as the workers finish them."""
    if workers == 1:
        _init_worker(cfg)
        for t in tasks:
            yield _simulate(t)
            progress and progress(1)
        return
    chunk = max(1, min(16, len(tasks) // (4 * workers) or 1))
    ctx = multiprocessing.get_context("spawn")
    with _single_threaded_children(), ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=_init_worker, initargs=(cfg,)) as pool:
        for r in pool.map(_simulate, tasks, chunksize=chunk):
            yield r
            progress and progress(1)


def sample_count(cfg: DatasetConfig) -> int:
    """Number of samples ``cfg`` generates (sample indices run 0 .. count - 1)."""
    return sum(o.count for o in cfg.objects)


def simulate_block(cfg: DatasetConfig, start: int, stop: int) -> list[dict[str, Any]]:
    """Simulate samples ``start .. stop - 1`` of ``cfg`` in this process: the unit of work of a distributed run.

    Each sample draws from its own seed, so a block gives the same values in any process and in any order;
    :func:`assemble` turns the blocks' results, concatenated in index order, into the dataset.
    """
    if _WORKER.get("cfg") != cfg:
        _init_worker(cfg)
    return [_simulate(t) for t in _tasks(cfg)[start:stop]]


def assemble(cfg: DatasetConfig, results: list[dict[str, Any]], *, seconds: float, workers: int) -> PairedDataset:
    """The dataset of every sample's result in index order (what :func:`generate` returns for the same cfg)."""
    tasks = _tasks(cfg)
    if len(results) != len(tasks):
        raise ValueError(f"assemble: {len(results)} results for a config of {len(tasks)} samples")
    return _assemble(cfg, tasks, results, seconds=seconds, workers=workers)


@contextlib.contextmanager
def _single_threaded_children():
    """One BLAS/OpenMP thread per worker: the workers already fill the cores, and threads would fight."""
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {k: os.environ.get(k) for k in names}
    os.environ.update({k: "1" for k in names})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _assemble(cfg: DatasetConfig, tasks: list[_Task], results: list[dict[str, Any]], *, seconds: float,
              workers: int) -> PairedDataset:
    def stack(key: str, dtype: Any) -> np.ndarray:
        return np.asarray([r[key] for r in results], dtype=dtype)

    names = [o.display_name for o in cfg.objects]
    unique = list(dict.fromkeys(names))
    provenance = {"source": "tactile-manip simulate", "config": to_dict(cfg), "layout": cfg.sensor_board().name,
                  "board": cfg.sensor_board().record, "code_version": code_version(),
                  "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  "generation_seconds": round(seconds, 2), "workers": workers}
    extras = {"field_raw_ut": stack("field_raw_ut", np.float32),
              "field_clean_ut": stack("field_clean_ut", np.float32), "saturated": stack("saturated", bool),
              "pose": stack("pose", np.float32), "force_n": stack("force_n", np.float32),
              "approach_mm": stack("approach_mm", np.float32),
              "skin_approach_mm": stack("skin_approach_mm", np.float32), "contact": stack("contact", bool),
              "bottomed_out": stack("bottomed_out", bool), "contact_area_mm2": stack("contact_area_mm2", np.float32),
              "contact_centroid_mm": stack("contact_centroid_mm", np.float32)}
    if cfg.randomise_spread > 0:  # each press on its own drawn sensor: record the draw (names in provenance)
        provenance["sensor_param_names"] = list(results[0]["sensor_params"])
        extras["sensor_params"] = np.array([list(r["sensor_params"].values()) for r in results], np.float32)
    return PairedDataset(
        readings=stack("field_ut", np.float32), images=stack("depth_q", np.uint8) if cfg.images else None,
        split=_splits(cfg)[[t.index for t in tasks]], image=depth_image_spec(cfg.sim.vbts.pixel_mm),
        targets=stack("targets", np.float32),
        target_names=SIM_TARGETS,
        object_index=np.array([unique.index(names[t.spec]) for t in tasks], dtype=np.int16),
        object_names=np.array(unique), extras=extras, provenance=provenance)


def generate_shards(cfg: DatasetConfig, path: str | Path, *, shard_size: int, workers: int = 0,
                    progress: Callable[[int], None] | None = None, force: bool = False) -> Path:
    """Simulate every sample of ``cfg`` into the shard folder ``path`` (:mod:`tactile_manip.data.shards`).

    Shards are written in sample order as their samples finish, so at most one shard's results are held here
    (plus what the workers finished ahead of it); the samples, and the fingerprint, equal :func:`generate`'s.
    The folder appears under ``path`` only when complete (``force`` replaces one that is there).
    """
    tasks = _tasks(cfg)
    workers = workers or os.cpu_count() or 1
    start = time.perf_counter()
    with ShardWriter(path, shard_size=shard_size, force=force) as writer:
        block: list[dict[str, Any]] = []
        provenance: dict[str, Any] = {}
        for r in _results(cfg, tasks, workers, progress):
            block.append(r)
            if len(block) == shard_size or len(writer.entries) * shard_size + len(block) == len(tasks):
                first = len(writer.entries) * shard_size
                shard = _assemble(cfg, tasks[first:first + len(block)], block,
                                  seconds=time.perf_counter() - start, workers=workers)
                writer.write(shard)
                block, provenance = [], shard.provenance
        return writer.finish(dict(provenance, generation_seconds=round(time.perf_counter() - start, 2)))
