"""Training of the angle head (:mod:`.model`) on simulated presses, seeded, with early stopping.

Run through ``tactile-manip train --config configs/train/angle_head.toml --data data/bars.npz data/robust.npz
--out RUN``. Labels (:func:`axis_labels`): a press of an object with a straight axis (a rod, bar, flat bar,
procedural bar or ridge, named by its dataset label) is labelled with that axis, the pose's yaw; any other
press of a dataset with images is labelled with the principal axis of its true depth image (what the image
route would find on a perfect reconstruction), and left out where that axis is undefined. The head learns how
sure to be from the labels themselves: a round contact's image axis is noise, so the likelihood teaches a
small concentration there.

Each epoch shows every training reading under a random symmetry of the board (a quarter turn adds 90 deg to
the axis, a mirror negates it), so the head never favours a direction the board does not; with
``redraw_noise``, through new chip drift and noise as well (:mod:`tactile_manip.learning.noise`), so the head
cannot learn one draw of them. AdamW with a one-cycle learning rate; the weights of the epoch with the lowest
validation negative log-likelihood are kept, and a run stops ``patience`` epochs after its best once the rate
falls.
``RUN/best.pt`` holds the weights and everything the export needs; ``RUN/history.json`` the per-epoch curve
and the validation figures.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from tactile_manip.config import check_ranges, load_config, to_dict
from tactile_manip.data import PairedDataset, load_dataset
from tactile_manip.errors import DatasetError
from tactile_manip.learning.angle_head.model import (AngleHead, AngleModelConfig, count_parameters, reading_features,
                                                     von_mises_nll)
from tactile_manip.learning.noise import ChipNoise
from tactile_manip.learning.schedule import check_schedule, optimise_step
from tactile_manip.learning.cvae.train import THREADS_RANGE, check_finite_readings
from tactile_manip.evaluation.images import ELONGATED
from tactile_manip.perception.pose import angle_from_image, wrap_axial
from tactile_manip.perception.symmetry import transform_reading

KIND = "angle_head"
WARMUP_FRACTION = 0.3
#: dataset labels (prefixes) of objects whose contact has a straight axis along the object's local x
AXIAL_PREFIXES = (*ELONGATED, "procedural_bar", "procedural_prism", "ridge")
SYMMETRIES = tuple((k, m) for m in (False, True) for k in range(4))


@dataclass(frozen=True)
class AngleTrainConfig:
    """Mirrors ``configs/train/angle_head.toml``."""

    kind: Literal["angle_head"] = "angle_head"
    hidden: int = 256             # units per hidden layer
    layers: int = 3               # hidden layers
    act: Literal["gelu", "relu", "silu"] = "gelu"
    epochs: int = 150
    batch_size: int = 256
    lr: float = 2e-3              # peak of the one-cycle schedule
    weight_decay: float = 1e-4    # AdamW
    symmetry: bool = True         # a random symmetry of the board per reading and epoch
    image_labels: bool = True     # label presses of other objects with the axis of their true image
    redraw_noise: bool = False    # each epoch reads the training presses through new chip drift and noise
    patience: int = 40            # epochs without a better validation NLL (counted once the rate falls)
    seed: int = 0
    threads: int = 0              # torch CPU threads (0: torch's default)

    def __post_init__(self) -> None:
        check_schedule(self)
        check_ranges(self, {"hidden": (1, 4096), "layers": (1, 16), "threads": THREADS_RANGE})
        self.model_config((4, 4, 3))

    def model_config(self, cells: tuple[int, int, int]) -> AngleModelConfig:
        return AngleModelConfig(cells=tuple(cells), hidden=self.hidden, layers=self.layers, act=self.act)


def load_angle_config(path: str | Path) -> AngleTrainConfig:
    return load_config(path, AngleTrainConfig)


def is_axial(label: str) -> bool:
    """Whether presses of the object ``label`` are labelled with its axis (see :data:`AXIAL_PREFIXES`)."""
    return any(str(label).startswith(p) for p in AXIAL_PREFIXES)


def axis_labels(data: PairedDataset, idx: np.ndarray, *, image_labels: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The presses of ``idx`` with a known axis: their indices, axis angles (rad, (-pi/2, pi/2]) and whether
    each is an axial object's (True) or an image's principal axis (False). See the module docstring."""
    idx = np.asarray(idx, dtype=np.int64)
    if not data.has("pose"):
        raise DatasetError("the angle head learns from presses with a known pose ('pose' per sample); this "
                           "dataset has none: simulate it with `tactile-manip simulate`")
    axial = np.array([is_axial(n) for n in data.objects(idx)], dtype=bool)
    keep, angle = [idx[axial]], [data.extra("pose")[idx[axial], 2]]
    if image_labels and data.has_images and (~axial).any():
        rest = idx[~axial]
        found = [(i, est.angle_rad) for i, img in zip(rest, data.depth_mm(rest))
                 if (est := angle_from_image(img, pixel_mm=data.image.pixel_mm)).defined]
        if found:
            keep.append(np.array([i for i, _ in found], np.int64))
            angle.append(np.array([a for _, a in found]))
    kind = np.concatenate([np.ones(len(keep[0]), bool)] + [np.zeros(len(k), bool) for k in keep[1:]])
    return np.concatenate(keep), wrap_axial(np.concatenate(angle)), kind


