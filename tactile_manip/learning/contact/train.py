"""Training of the contact network (:mod:`.model`) on labelled presses, seeded, with early stopping.

Run through ``tactile-manip train --config configs/train/contact.toml --data D.npz --out RUN``. The samples of
the dataset's ``train`` split train; its ``val`` split validates, or, when it has none, the last
``val_fraction`` of each run's training samples in time order (never the test split). Inputs and targets are
standardised with the training samples' statistics, stored with the weights. Each ensemble member trains
with its own seed on the Gaussian NLL per target (with ``nll_beta`` > 0 the beta-NLL of Seitzer et al. 2022:
the NLL weighted by the predicted variance to the power beta), AdamW and a one-cycle learning rate, and keeps
the weights of its best validation epoch (RMSE of the standardised targets); once the learning rate has
begun to fall, it stops after ``patience`` epochs without improvement (while the rate still rises the
validation error may stall without the run being done). Last, the mixture's sigma is scaled per target so
that 68.3 % of the validation errors fall within one sigma (``calibrate_sigma``): the members' variance heads
and their disagreement are otherwise too wide or too narrow by a factor that depends on the data. Then
(``sigma_map``) a non-decreasing map of that sigma makes it hold wherever the sigma lies, not only on the
validation samples' mix (:class:`~tactile_manip.perception.confidence.SigmaCalibration`, the isotonic fit the
pose estimator's confidence calibration uses); the export carries it and the runtime applies it.

A dataset without training rows, or with a NaN or infinite reading anywhere (any row may be another's
context), is refused before training with a ``DatasetError`` naming it.

``RUN/best.pt`` holds the mixture of the members with everything the export needs; ``RUN/history.json`` each
member's curve and the validation RMSE per target of the mixture.
"""

from __future__ import annotations

import functools
import json
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from tactile_manip.boards.identity import record_of_provenance
from tactile_manip.config import check_ranges, to_dict
from tactile_manip.data import PairedDataset, load_datasets
from tactile_manip.data.dataset import UNLABELLED
from tactile_manip.errors import ConfigError, DatasetError
from tactile_manip.learning.contact.model import (ContactModel, ContactModelConfig, GaussianMLP, count_parameters,
                                                  frame_features)
from tactile_manip.learning.noise import ChipNoise
from tactile_manip.learning.schedule import check_schedule, optimise_step
from tactile_manip.learning.threads import limited_threads
from tactile_manip.learning.cvae.train import THREADS_RANGE, check_finite_readings, check_training_rows, data_name
from tactile_manip.perception.confidence import ONE_SIGMA, SigmaCalibration
from tactile_manip.perception.contact_context import context_windows

KIND = "contact"
WARMUP_FRACTION = 0.3  # share of the one-cycle schedule over which the learning rate rises


