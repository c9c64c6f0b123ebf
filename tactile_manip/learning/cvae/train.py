"""Training of the SuperMag CVAE: AdamW on the negative ELBO, seeded, resumable, optionally data-parallel.

Run through ``tactile-manip train`` (or ``torchrun ... -m tactile_manip train`` for DistributedDataParallel:
gloo on CPU, nccl on GPU, one GPU per process by ``LOCAL_RANK``). ``device = "auto"`` trains on the GPU when
torch sees one (the dataset split is moved there once; matrix products use TF32) and on the CPU otherwise;
shuffling, augmentation and the latent noise are drawn on the CPU from the seeded generator, so the batches
and their symmetries are the same on either device. Each epoch validates the prior-mean reconstruction (PSNR
with the fixed 2 mm data range) and writes ``checkpoint.pt`` (everything needed to resume), ``best.pt`` (best
validation PSNR), ``history.json`` and ``loss.png`` to the output folder. Early stopping ends the run when the
validation PSNR has not improved for ``patience`` epochs; a NaN or infinite loss (checked at every step), or non-finite
weights or validation output (checked before each checkpoint), stops it with a ``TrainingError`` naming the
epoch and the learning rate, and keeps the last good checkpoint. Before that, a dataset in memory without
training rows, or with NaN or infinite readings in its train or val split, is refused with a ``DatasetError``
naming it (:func:`check_training_rows`, :func:`check_finite_readings`, shared by every network's training).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from tactile_manip.config import check_ranges, config_differences, load_config, to_dict
from tactile_manip.errors import ConfigError, DatasetError, TactileManipError
from tactile_manip.learning.checkpoint import read_checkpoint
from tactile_manip.learning.cvae.data import (InputSpec, OutputSpec, StreamedData, StreamedPairs, TensorPairs,
                                              augment_batch, open_training_data, select)
from tactile_manip.learning.cvae.model import (CVAEConfig, SuperMagCVAE, count_parameters, gaussian_nll, negative_elbo,
                                               preset)
from tactile_manip.data import PairedDataset


class TrainingError(TactileManipError, RuntimeError):
    """Training cannot go on (a non-finite loss, an incompatible checkpoint)."""


# allowed ranges of the training loop's sizes (every network's): far above any shipped config, low enough that a
# typo fails at once instead of allocating gigabytes or running for weeks
SCHEDULE_RANGES = {"epochs": (1, 100_000), "batch_size": (1, 65_536), "patience": (1, 100_000)}
THREADS_RANGE = (0, 1024)   # torch CPU threads (0: torch's default)


def data_name(paths: list[str | Path] | tuple[str | Path, ...]) -> str:
    """How messages name the dataset of one or several ``--data`` paths."""
    return " + ".join(str(p) for p in paths)


def check_training_rows(data: PairedDataset, name: str) -> None:
    """Refuse (DatasetError) a dataset with no sample in its train split, saying which splits hold its rows."""
    if not np.any(data.split == "train"):
        held = sorted(set(data.split.tolist()))
        where = f"the {held[0]} split" if len(held) == 1 else f"the {' and '.join(held)} splits"
        raise DatasetError(f"no training rows: every row of {name} is in {where}; give it a train split (import "
                           "splits it by time, `--split` names one) or train on another dataset")


def check_finite_readings(data: PairedDataset, index: np.ndarray, name: str) -> None:
    """Refuse (DatasetError) NaN or infinite readings among the samples ``index`` of ``data``, naming the dataset,
    how many there are and the channel and cell of the first (a non-finite reading turns the loss NaN, or is
    clamped into a value no sensor read; targets are checked when a dataset is made)."""
    readings = data.readings[np.asarray(index)]
    bad = ~np.isfinite(readings)
    if bad.any():
        i, r, c, a = (int(v) for v in np.argwhere(bad)[0])
        samples = int(bad.reshape(len(bad), -1).any(axis=1).sum())
        raise DatasetError(f"{name}: {int(bad.sum())} NaN or infinite readings in {samples} samples (first: sample "
                           f"{int(np.asarray(index)[i])}, channel "
                           f"{data.channels.names[a]!r} of cell ({r}, {c})); drop those samples or import the data "
                           "again")


@dataclass(frozen=True)
class DecoderOverrides:
    """``[decoder]`` of a training config: decoder settings that replace the preset's (the defaults keep it)."""

    native_scale: int = 0                # the decoder works at image size / native_scale (0: keep)
    channels: list[int] = field(default_factory=list)  # feature channels per stage, coarse -> fine ([]: keep)
    dec_blocks: int = -1                 # conv blocks after each decoder stage (-1: keep)
    head: str = ""                       # "resize" / "shuffle" (CVAEConfig.head; "": keep)
    act: str = ""                        # "gelu" / "relu" in the decoder's conv blocks ("": keep)

    def __post_init__(self) -> None:
        check_ranges(self, {"native_scale": (0, 64), "dec_blocks": (-1, 16)})
        if any(isinstance(c, bool) or not isinstance(c, int) or not 1 <= c <= 4096 for c in self.channels):
            raise ConfigError(f"decoder: channels must be integers in [1, 4096], got {list(self.channels)}")

    def overrides(self) -> dict[str, Any]:
        """The CVAEConfig fields this sets (validated by CVAEConfig itself)."""
        out: dict[str, Any] = {"native_scale": self.native_scale or None, "channels": tuple(self.channels) or None,
                               "dec_blocks": None if self.dec_blocks < 0 else self.dec_blocks,
                               "head": self.head or None, "act": self.act or None}
        return {k: v for k, v in out.items() if v is not None}


