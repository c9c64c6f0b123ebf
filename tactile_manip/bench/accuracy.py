"""Accuracy of a reconstructor, computed exactly as the evaluate and trials commands compute it.

- Readings: the ``test`` split (unseen objects) of a paired dataset when the file is there, so the figures
  are those of ``tactile-manip evaluate``; otherwise the test objects of the dataset config, simulated here
  (``per_object`` presses of each).
- Image metrics: :func:`tactile_manip.evaluation.images.evaluate_methods` on those readings (PSNR and
  SSIM with the 2 mm data range, FD-DCT, the PCA angle error on the rods against the true yaw).
- Reorientation: :func:`tactile_manip.trials.runner.run_scene` on a fixed scene, one method at a time,
  scored by :func:`tactile_manip.trials.stats.summarise` at the scene's tolerance.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.evaluation.images import ELONGATED, evaluate_methods
from tactile_manip.perception.reconstruct import Reconstructor
from tactile_manip.data import PairedDataset, load_dataset


def first_per_object(data: PairedDataset, split: str, per_object: int) -> np.ndarray:
    """Indices of the first ``per_object`` samples of each object in ``split`` (ascending)."""
    idx = data.indices(split)
    names = data.objects(idx)
    keep = np.concatenate([idx[names == n][:per_object] for n in dict.fromkeys(names.tolist())])
    return np.sort(keep)


def simulate_test_objects(config_path: str | Path, per_object: int | None, *, workers: int = 0) -> PairedDataset:
    """Simulate only the test objects of a dataset config (``per_object`` presses each; None: the config's
    counts). The presses differ from the full dataset's (each sample's seed is its index in the config)."""
    from tactile_manip.sim.dataset import generate, load_dataset_config

    cfg = load_dataset_config(config_path)
    objects = [o for o in cfg.objects if o.split == "test"]
    if not objects:
        raise ValueError(f"{config_path}: no objects with split = 'test' to benchmark on")
    if per_object is not None:
        objects = [dataclasses.replace(o, count=per_object) for o in objects]
    cfg = dataclasses.replace(cfg, objects=objects)
    total = sum(o.count for o in objects)
    return generate(cfg, workers=1 if total < 64 else workers)


def load_readings(data_path: str | Path | None, config_path: str | Path, *,
                  per_object: int | None) -> tuple[PairedDataset, dict[str, Any]]:
    """The benchmark's readings as a dataset whose ``test`` split is what every method is scored on, and a
    description of where they came from."""
    if data_path is not None and Path(data_path).exists():  # a folder or a foreign file is refused, not replaced
        data = load_dataset(data_path)
        data.require_images(f"bench on {data_path}")
        source = {"source": f"{data_path} test split", "data_fingerprint": data.fingerprint()}
        if per_object is not None:
            data = data.subset(first_per_object(data, "test", per_object))
            source["source"] += f", first {per_object} per object"
    else:
        data = simulate_test_objects(config_path, per_object)
        source = {"source": f"simulated test objects of {config_path}" + (f", {per_object} per object"
                                                                         if per_object else "")}
        if data_path is not None:
            source["note"] = f"{data_path} not found: readings simulated"
    test = data.indices("test")
    source |= {"readings": int(test.size), "rod_readings": int(rod_mask(data, test).sum()),
               "objects": sorted(set(data.objects(test).tolist()))}
    return data, source


def rod_mask(data: PairedDataset, index: np.ndarray) -> np.ndarray:
    """Which samples at ``index`` are rods (the elongated objects whose angle is scored)."""
    return np.array([any(str(n).startswith(e) for e in ELONGATED) for n in data.objects(index)], dtype=bool)


class Chunked(Reconstructor):
    """``inner`` with its batches cut into chunks of ``chunk`` readings: the same images, bounded memory
    (a whole test split in one batch through the paper preset needs tens of GB of activations)."""

    def __init__(self, inner: Reconstructor, chunk: int = 32) -> None:
        self.inner, self.chunk = inner, int(chunk)
        self.name, self.input_shape = inner.name, inner.input_shape
        self.output_shape, self.pixel_mm = inner.output_shape, inner.pixel_mm

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        step = self.chunk
        parts = [self.inner.reconstruct_batch(fields_ut[i:i + step]) for i in range(0, len(fields_ut), step)]
        return np.concatenate(parts), None


def image_accuracy(data: PairedDataset, rec: Reconstructor, label: str) -> tuple[dict[str, Any], np.ndarray]:
    """Table I metrics of ``rec`` on the test split, and its predictions (N, H, W) mm."""
    (result,), predictions = evaluate_methods(data, {label: Chunked(rec)}, split="test")
    a = result.angle_error_deg
    return ({"psnr_db": result.psnr_db[0], "psnr_db_std": result.psnr_db[1], "ssim": result.ssim[0],
             "ssim_std": result.ssim[1], "fd_dct": result.fd_dct,
             "angle_median_deg": a.get("median"), "angle_p95_deg": a.get("p95"),
             "angle_undefined_fraction": a.get("undefined_fraction"), "angle_count": a.get("count", 0)},
            predictions[label])


ROD_SCENE_OBJECTS = (("cylinder", 3.0), ("hex_bar", 4.0), ("square_bar", 2.5), ("cylinder", 6.0), ("hex_bar", 8.0),
                     ("square_bar", 5.0))


def rod_scene(trials: int, *, seed: int = 0):
    """The scene of ``configs/scenes/reorient_sim.toml`` (the six unseen rods, random in-hand angle, +-2 mm,
    10-11 N, 5 deg tolerance) with ``trials`` presentations, built in Python so it needs no file."""
    from tactile_manip.trials.scene import PresentationConfig, TrialObject, TrialScene

    objects = [TrialObject(name, f"{name}_{size:g}mm".replace(".", "p"), {"size_mm": size})
               for name, size in ROD_SCENE_OBJECTS]
    # the scene names its grip-force model as the shipped file does; the bench's trials score the angle only
    return TrialScene(name="reorient_sim", trials=trials, seed=seed, presentation=PresentationConfig(objects=objects),
                      contact_model="models/contact_supermag.onnx")


def load_trial_scene(path: str | Path | None, trials: int):
    """The scene file at ``path`` (or :func:`rod_scene` when None) with ``trials`` presentations."""
    from tactile_manip.trials.scene import load_scene

    if path is None:
        return rod_scene(trials)
    return dataclasses.replace(load_scene(path), trials=trials)


def trial_success(scene, method: str, *, spec=None, reconstructor: Reconstructor | None = None,
                  scene_path: str | Path | None = None) -> dict[str, Any]:
    """Run ``scene`` for one method (``spec``: a MethodSpec, as the trials command; or a ready
    ``reconstructor``) and score it at the scene's tolerance."""
    from tactile_manip.perception.estimator import TactilePoseEstimator
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.trials.methods import build_pose_estimators
    from tactile_manip.trials.runner import run_scene
    from tactile_manip.trials.stats import summarise

    if spec is not None:
        scene = dataclasses.replace(scene, methods=[spec])
        poses = build_pose_estimators(scene, Path(scene_path) if scene_path else None)
    else:
        poses = {method: TactilePoseEstimator(reconstructor)}
    estimators = {name: TactileEstimator(pose) for name, pose in poses.items()}  # the angle alone: no contact model
    records: list = []
    run_scene(scene, records.append, estimators=estimators, progress=False)
    s = next(iter(summarise(records, math.radians(scene.tolerance_deg)).methods.values()))
    return {"successes": s.successes, "n": s.n, "rate": s.success_rate, "wilson_low": s.wilson_low,
            "wilson_high": s.wilson_high, "error_median_deg": s.abs_error_median_deg,
            "error_p95_deg": s.abs_error_p95_deg, "faults": s.faults, "outcomes": s.outcomes}