def labelled_presses(paths: list[str | Path], *, image_labels: bool = True, redraw_noise: bool = False
                     ) -> dict[str, dict[str, Any]]:
    """Readings, axis angles and kinds of the train and val splits of several datasets, concatenated; with
    ``redraw_noise``, the train split's :class:`~tactile_manip.learning.noise.ChipNoise` too (key ``"noise"``)."""
    parts: dict[str, list] = {"train": [], "val": []}
    noise: list[ChipNoise] = []
    cells = None
    for path in paths:
        data = load_dataset(path)
        if cells is not None and tuple(data.readings.shape[1:]) != cells:
            raise DatasetError(f"{path}: readings of shape {data.readings.shape[1:]}, the others {cells}")
        cells = tuple(data.readings.shape[1:])
        check_finite_readings(data, np.flatnonzero(np.isin(data.split, tuple(parts))), str(path))
        for split in parts:
            idx, angle, axial = axis_labels(data, data.indices(split), image_labels=image_labels)
            parts[split].append((data.readings[idx].astype(np.float32), angle, axial))
            if redraw_noise and split == "train":
                noise.append(ChipNoise.of(data, idx))
    out: dict[str, dict[str, Any]] = {}
    for split, rows in parts.items():
        out[split] = {"readings": np.concatenate([r[0] for r in rows]), "angle_rad": np.concatenate([r[1] for r in rows]),
                      "axial": np.concatenate([r[2] for r in rows])}
    if noise:
        out["train"]["noise"] = ChipNoise.concatenate(noise)
    return out


def symmetric(readings: np.ndarray, angle_rad: np.ndarray, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray]:
    """Each reading under a random symmetry of the board, and its axis moved with it."""
    out, out_angle = np.empty_like(readings), np.empty_like(angle_rad)
    choice = rng.integers(0, len(SYMMETRIES), len(readings))
    for s, (turns, mirror) in enumerate(SYMMETRIES):
        sel = choice == s
        out[sel] = transform_reading(readings[sel], turns, mirror)
        out_angle[sel] = (-angle_rad[sel] if mirror else angle_rad[sel]) + turns * math.pi / 2
    return out, out_angle