@dataclass(frozen=True)
class TrainConfig:
    """Mirrors ``configs/train/*.toml``."""

    preset: str = "compact"              # architecture preset (tactile_manip.learning.cvae.model.PRESETS)
    latent: int = 0                      # override the preset's latent size (0: keep)
    norm: str = ""                       # override the preset's normalisation ("batch" / "group"; "": keep)
    decoder: DecoderOverrides = field(default_factory=DecoderOverrides)  # decoder settings over the preset's
    axes: str = "xyz"                    # "xyz", or "z" for the z-axis-only variant
    objects: list[str] = field(default_factory=list)  # train only on these objects ([]: all)
    drop_bottomed_out: bool = False      # leave out training/validation presses the data flags as through the
                                         # layer (extra "bottomed_out"; data without the flag loses nothing)
    clamp_ut: float = 500.0              # input clamp, uT (SuperMag: +-500 scaled to [-1, 1])
    clamp_std: float = 5.0               # input clamp of readings not in uT, standard deviations of the training split
    epochs: int = 60
    batch_size: int = 32                 # global batch (split across DDP processes)
    lr: float = 1e-4                     # AdamW learning rate (SuperMag: 1e-4, fixed)
    lr_schedule: Literal["constant", "cosine"] = "constant"  # cosine: decay to lr_min over the epochs
    lr_min: float = 1e-5
    weight_decay: float = 0.01
    kl_weight: float = 1.0
    nll_beta: float = 0.5                # beta-NLL weighting of the Gaussian decoder (0: plain NLL)
    prior_weight: float = 1.0            # weight of the prior-path reconstruction (hybrid CVAE objective)
    augment: bool = True                 # random symmetry of the square per batch
    patience: int = 15                   # early stopping: epochs without a better validation PSNR
    seed: int = 0
    threads: int = 0                     # torch CPU threads per process (0: torch's default)
    device: str = "auto"                 # "auto" (a GPU when torch sees one), "cpu", "cuda" or "cuda:N"
    max_minutes: float = 0.0             # stop after this wall time (0: no limit)
    shard_buffer: int = 2                # shard folders: shards shuffled together (memory grows with it)

    def __post_init__(self) -> None:
        check_ranges(self, {**SCHEDULE_RANGES, "shard_buffer": (1, 64), "latent": (0, 4096), "threads": THREADS_RANGE,
                            "max_minutes": (0.0, 60.0 * 24 * 365)}, units={"max_minutes": "min"})
        if not (math.isfinite(self.lr) and 0 < self.lr < 1):
            raise ValueError(f"lr must be in (0, 1), got {self.lr}")
        if not (math.isfinite(self.lr_min) and 0 <= self.lr_min < 1):  # the cosine schedule ends at lr_min
            raise ValueError(f"lr_min must be in [0, 1), got {self.lr_min}")
        if not (math.isfinite(self.weight_decay) and self.weight_decay >= 0):
            raise ValueError(f"weight_decay must be >= 0, got {self.weight_decay}")
        if not (math.isfinite(self.nll_beta) and 0 <= self.nll_beta <= 1):
            raise ValueError(f"nll_beta must be in [0, 1], got {self.nll_beta}")
        if not (math.isfinite(self.prior_weight) and self.prior_weight >= 0):
            raise ValueError(f"prior_weight must be >= 0, got {self.prior_weight}")
        if not (math.isfinite(self.kl_weight) and self.kl_weight >= 0):
            raise ValueError(f"kl_weight must be >= 0, got {self.kl_weight}")
        InputSpec(self.clamp_ut, self.axes, clamp_std=self.clamp_std)
        if not re.fullmatch(r"auto|cpu|cuda(:\d+)?", self.device):
            raise ValueError(f"device must be 'auto', 'cpu', 'cuda' or 'cuda:N', got {self.device!r}")