@dataclass(frozen=True)
class ContactTrainConfig:
    """Mirrors ``configs/train/contact.toml``."""

    kind: Literal["contact"] = "contact"
    targets: list[str] = field(default_factory=list)  # targets learnt ([]: all of the dataset's)
    context_frames: int = 3       # frames per input: the reading and the ones before it
    context_max_gap_s: float = 1.0  # an older frame further back than this is no context (s)
    features: Literal["field", "field_direction"] = "field_direction"
    hidden: int = 128             # units per hidden layer
    layers: int = 3               # hidden layers
    act: Literal["gelu", "relu", "silu"] = "gelu"
    members: int = 5              # ensemble members (independent seeds)
    epochs: int = 300             # per member
    batch_size: int = 128
    lr: float = 2e-3              # peak of the one-cycle schedule
    weight_decay: float = 1e-4    # AdamW
    nll_beta: float = 0.0         # beta-NLL exponent (0: plain Gaussian NLL)
    val_fraction: float = 0.1     # validation tail of each run's training samples when the data has no val split
    patience: int = 60            # epochs without a better validation RMSE before a member stops (counted once
                                  # the learning rate falls)
    calibrate_sigma: bool = True  # scale sigma so that 68.3 % of validation errors are within one sigma
    sigma_map: bool = True        # then map it so that holds wherever the sigma lies (needs 80+ val samples)
    redraw_noise: bool = False    # each epoch reads the training presses through new chip drift and noise
                                  # (simulated datasets, one frame of context: tactile_manip.learning.noise)
    unlabelled: Literal["ignore", "manifold", "twin"] = "ignore"  # the dataset's unlabelled training presses: left
                                  # out, labelled from the labelled ones (.fewlabel), or from the twin's simulated
                                  # presses (train --prior) corrected by the labelled ones (.twin_prior)
    manifold_neighbours: int = 20  # neighbours per reading in that map
    twin_neighbours: int = 8      # the twin's presses whose targets place a reading
    twin_norm_weight: float = 0.5  # weight of the log field norm beside the field's direction in that search
    twin_refine: bool = True      # the twin's places refitted on a smooth model of the real field; with labels,
                                  # they then start the few-label recipe's refit beside its maps (.twin_prior)
    label_recency: float = 0.0    # the fit of the field norm weighs a labelled press by e ** (this x the share of
                                  # its run elapsed before it): later presses count more where the skin drifts
    seed: int = 0
    threads: int = 0              # CPU threads of torch and of numpy's BLAS each (0: each library's default)

    def __post_init__(self) -> None:
        check_schedule(self)
        if not 0 <= self.nll_beta <= 1:
            raise ValueError(f"nll_beta must be in [0, 1], got {self.nll_beta}")
        if not 0 < self.val_fraction < 1:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        check_ranges(self, {"context_max_gap_s": (0.0, 3600.0), "threads": THREADS_RANGE,
                            "manifold_neighbours": (3, 200), "label_recency": (0.0, 10.0),
                            "twin_neighbours": (1, 200), "twin_norm_weight": (0.0, 100.0)},
                     units={"context_max_gap_s": "s"})
        if self.redraw_noise and self.context_frames != 1:
            raise ValueError(f"redraw_noise draws the noise of one frame; it needs context_frames = 1, got "
                             f"{self.context_frames}")
        self.model_config((3, 3, 3), 1)  # the architecture fields, checked by ContactModelConfig

    def model_config(self, cells: tuple[int, int, int], targets: int) -> ContactModelConfig:
        return ContactModelConfig(cells=tuple(cells), targets=targets, context_frames=self.context_frames,
                                  features=self.features, hidden=self.hidden, layers=self.layers, act=self.act,
                                  members=self.members)


def load_contact_config(path: str | Path) -> ContactTrainConfig:
    from tactile_manip.config import load_config

    return load_config(path, ContactTrainConfig)


def dataset_windows(data: PairedDataset, cfg: ContactTrainConfig | dict) -> np.ndarray:
    """Input windows (N, T, R, C, A) of every sample, with the context settings of ``cfg`` (a config or the
    ``context`` record of a checkpoint)."""
    frames = cfg["frames"] if isinstance(cfg, dict) else cfg.context_frames
    gap = cfg["max_gap_s"] if isinstance(cfg, dict) else cfg.context_max_gap_s
    time_s = data.extra("time_s") if data.has("time_s") else None
    return context_windows(data.readings, frames=frames, max_gap_s=gap, time_s=time_s, groups=data.groups)