def train_angle_head(cfg: AngleTrainConfig, data_paths: list[str | Path], out: str | Path, *,
                     progress: Callable[[dict[str, Any]], None] | None = None,
                     on_start: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Train, write ``out/best.pt`` and ``out/history.json``, and return the summary.

    ``on_start(epochs)`` is called once the data are labelled; ``progress(row)`` after every epoch (``row``:
    epoch, loss, val_nll, val_within_5).
    """
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    data = labelled_presses(list(data_paths), image_labels=cfg.image_labels, redraw_noise=cfg.redraw_noise)
    train, val = data["train"], data["val"]
    if len(train["angle_rad"]) < cfg.batch_size or len(val["angle_rad"]) < 1:
        raise DatasetError(f"{len(train['angle_rad'])} training and {len(val['angle_rad'])} validation presses with "
                           f"a known axis: too few (need at least one batch, {cfg.batch_size}, and a val split)")
    mcfg = cfg.model_config(tuple(train["readings"].shape[1:]))
    torch.manual_seed(cfg.seed)
    model = AngleHead(mcfg)
    with torch.no_grad():
        model.set_normalisation(reading_features(torch.from_numpy(train["readings"])))
    rng = np.random.default_rng(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    n = len(train["angle_rad"])
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=cfg.epochs * math.ceil(n / cfg.batch_size),
                                                pct_start=WARMUP_FRACTION)
    peak_epoch = math.ceil(WARMUP_FRACTION * cfg.epochs)
    xv, av = torch.from_numpy(val["readings"]), torch.from_numpy(val["angle_rad"].astype(np.float32))
    if on_start:
        on_start(cfg.epochs)
    start = time.perf_counter()
    best: dict[str, Any] = {"val_nll": math.inf, "epoch": 0, "state": None}
    history = []
    for epoch in range(1, cfg.epochs + 1):
        x, a = train["readings"], train["angle_rad"]
        if cfg.redraw_noise:
            x = train["noise"].draw(rng)
        if cfg.symmetry:
            x, a = symmetric(x, a, rng)
        x, a = torch.from_numpy(x), torch.from_numpy(a.astype(np.float32))
        model.train()
        total = 0.0
        for i in torch.randperm(n, generator=gen).split(cfg.batch_size):
            total += optimise_step(von_mises_loss(model(x[i]), a[i]), opt, sched, epoch) * len(i)
        row = {"epoch": epoch, "loss": total / n, **validation(model, xv, av, val["axial"])}
        history.append(row)
        if progress:
            progress(row)
        if row["val_nll"] < best["val_nll"]:
            best = {"val_nll": row["val_nll"], "epoch": epoch,
                    "state": {k: v.clone() for k, v in model.state_dict().items()}}
        elif epoch - max(best["epoch"], peak_epoch) >= cfg.patience:
            break
    model.load_state_dict(best["state"])
    model.eval()
    final = validation(model, xv, av, val["axial"])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    record = {"paths": [str(p) for p in data_paths], "train_presses": int(n),
              "train_axial": int(train["axial"].sum()), "val_presses": int(len(av))}
    summary = {"kind": KIND, "train_config": to_dict(cfg), "model_config": to_dict(mcfg),
               "parameters": count_parameters(model), **record, "best_epoch": best["epoch"],
               "epochs_run": len(history), "val": final, "train_seconds": round(time.perf_counter() - start, 1),
               "history": history}
    payload = {"kind": KIND, "model": model.state_dict(), "model_config": to_dict(mcfg),
               "input": {"cells": list(mcfg.cells)}, "train_config": to_dict(cfg), "data": record, "val": final}
    tmp = out / "best.pt.partial"
    torch.save(payload, tmp)
    tmp.replace(out / "best.pt")
    (out / "history.json").write_text(json.dumps(summary, indent=1))
    return summary


def von_mises_loss(axis: torch.Tensor, angle_rad: torch.Tensor) -> torch.Tensor:
    return von_mises_nll(axis, angle_rad).mean()


@torch.no_grad()
def validation(model: AngleHead, readings: torch.Tensor, angle_rad: torch.Tensor, axial: np.ndarray
               ) -> dict[str, float]:
    """Mean NLL over all validation presses; share within 5 / 2 deg and median error over the axial ones."""
    model.eval()
    axis = model(readings)
    nll = float(von_mises_nll(axis, angle_rad).mean())
    err = np.degrees(np.abs(wrap_axial(0.5 * np.arctan2(axis[:, 1].numpy(), axis[:, 0].numpy())
                                       - angle_rad.numpy().astype(np.float64))))[axial]
    return {"val_nll": nll, "val_within_5": float(np.mean(err <= 5)) if err.size else math.nan,
            "val_within_2": float(np.mean(err <= 2)) if err.size else math.nan,
            "val_median_deg": float(np.median(err)) if err.size else math.nan}