def load_train_config(path: str | Path) -> TrainConfig:
    return load_config(path, TrainConfig)


def model_config(cfg: TrainConfig, data: PairedDataset | StreamedData) -> CVAEConfig:
    """Architecture from the preset, with the taxel grid and image size read from the dataset."""
    rows, cols = data.grid
    h, w = data.image_shape
    return architecture(cfg, taxel_rows=rows, taxel_cols=cols, image_h=h, image_w=w,
                        axes=data.channels.count if cfg.axes == "xyz" else 1)


def architecture(cfg: TrainConfig, **shape: int) -> CVAEConfig:
    """The preset with the config's overrides (latent, norm, ``[decoder]``) and ``shape`` (taxel grid, channels
    seen, image size; the CVAEConfig defaults where not given)."""
    extra = {"latent": cfg.latent} if cfg.latent else {}
    if cfg.norm:
        extra["norm"] = cfg.norm
    shape.setdefault("axes", 1 if cfg.axes == "z" else 3)
    return preset(cfg.preset, **shape, **extra, **cfg.decoder.overrides())


@dataclass
class _Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @property
    def main(self) -> bool:
        return self.rank == 0


def _init_distributed() -> _Dist:
    """Join the torchrun process group when started by torchrun (WORLD_SIZE > 1)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return _Dist()
    backend = "nccl" if torch.cuda.is_available() else "gloo"
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if backend == "nccl":
        torch.cuda.set_device(local_rank)
    torch.distributed.init_process_group(backend)
    return _Dist(torch.distributed.get_rank(), world, local_rank)


def resolve_device(name: str, dist: _Dist | None = None) -> torch.device:
    """The torch device of a ``TrainConfig.device`` (under torchrun, "auto" and "cuda" mean this process's GPU)."""
    dist = dist or _Dist()
    if name == "cpu" or (name == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise TrainingError(f"device {name!r}: torch sees no CUDA GPU (torch {torch.__version__}, "
                            f"CUDA build {torch.version.cuda}); use device = \"cpu\" or \"auto\"")
    index = int(name.split(":")[1]) if ":" in name else dist.local_rank
    if index >= torch.cuda.device_count():
        raise TrainingError(f"device {name!r}: torch sees {torch.cuda.device_count()} CUDA GPU(s)")
    return torch.device("cuda", index)


def train(cfg: TrainConfig, data_path: str | Path | list[str | Path], out_dir: str | Path, *, resume: bool = False,
          init: str | Path | None = None, progress: Callable[[dict[str, float]], None] | None = None,
          on_start: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Train a model and return the run summary (also written to ``out_dir/history.json``).

    ``data_path`` is one dataset file or several, trained on as one (:func:`~tactile_manip.data.concatenate`:
    each keeps its splits).

    ``init`` (a checkpoint, e.g. the ``best.pt`` beside a shipped model) fine-tunes: the model starts from its
    weights and keeps its input normalisation (the inputs mean what they meant to those weights), with a
    fresh optimiser and ``cfg``'s schedule (a fine-tuning config has a lower ``lr`` and few epochs). The
    architecture ``cfg`` and the data give must be the checkpoint's. Not with ``resume``.

    ``progress(row)`` is called after each epoch; ``on_start(epochs_done)`` once everything is loaded and checked
    (data, model, a resumed checkpoint), just before the first epoch.
    """
    dist = _init_distributed()
    try:
        paths = [Path(p) for p in (data_path if isinstance(data_path, (list, tuple)) else [data_path])]
        return _train(cfg, paths, Path(out_dir), resume, progress, dist, on_start, init)
    finally:
        if dist.world > 1:
            torch.distributed.destroy_process_group()


def _train(cfg: TrainConfig, data_paths: list[Path], out: Path, resume: bool, progress, dist: _Dist,
           on_start=None, init: str | Path | None = None) -> dict[str, Any]:
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    device = resolve_device(cfg.device, dist)
    if device.type == "cuda":
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
    data = open_training_data(data_paths)  # in memory, or a view of shard folders streamed each epoch
    data.require_images("training the image model")
    if isinstance(data, PairedDataset):  # in memory: checked whole here (shard folders stream part by part)
        check_training_rows(data, data_name(data_paths))
        check_finite_readings(data, np.flatnonzero(np.isin(data.split, ("train", "val"))), data_name(data_paths))
    if cfg.drop_bottomed_out and not data.has("bottomed_out") and dist.main:
        dropped = data.provenance.get("dropped_extras", [])
        why = " (only some of the datasets record it)" if "bottomed_out" in dropped else ""
        print(f"note: drop_bottomed_out = true, but the data flags no press as bottomed out{why}: "
              "every press is trained on", flush=True)
    train_set, val_set, spec = _pairs(data, cfg, device)
    mcfg = model_config(cfg, data)
    model = SuperMagCVAE(mcfg)
    state = {"epoch": 0, "history": [], "best_psnr": -math.inf, "best_epoch": 0, "seconds": 0.0}
    if init is not None:
        if resume:
            raise TrainingError("--init starts a new run from a checkpoint's weights; --resume continues this "
                                "run's own checkpoint: give one of them")
        spec, state["init"] = _init_from(Path(init), model, mcfg, cfg, data)
    model = model.to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    out.mkdir(parents=True, exist_ok=True)
    if resume:
        state = _load_checkpoint(out / "checkpoint.pt", model, opt, mcfg, data, cfg)
    state["device"] = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    net = model
    if dist.world > 1:
        if torch.cuda.is_available():  # SyncBatchNorm needs a GPU; on CPU each process keeps its own statistics
            model = torch.nn.SyncBatchNorm.convert_sync_batchnorm(model)
        net = torch.nn.parallel.DistributedDataParallel(
            model, device_ids=[device.index] if device.type == "cuda" else None)
    sampler_gen = torch.Generator().manual_seed(cfg.seed)
    schedule = _schedule(cfg)
    start = time.perf_counter() - state["seconds"]
    if on_start:
        on_start(state["epoch"])
    for epoch in range(state["epoch"] + 1, cfg.epochs + 1):
        sampler_gen.manual_seed(cfg.seed * 100_003 + epoch)  # same batches for any world size and on resume
        for group in opt.param_groups:
            group["lr"] = schedule(epoch)
        deadline = start + 60 * cfg.max_minutes if cfg.max_minutes else math.inf
        train_stats = _train_epoch(net, opt, train_set, cfg, spec, dist, sampler_gen, deadline, epoch=epoch)
        val = evaluate_split(model, val_set, spec)
        state["seconds"] = time.perf_counter() - start
        row = {"epoch": epoch, "lr": schedule(epoch), **train_stats, **{f"val_{k}": v for k, v in val.items()},
               "seconds": round(state["seconds"], 1)}
        state["history"].append(row)
        state["epoch"] = epoch
        improved = val["psnr"] > state["best_psnr"]
        if improved:
            state["best_psnr"], state["best_epoch"] = val["psnr"], epoch
        # weights, BatchNorm statistics and the validation output: a model that is finite but outputs NaN
        # (overflowing variance) is as diverged as one with NaN weights, and is not saved either
        finite = all(torch.isfinite(t).all() for t in model.state_dict().values() if t.is_floating_point())
        if not (finite and math.isfinite(val["mse"])):
            what = "parameters or statistics" if not finite else f"the validation error ({val['mse']})"
            raise TrainingError(f"training diverged: {what} became NaN or infinite in epoch {epoch} "
                                f"(lr {schedule(epoch):g}); lower lr; the last good checkpoint in {out} is kept")
        if dist.main:
            _save_checkpoint(out / "checkpoint.pt", model, opt, mcfg, cfg, spec, data, state)
            if improved:
                _save_checkpoint(out / "best.pt", model, opt, mcfg, cfg, spec, data, state)
            _write_history(out, cfg, mcfg, model, data, state, dist)
        if progress:
            progress(row)
        if epoch - state["best_epoch"] >= cfg.patience:
            break
        if cfg.max_minutes and state["seconds"] > 60 * cfg.max_minutes:
            break
    return json.loads((out / "history.json").read_text()) if dist.main else {}


def _pairs(data: PairedDataset | StreamedData, cfg: TrainConfig, device: torch.device
           ) -> tuple[TensorPairs | StreamedPairs, TensorPairs | StreamedPairs, InputSpec]:
    """The training and validation splits (in memory on ``device``, or streamed from shards) and the input spec."""
    objects, drop = tuple(cfg.objects), cfg.drop_bottomed_out
    if isinstance(data, StreamedData):
        train_set = StreamedPairs(data, "train", objects, drop_bottomed_out=drop, buffer_parts=cfg.shard_buffer
                                  ).to(device)
        _check_one_batch(len(train_set), cfg)
        spec = InputSpec.for_stream(train_set, clamp_ut=cfg.clamp_ut, axes=cfg.axes, clamp_std=cfg.clamp_std)
        return train_set, StreamedPairs(data, "val", objects, drop_bottomed_out=drop).to(device), spec
    train_index = select(data, "train", objects, drop_bottomed_out=drop)
    _check_one_batch(len(train_index), cfg)
    spec = InputSpec.for_data(data, train_index, clamp_ut=cfg.clamp_ut, axes=cfg.axes, clamp_std=cfg.clamp_std)
    train_set = TensorPairs(data, train_index).to(device)
    return train_set, TensorPairs(data, select(data, "val", objects, drop_bottomed_out=drop)).to(device), spec


def _check_one_batch(samples: int, cfg: TrainConfig) -> None:
    """An epoch takes whole batches only: a training split smaller than one batch would take no step at all."""
    if samples < cfg.batch_size:
        chosen = " (of the config's objects)" if cfg.objects else ""
        raise TrainingError(f"the training split has {samples} samples{chosen}, fewer than one batch "
                            f"(batch_size = {cfg.batch_size}): collect more data, or set batch_size to at most "
                            f"{samples} in the training config")


def _schedule(cfg: TrainConfig) -> Callable[[int], float]:
    """Learning rate of each epoch (1-based)."""
    if cfg.lr_schedule == "constant":
        return lambda epoch: cfg.lr
    span = max(cfg.epochs - 1, 1)
    return lambda epoch: cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1 + math.cos(math.pi * (epoch - 1) / span))


def _train_epoch(net, opt, train_set: TensorPairs | StreamedPairs, cfg: TrainConfig, spec: InputSpec, dist: _Dist,
                 gen: torch.Generator, deadline: float = math.inf, *, epoch: int = 0) -> dict[str, float]:
    """One pass over the training set; stops early (a partial epoch) when ``deadline`` (perf_counter) passes."""
    net.train()
    net_cfg = (net.module if hasattr(net, "module") else net).cfg
    per_rank = cfg.batch_size // dist.world
    sums: dict[str, float] = {}
    n_batches = 0
    for field_ut, image in train_set.batches(cfg.batch_size, gen, rank=dist.rank, world=dist.world):
        if n_batches and time.perf_counter() > deadline:  # at least one step, so every epoch has statistics
            break
        if cfg.augment:
            field_ut, image = augment_batch(field_ut, image, gen, vector=train_set.vector)
        noise = torch.randn(cfg.batch_size, net_cfg.latent, generator=gen)[dist.rank * per_rank:][:per_rank]
        noise = noise.to(field_ut.device)
        out = net(spec.scale(field_ut), image, noise)
        loss, stats = negative_elbo(out, image, kl_weight=cfg.kl_weight, nll_beta=cfg.nll_beta)
        if cfg.prior_weight > 0:  # Sohn et al. 2015: also train the path used at inference (z = prior mean)
            module = net.module if hasattr(net, "module") else net
            prior_nll = gaussian_nll(*module.prior_mean_decode(spec.scale(field_ut)), image, cfg.nll_beta).mean()
            loss = loss + cfg.prior_weight * prior_nll
            stats["prior_nll"] = float(prior_nll.detach())
        if not torch.isfinite(loss):  # before the step and before this epoch's checkpoint
            lr = opt.param_groups[0]["lr"]
            raise TrainingError(f"training diverged: the loss became {float(loss.detach())} (NaN or infinite) in "
                                f"epoch {epoch}, step {n_batches + 1} (lr {lr:g}); lower lr or check the data; "
                                "no checkpoint of this epoch is written, earlier ones are kept")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1e4)
        opt.step()
        for k, v in stats.items():
            sums[k] = sums.get(k, 0.0) + v
        n_batches += 1
    stats = {k: v / max(n_batches, 1) for k, v in sums.items()}
    stats["batches"] = n_batches
    stats["epoch_fraction"] = n_batches / max(train_set.batch_count(cfg.batch_size), 1)
    return stats


@torch.no_grad()
def evaluate_split(model: SuperMagCVAE, pairs: TensorPairs | StreamedPairs, spec: InputSpec, *, batch: int = 128
                   ) -> dict[str, float]:
    """Prior-mean reconstruction of a split: MSE (target units squared) and mean PSNR (dB, the images' range)."""
    model.eval()
    se, psnrs = [], []
    for field_ut, image in pairs.chunks(batch):
        eps = torch.zeros(len(field_ut), 1, model.cfg.latent, device=field_ut.device)
        mean, _ = model.generate(spec.scale(field_ut), eps)
        mse = ((mean - image) ** 2).flatten(1).mean(1)
        se.append(mse)
        psnrs.append(10 * torch.log10(pairs.data_range**2 / mse.clamp_min(1e-12)))
    return {"mse": float(torch.cat(se).mean()), "psnr": float(torch.cat(psnrs).mean())}


def _save_checkpoint(path: Path, model, opt, mcfg: CVAEConfig, cfg: TrainConfig, spec: InputSpec,
                     data: PairedDataset | StreamedData, state: dict) -> None:
    payload = {"model": model.state_dict(), "optimizer": opt.state_dict(), "model_config": to_dict(mcfg),
               "train_config": to_dict(cfg), "input": to_dict(spec), "output": to_dict(OutputSpec.for_data(data)),
               "data": data.describe(), "data_fingerprint": data.fingerprint(),
               "state": state}
    tmp = path.with_name(path.name + ".partial")
    torch.save(payload, tmp)
    tmp.replace(path)


def _load_checkpoint(path: Path, model, opt, mcfg: CVAEConfig, data: PairedDataset | StreamedData,
                     cfg: TrainConfig) -> dict:
    if not path.is_file():
        raise TrainingError(f"--resume: no checkpoint at {path}")
    payload = read_checkpoint(path)
    differences = config_differences(payload["model_config"], to_dict(mcfg))
    if differences:
        raise TrainingError(f"--resume: {path} was trained with another architecture or dataset shape "
                            f"({'; '.join(differences)}); use the same config or start a new output folder")
    if payload.get("data_fingerprint", data.fingerprint()) != data.fingerprint():
        raise TrainingError(f"--resume: {path} was trained on data with fingerprint {payload['data_fingerprint']}, "
                            f"the --data given now has {data.fingerprint()} (other files, or another order); "
                            "resume with the same --data, in the same order")
    selection = ("objects", "drop_bottomed_out", "axes")
    before = payload.get("train_config", {})
    changed = [f"{k}: {before[k]!r} -> {getattr(cfg, k)!r}" for k in selection
               if k in before and before[k] != getattr(cfg, k)]
    if changed:
        raise TrainingError(f"--resume: the config selects other samples or inputs than {path} was trained on "
                            f"({'; '.join(changed)}); use the same config or start a new output folder")
    model.load_state_dict(payload["model"])
    opt.load_state_dict(payload["optimizer"])
    return payload["state"]


def _init_from(path: Path, model, mcfg: CVAEConfig, cfg: TrainConfig,
               data: PairedDataset | StreamedData) -> tuple[InputSpec, dict[str, Any]]:
    """Load ``path``'s weights into ``model`` for fine-tuning; its input normalisation, and what to record."""
    payload = read_checkpoint(path)
    differences = config_differences(payload["model_config"], to_dict(mcfg))
    if differences:
        raise TrainingError(f"--init: {path} has another architecture or dataset shape than this config and data "
                            f"({'; '.join(differences)}); fine-tune with the config the checkpoint was trained "
                            "with (its train_config) on data of the same reading and image shapes")
    spec = InputSpec(**payload["input"])
    if spec.axes != cfg.axes:
        raise TrainingError(f"--init: {path} reads the axes {spec.axes!r}, the config {cfg.axes!r}")
    output = to_dict(OutputSpec.for_data(data))
    if payload.get("output", output) != output:  # the decoder's outputs would mean other image values
        raise TrainingError(f"--init: {path} was trained on images scaled as {payload['output']}, the --data "
                            f"given now scales them as {output} (another image unit or range)")
    model.load_state_dict(payload["model"])
    state = payload.get("state", {})
    return spec, {"checkpoint": str(path), "data_fingerprint": payload.get("data_fingerprint"),
                  "epochs": state.get("epoch"), "best_val_psnr": state.get("best_psnr")}


def _write_history(out: Path, cfg: TrainConfig, mcfg: CVAEConfig, model, data: PairedDataset | StreamedData,
                   state: dict, dist: _Dist) -> None:
    summary = {"train_config": to_dict(cfg), "model_config": to_dict(mcfg),
               "parameters": count_parameters(model),
               "inference_parameters": count_parameters(model, inference_only=True),
               "data_fingerprint": data.fingerprint(), "world_size": dist.world,
               "threads": torch.get_num_threads(), "device": state.get("device", "cpu"),
               "best_val_psnr": state["best_psnr"],
               "best_epoch": state["best_epoch"], "epochs_run": state["epoch"], "init": state.get("init"),
               "train_seconds": round(state["seconds"], 1), "history": state["history"]}
    (out / "history.json").write_text(json.dumps(summary, indent=1))
    _plot_losses(out / "loss.png", state["history"])


def _plot_losses(path: Path, history: list[dict]) -> None:
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    epochs = [r["epoch"] for r in history]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    a.plot(epochs, [r["loss"] for r in history], label="train -ELBO")
    a.set_xlabel("epoch")
    a.set_ylabel("negative ELBO per image")
    a.set_yscale("symlog")
    a.legend()
    b.plot(epochs, [r["val_psnr"] for r in history], color="C1", label="validation PSNR (prior mean)")
    b.set_xlabel("epoch")
    b.set_ylabel("PSNR [dB], range 2 mm")
    b.legend()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def with_overrides(cfg: TrainConfig, **changes: Any) -> TrainConfig:
    """``cfg`` with the non-None ``changes`` applied (CLI flags)."""
    return dataclasses.replace(cfg, **{k: v for k, v in changes.items() if v is not None})