def split_indices(data: PairedDataset, val_fraction: float, *, unlabelled: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Training and validation sample indices: the val split, or each run's last training samples in time
    (``unlabelled``: the unlabelled training presses count as training samples)."""
    train, val = data.indices("train"), data.indices("val")
    if unlabelled:
        train = np.sort(np.concatenate([train, data.indices(UNLABELLED)]))
    if len(val):
        return train, val
    groups = np.zeros(len(data), np.int64) if data.groups is None else data.groups
    t = data.extra("time_s") if data.has("time_s") else np.arange(len(data), dtype=np.float64)
    keep, hold = [], []
    for g in np.unique(groups[train]):
        rows = train[groups[train] == g]
        rows = rows[np.argsort(t[rows], kind="stable")]
        n_val = max(1, int(round(val_fraction * len(rows))))
        keep.append(rows[:-n_val])
        hold.append(rows[-n_val:])
    return np.sort(np.concatenate(keep)), np.sort(np.concatenate(hold))


def chosen_targets(data: PairedDataset, cfg: ContactTrainConfig) -> list[str]:
    if not data.has_targets:
        raise DatasetError("the contact model learns per-sample targets; this dataset holds images only: import "
                           "labelled presses (`tactile-manip import --labels-csv ...`) or simulate with targets")
    names = cfg.targets or list(data.target_names)
    unknown = [n for n in names if n not in data.target_names]
    if unknown:
        raise ConfigError(f"targets {unknown} are not in the dataset; it has {list(data.target_names)}")
    return names


def train_contact(cfg: ContactTrainConfig, data_paths: list[str | Path], out: str | Path, *,
                  progress: Callable[[dict[str, Any]], None] | None = None,
                  on_start: Callable[[int], None] | None = None,
                  stages: Callable[..., Any] | None = None, prior: str | Path | None = None) -> dict[str, Any]:
    """Train, write ``out/best.pt`` and ``out/history.json``, and return the summary.

    ``on_start(total_epochs)`` is called once the data are loaded and checked and the unlabelled presses
    labelled; ``progress(row)`` after every epoch of every member (``row``: member, epoch, loss, val_rmse);
    ``stages`` makes the labeller's progress displays (``pseudo_labels``). ``prior``: a dataset of the twin's
    simulated presses (``unlabelled = "twin"``, which needs it; with the twin, a dataset whose training presses are
    all unlabelled trains on the twin's labels alone). Torch and numpy's BLAS run on ``cfg.threads`` threads
    (:func:`~tactile_manip.learning.threads.limited_threads`). The summary's ``train_seconds`` is the network's
    training alone; ``pseudo_labels["seconds"]`` the labelling's.
    """
    if (cfg.unlabelled == "twin") != (prior is not None):
        raise ConfigError('unlabelled = "twin" labels the presses from the twin\'s simulated presses: give them with '
                          '--prior TWIN.npz (tactile-manip simulate --board fitted.toml), and --prior only with it')
    with limited_threads(cfg.threads):
        return _train_contact(cfg, data_paths, out, progress=progress, on_start=on_start, stages=stages, prior=prior)


def _train_contact(cfg: ContactTrainConfig, data_paths: list[str | Path], out: str | Path, *,
                   progress: Callable[[dict[str, Any]], None] | None,
                   on_start: Callable[[int], None] | None,
                   stages: Callable[..., Any] | None, prior: str | Path | None) -> dict[str, Any]:
    data = load_datasets([Path(p) for p in data_paths], images=False)
    names = chosen_targets(data, cfg)
    if not (cfg.unlabelled == "twin" and len(data.indices(UNLABELLED))):
        check_training_rows(data, data_name(data_paths))
    check_finite_readings(data, np.arange(len(data)), data_name(data_paths))  # any row may be a context frame
    labels = np.stack([data.target(n) for n in names], axis=1)
    labelling = cfg.unlabelled != "ignore" and len(data.indices(UNLABELLED)) > 0
    train_idx, val_idx = split_indices(data, cfg.val_fraction, unlabelled=labelling)
    if cfg.calibrate_sigma and len(val_idx) < MIN_SIGMA_SAMPLES:  # said before the labelling and the training
        warnings.warn(f"{data_name(data_paths)}: sigma is calibrated on {len(val_idx)} validation sample(s), fewer "
                      f"than {MIN_SIGMA_SAMPLES}: a 68.3 % quantile of so few errors says little, so the sigmas may "
                      "not hold their promise; give more validation presses (import --val-fraction, or a larger "
                      "val_fraction), or set calibrate_sigma = false", UserWarning, stacklevel=2)
    windows = dataset_windows(data, cfg)
    pseudo = None
    if labelling:
        pseudo = (_twin_labels(data, labels, names, cfg, windows, Path(prior), stages) if prior is not None
                  else _pseudo_labels(data, labels, names, cfg, windows, stages))
    if len(train_idx) < 2:
        raise DatasetError(f"{len(train_idx)} training sample(s): too few to train on")
    windows = torch.from_numpy(windows)
    targets = torch.from_numpy(labels.astype(np.float32))
    mcfg = cfg.model_config(tuple(data.readings.shape[1:]), len(names))
    torch.manual_seed(cfg.seed)
    model = ContactModel(mcfg)
    with torch.no_grad():
        model.set_normalisation(frame_features(windows[train_idx], mcfg), targets[train_idx])
        z = model.standardised_features(windows)
        y = (targets - model.target_offset) / model.target_scale
    noise = ChipNoise.of(data, train_idx) if cfg.redraw_noise else None
    if on_start:
        on_start(cfg.members * cfg.epochs)
    start = time.perf_counter()
    curves = []

    @torch.no_grad()
    def fresh(rng: np.random.Generator) -> torch.Tensor:  # the training presses' features through new chips
        return model.standardised_features(torch.from_numpy(noise.draw(rng))[:, None])

    for m in range(cfg.members):
        seed = cfg.seed * 1000 + m
        redraw = None if noise is None else functools.partial(fresh, np.random.default_rng(seed))
        member, curve = _train_member(cfg, mcfg, z, y, train_idx, val_idx, seed=seed, fresh=redraw,
                                      progress=(lambda row, m=m: progress({"member": m, **row})) if progress else None)
        model.members[m].load_state_dict(member.state_dict())
        curves.append(curve)
    model.eval()
    sigma_maps: dict[str, dict[str, Any]] = {}
    val_rmse = _rmse_per_target(model, windows[val_idx], targets[val_idx], names)
    if cfg.calibrate_sigma:
        fit_sigma_scale(model, windows[val_idx], targets[val_idx])
        if pseudo is not None and np.isfinite(pseudo["loo_rmse"]).all():
            # validated against labels of the map or the twin: widened by those labels' own error
            wider = widening(val_rmse, pseudo["loo_rmse"], names)
            model.sigma_scale.mul_(torch.tensor(wider, dtype=torch.float32))
        elif cfg.sigma_map and len(val_idx) >= 2 * SIGMA_MAP_RUN:
            sigma_maps = fit_sigma_maps(model, windows[val_idx], targets[val_idx], names)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"kind": KIND, "train_config": to_dict(cfg), "model_config": to_dict(mcfg), "targets": names,
               "sigma_scale": model.sigma_scale.tolist(), "sigma_calibration": sigma_maps,
               "parameters": count_parameters(model), "train_samples": int(len(train_idx)),
               "val_samples": int(len(val_idx)), "val_rmse": val_rmse,
               "best_epochs": [c["best_epoch"] for c in curves], "train_seconds": round(time.perf_counter() - start, 1),
               "data_fingerprint": data.fingerprint(), "members": curves, "pseudo_labels": pseudo}
    payload = {"kind": KIND, "model": model.state_dict(), "model_config": to_dict(mcfg), "train_config": to_dict(cfg),
               "input": _input_record(data, cfg), "targets": names, "sigma_calibration": sigma_maps,
               "data": {"fingerprint": data.fingerprint(), "samples": len(data), "provenance_source":
                        data.provenance.get("source"), "val_rmse": val_rmse, "pseudo_labels": pseudo}}
    if prior is not None:
        summary["prior"] = payload["data"]["prior"] = pseudo["prior"] if pseudo else {"path": str(prior)}
    tmp = out / "best.pt.partial"
    torch.save(payload, tmp)
    tmp.replace(out / "best.pt")
    (out / "history.json").write_text(json.dumps(summary, indent=1))
    return summary


def _pseudo_labels(data: PairedDataset, labels: np.ndarray, names: list[str], cfg: ContactTrainConfig,
                   windows: np.ndarray, stages: Callable[..., Any] | None = None) -> dict[str, Any] | None:
    """Fill ``labels`` (N, K) of the targets ``names`` in place on the unlabelled training presses from the
    labelled ones (:func:`~tactile_manip.learning.contact.fewlabel.pseudo_labels`, given the oldest frame of each
    press's ``windows`` as its earlier reading, and, with ``label_recency`` above 0 and the presses' times, the
    labelled presses weighed by :func:`~tactile_manip.learning.contact.fewlabel.recency_weights` per run; each
    stage shown by ``stages``); what was done, or None where nothing is unlabelled."""
    from tactile_manip.learning.contact.fewlabel import pseudo_labels

    if not len(data.indices(UNLABELLED)):
        return None
    return _label_unlabelled(data, labels, cfg, windows, lambda readings, known, labelled, earlier, weights: (
        pseudo_labels(readings, known, labelled, neighbours=cfg.manifold_neighbours, earlier=earlier, names=names,
                      weights=weights, stages=stages)))


def _twin_labels(data: PairedDataset, labels: np.ndarray, names: list[str], cfg: ContactTrainConfig,
                 windows: np.ndarray, prior: Path, stages: Callable[..., Any] | None = None) -> dict[str, Any]:
    """As :func:`_pseudo_labels`, the unlabelled training presses labelled from the twin's simulated presses in
    the dataset at ``prior`` (:func:`~tactile_manip.learning.contact.twin_prior.twin_labels`), corrected by the
    labelled ones; refuses a prior of another reading layout or board than the data's."""
    from tactile_manip.boards.identity import check_same_board
    from tactile_manip.data import load_dataset
    from tactile_manip.learning.contact.twin_prior import check_bank_targets, twin_labels

    check_bank_targets(names)
    bank = load_dataset(prior, images=False)
    if bank.readings.shape[1:] != data.readings.shape[1:]:
        raise DatasetError(f"--prior {prior} holds {bank.readings.shape[1:]} readings, the data "
                           f"{data.readings.shape[1:]}: simulate the twin on the board the presses were imported with")
    check_same_board(f"--prior {prior}", record_of_provenance(bank.provenance), "the training data",
                     record_of_provenance(data.provenance))
    bank_targets = np.stack([bank.target(n) for n in bank.target_names], axis=1)
    done = _label_unlabelled(data, labels, cfg, windows, lambda readings, known, labelled, earlier, weights: (
        twin_labels(readings, known, labelled, bank_readings=bank.readings, bank_targets=bank_targets, names=names,
                    bank_names=list(bank.target_names), earlier=earlier, weights=weights,
                    neighbours=cfg.twin_neighbours, norm_weight=cfg.twin_norm_weight, refine=cfg.twin_refine,
                    map_neighbours=cfg.manifold_neighbours, stages=stages)))
    done["prior"] = {"path": str(prior), "presses": len(bank), "fingerprint": bank.fingerprint(),
                     "board": record_of_provenance(bank.provenance)}
    return done


def _label_unlabelled(data: PairedDataset, labels: np.ndarray, cfg: ContactTrainConfig, windows: np.ndarray,
                      labeller: Callable[..., Any]) -> dict[str, Any]:
    """The training and unlabelled rows handed to ``labeller(readings, labels, labelled, earlier, weights)``
    (each press's oldest frame as its earlier reading where windows hold more than one; recency weights per run
    where ``label_recency`` is above 0 and the presses have times); its values written into ``labels`` in place,
    and what was done, with the labelling's seconds."""
    from tactile_manip.learning.contact.fewlabel import recency_weights

    hidden = data.indices(UNLABELLED)
    rows = np.sort(np.concatenate([data.indices("train"), hidden]))
    labelled = np.isin(rows, data.indices("train"))
    weights = None
    if cfg.label_recency > 0 and data.has("time_s"):
        weights = recency_weights(data.extra("time_s")[rows], cfg.label_recency,
                                  None if data.groups is None else data.groups[rows])
    start = time.perf_counter()
    found = labeller(data.readings[rows], labels[rows], labelled,
                     windows[rows, -1] if windows.shape[1] > 1 else None, weights)
    labels[rows] = found.values
    return {"labelled": int(labelled.sum()), "unlabelled": int(len(hidden)),
            "loo_rmse": [float(v) for v in found.loo_rmse], "methods": list(found.methods),
            "seconds": round(time.perf_counter() - start, 1)}


def widening(val_rmse: dict[str, float], loo_rmse: list[float], names: list[str]) -> list[float]:
    """Per target, the factor that takes an error against map labels to one against the truth, the two errors
    taken as independent: sqrt(1 + (label error / network error)^2)."""
    return [math.sqrt(1.0 + (loo / max(val_rmse[n], 1e-12)) ** 2) for n, loo in zip(names, loo_rmse)]


def _input_record(data: PairedDataset, cfg: ContactTrainConfig) -> dict[str, Any]:
    """What the model reads: shape, channels, board layout, and the stream's frame period for the context."""
    period = None
    if data.has("time_s") and len(data) > 1:
        steps = np.diff(np.sort(data.extra("time_s")))
        period = float(np.median(steps[steps > 0])) if (steps > 0).any() else None
    board = record_of_provenance(data.provenance)
    return {"cells": list(data.readings.shape[1:]), "channels": to_dict(data.channels),
            "layout": data.provenance.get("layout", "supermag-4x4" if data.grid == (4, 4) else
                                          f"grid-{data.grid[0]}x{data.grid[1]}"),
            **({"board": board} if board is not None else {}),
            "context": {"frames": cfg.context_frames, "max_gap_s": cfg.context_max_gap_s,
                        "frame_period_s": period}}


def _train_member(cfg: ContactTrainConfig, mcfg: ContactModelConfig, z: torch.Tensor, y: torch.Tensor,
                  train_idx: np.ndarray, val_idx: np.ndarray, *, seed: int,
                  progress: Callable[[dict[str, Any]], None] | None,
                  fresh: Callable[[], torch.Tensor] | None = None) -> tuple[GaussianMLP, dict[str, Any]]:
    """One member, trained on standardised features ``z`` (N, F) and targets ``y`` (N, K); its best weights.
    ``fresh()``, where given, returns the training samples' features read through new chip noise, each epoch."""
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    net = GaussianMLP(mcfg)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    xt, yt = z[train_idx], y[train_idx]
    xv, yv = z[val_idx], y[val_idx]
    steps_per_epoch = math.ceil(len(xt) / cfg.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=cfg.epochs * steps_per_epoch,
                                                pct_start=WARMUP_FRACTION)
    peak_epoch = math.ceil(WARMUP_FRACTION * cfg.epochs)
    best = {"val_rmse": math.inf, "best_epoch": 0, "state": None}
    history = []
    for epoch in range(1, cfg.epochs + 1):
        if fresh is not None:
            xt = fresh()
        net.train()
        order = torch.randperm(len(xt), generator=gen)
        total = 0.0
        for b in range(0, len(xt), cfg.batch_size):
            i = order[b:b + cfg.batch_size]
            mean, log_var = net(xt[i])
            loss = beta_nll(mean, log_var, yt[i], cfg.nll_beta)
            total += optimise_step(loss, opt, sched, epoch, hint="lower lr or check the targets") * len(i)
        net.eval()
        with torch.no_grad():
            val = float(((net(xv)[0] - yv) ** 2).sum(1).mean().sqrt())
        row = {"epoch": epoch, "loss": total / len(xt), "val_rmse": val}
        history.append(row)
        if progress:
            progress(row)
        if val < best["val_rmse"]:
            best = {"val_rmse": val, "best_epoch": epoch, "state": {k: v.clone() for k, v in net.state_dict().items()}}
        elif epoch - max(best["best_epoch"], peak_epoch) >= cfg.patience:
            break
    net.load_state_dict(best["state"])
    return net, {"seed": seed, "best_epoch": best["best_epoch"], "epochs_run": len(history),
                 "best_val_rmse_std": best["val_rmse"], "history": history}


def beta_nll(mean: torch.Tensor, log_var: torch.Tensor, target: torch.Tensor, beta: float) -> torch.Tensor:
    """Mean beta-NLL of Gaussians (mean, log variance) at ``target``, all (B, K)."""
    nll = 0.5 * (log_var + (mean - target) ** 2 / log_var.exp())
    if beta:
        nll = nll * log_var.exp().detach() ** beta
    return nll.mean()


@torch.no_grad()
def fit_sigma_scale(model: ContactModel, windows: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Set ``model.sigma_scale`` (K,) so that a share :data:`ONE_SIGMA` of the errors on ``windows`` (N, T, R,
    C, A) against ``targets`` (N, K) fall within one sigma, per target; returns it."""
    model.sigma_scale.fill_(1.0)
    mean, sigma = model(windows)
    z = (mean - targets).abs() / sigma.clamp_min(1e-12)         # (N, K)
    scale = torch.quantile(z, ONE_SIGMA, dim=0).clamp_min(1e-6)
    model.sigma_scale.copy_(scale)
    return scale


SIGMA_MAP_RUN = 40      # validation samples per knot of a sigma map
MIN_SIGMA_SAMPLES = 20  # fewest validation samples whose errors calibrate sigma (5 % steps of the quantile)


@torch.no_grad()
def fit_sigma_maps(model: ContactModel, windows: torch.Tensor, targets: torch.Tensor, names: list[str]
                   ) -> dict[str, dict[str, Any]]:
    """Per target, the :class:`~tactile_manip.perception.confidence.SigmaCalibration` of the model's sigma on
    ``windows`` against ``targets`` (runs of :data:`SIGMA_MAP_RUN`), as dicts by target name."""
    mean, sigma = model(windows)
    err = (mean - targets).abs().numpy()
    return {n: SigmaCalibration.fit(sigma[:, k].numpy(), err[:, k], min_per_knot=SIGMA_MAP_RUN).to_dict()
            for k, n in enumerate(names)}


@torch.no_grad()
def _rmse_per_target(model: ContactModel, windows: torch.Tensor, targets: torch.Tensor,
                     names: list[str]) -> dict[str, float]:
    mean, _ = model(windows)
    return {n: float(((mean[:, k] - targets[:, k]) ** 2).mean().sqrt()) for k, n in enumerate(names)}
