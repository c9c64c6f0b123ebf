"""Table I of SuperMag on our data: reconstruction quality of every method on unseen objects.

For each method (the interpolation baselines and any exported models) over the dataset's ``test`` split:
PSNR and SSIM per image (mean +- std, data range 2 mm, see :mod:`tactile_manip.evaluation.metrics`), the
Frechet distance in the fixed DCT feature space (``FD-DCT``; a real ``FID`` only when the user supplies an
Inception network as ONNX), per-object breakdowns, and the angle error of the PCA pipeline on elongated
objects (rods), scored against the true yaw. Writes ``table.md``, ``results.json`` and ``gallery.png``.
"""

from __future__ import annotations

import json
import math
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.extras import require
from tactile_manip.evaluation import metrics
from tactile_manip.perception.pose import angle_from_image, wrap_axial
from tactile_manip.perception.reconstruct import ModelFileError, Reconstructor
from tactile_manip.data import PairedDataset

ELONGATED = ("cylinder", "hex_bar", "square_bar", "flat_bar")
FORCE_BANDS_N = (2.0, 5.0, 8.0, 11.0, 15.0)   # edges of the force bands reported when a test split spans them


@dataclass
class MethodResult:
    """Metrics of one method on one split."""

    name: str
    psnr_db: tuple[float, float]
    ssim: tuple[float, float]
    fd_dct: float
    fid: float | None
    angle_error_deg: dict[str, float]
    per_object: dict[str, dict[str, float]] = field(default_factory=dict)
    seconds_per_image: float = 0.0
    per_group: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)  # force bands, sensor draws

    def row(self) -> dict[str, Any]:
        return {"method": self.name, "psnr_db_mean": self.psnr_db[0], "psnr_db_std": self.psnr_db[1],
                "ssim_mean": self.ssim[0], "ssim_std": self.ssim[1], "fd_dct": self.fd_dct, "fid": self.fid,
                "angle_error_deg": self.angle_error_deg, "per_object": self.per_object,
                "per_group": self.per_group, "seconds_per_image": self.seconds_per_image}


def evaluate_methods(data: PairedDataset, methods: dict[str, Reconstructor], *, split: str = "test",
                     inception_onnx: str | Path | None = None) -> tuple[list[MethodResult], dict[str, np.ndarray]]:
    """Run every method on ``split``; returns the results and each method's predictions (N, H, W)."""
    idx = data.indices(split)
    truth = data.image_values(idx)
    names = data.objects(idx)
    fid_features = _inception_features(inception_onnx) if inception_onnx else None
    truth_feats = fid_features(truth) if fid_features else None
    groups = sample_groups(data, idx)
    results, predictions = [], {}
    for label, method in methods.items():
        t0 = time.perf_counter()
        pred = method.reconstruct_batch(data.readings[idx])
        seconds = (time.perf_counter() - t0) / len(idx)
        predictions[label] = pred
        L = data.image.data_range
        p, s = metrics.psnr(pred, truth, data_range=L), metrics.ssim(pred, truth, data_range=L)
        per_object = {str(n): {"psnr_db": float(np.mean(p[names == n])), "ssim": float(np.mean(s[names == n])),
                               "count": int(np.sum(names == n))} for n in np.unique(names)}
        fid = metrics.frechet_distance(fid_features(pred), truth_feats) if fid_features else None
        errors = rod_angle_errors(data, idx, pred)
        per_group = {g: {band: _summary(p[m], s[m], errors[m]) for band, m in bands.items()}
                     for g, bands in groups.items()}
        results.append(MethodResult(label, (float(p.mean()), float(p.std())), (float(s.mean()), float(s.std())),
                                    metrics.fd_dct(pred, truth), fid, _angle_summary(errors), per_object,
                                    seconds, per_group))
    return results, predictions


def rod_angle_errors(data: PairedDataset, idx: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """PCA angle error (deg, >= 0) of each sample's reconstruction against its true yaw, for the elongated
    objects of ``idx`` (NaN for other samples); an undefined angle counts as the worst error, 90 deg."""
    errors = np.full(len(idx), np.nan)
    if not data.has("pose") or data.image.pixel_mm is None:
        return errors
    names = data.objects(idx)
    yaw = data.extra("pose")[idx, 2]
    for i in range(len(idx)):
        if any(str(names[i]).startswith(e) for e in ELONGATED):
            est = angle_from_image(pred[i], pixel_mm=data.image.pixel_mm)
            errors[i] = abs(math.degrees(wrap_axial(est.angle_rad - float(yaw[i])))) if est.defined else 90.0
    return errors


def rod_estimates(data: PairedDataset, idx: np.ndarray, estimator, *, chunk: int = 256
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Single-frame estimates of the elongated objects' presses among ``idx``: their indices, the estimator's
    confidence (0 when undefined) and the angle error against the true yaw, deg (90 when undefined).

    ``estimator`` is a :class:`~tactile_manip.perception.estimator.TactilePoseEstimator`; readings go through
    it ``chunk`` at a time (:meth:`~tactile_manip.perception.estimator.TactilePoseEstimator.estimate_many`).
    """
    if not data.has("pose"):
        raise ValueError("the dataset has no 'pose' per sample: the true angles of its presses are unknown")
    names = data.objects(idx)
    rods = np.asarray(idx)[[any(str(n).startswith(e) for e in ELONGATED) for n in names]]
    if rods.size == 0:
        raise ValueError(f"no presses of elongated objects ({', '.join(ELONGATED)}) among the "
                         f"{len(idx)} selected: their angle is what the confidence is calibrated on")
    yaw = data.extra("pose")[rods, 2]
    conf, err = np.zeros(rods.size), np.full(rods.size, 90.0)
    for start in range(0, rods.size, chunk):
        part = slice(start, start + chunk)
        for i, est in enumerate(estimator.estimate_many(list(data.readings[rods[part]].astype(np.float64))),
                                start=start):
            if est.defined:
                conf[i] = est.confidence
                err[i] = abs(math.degrees(wrap_axial(est.angle_rad - float(yaw[i]))))
    return rods, conf, err


def _angle_summary(errors: np.ndarray) -> dict[str, float]:
    """Median, p95, shares within 2 and 5 deg, count and undefined fraction of the rod angle errors."""
    e = errors[np.isfinite(errors)]
    if not e.size:
        return {}
    return {"median": float(np.median(e)), "p95": float(np.percentile(e, 95)), "count": int(e.size),
            "within_2_deg": float(np.mean(e <= 2.0)), "within_5_deg": float(np.mean(e <= 5.0)),
            "undefined_fraction": float(np.mean(e >= 90.0))}


def _summary(psnr: np.ndarray, ssim: np.ndarray, errors: np.ndarray) -> dict[str, float]:
    return {"psnr_db": float(psnr.mean()), "ssim": float(ssim.mean()), "count": int(psnr.size),
            **{f"angle_{k}": v for k, v in _angle_summary(errors).items()}}


def sample_groups(data: PairedDataset, idx: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """Masks over ``idx`` for the breakdowns a split supports: force bands (``FORCE_BANDS_N``) when its forces
    span more than 2 N; magnet strength and chip noise terciles when each press has its own drawn sensor."""
    groups: dict[str, dict[str, np.ndarray]] = {}
    if data.has("force_n"):
        f = data.extra("force_n")[idx]
        if f.size and f.max() - f.min() > 2.0:
            edges = FORCE_BANDS_N
            bands = {f"{lo:g}-{hi:g} N": (f >= lo) & ((f < hi) if hi < edges[-1] else (f <= hi))
                     for lo, hi in zip(edges[:-1], edges[1:])}
            groups["force"] = {k: m for k, m in bands.items() if m.any()}
    names = data.provenance.get("sensor_param_names", [])
    if data.has("sensor_params") and len(idx) >= 3:
        params = data.extra("sensor_params")[idx]
        for key, label in (("magnet.remanence_t", "magnet"), ("chip.noise_z_ut", "chip noise")):
            if key in names:
                v = params[:, names.index(key)]
                lo, hi = np.quantile(v, [1 / 3, 2 / 3])
                groups[label] = {f"low ({v.min():.3g}-{lo:.3g})": v <= lo, f"mid ({lo:.3g}-{hi:.3g})": (v > lo) & (v <= hi),
                                 f"high ({hi:.3g}-{v.max():.3g})": v > hi}
    return groups


def _inception_features(path: str | Path):
    """Features from a user-supplied Inception network in ONNX: (N, 3, 299, 299) ImageNet-normalised in,
    (N, 2048) pool features out. Depth images are scaled by the 2 mm range to [0, 1] and repeated to RGB.

    Raises:
        ModelFileError: the file is missing, not ONNX, or not a network of that signature (checked on one
            blank image before any method runs).
    """
    from scipy import ndimage

    session, name = _inception_session(Path(path))
    mean = np.array([0.485, 0.456, 0.406], np.float32)[:, None, None]
    std = np.array([0.229, 0.224, 0.225], np.float32)[:, None, None]

    def features(images: np.ndarray) -> np.ndarray:
        out = []
        for img in images:
            zoom = (299 / img.shape[0], 299 / img.shape[1])
            x = np.clip(ndimage.zoom(img / metrics.DEPTH_RANGE_MM, zoom, order=1), 0, 1).astype(np.float32)
            x = (np.repeat(x[None], 3, axis=0) - mean) / std
            out.append(session.run(None, {name: x[None]})[0].reshape(-1))
        return np.asarray(out)

    return features


def _inception_session(path: Path):
    ort = require("onnxruntime", "--inception-onnx")
    if not path.is_file():
        raise ModelFileError(f"Inception model not found: {path}")
    try:
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    except Exception as e:  # noqa: BLE001 - onnxruntime raises its own classes (InvalidProtobuf, Fail, ...)
        raise ModelFileError(f"{path} is not a readable ONNX model ({type(e).__name__})") from e
    inputs = session.get_inputs()
    if len(inputs) != 1 or len(inputs[0].shape) != 4 or list(inputs[0].shape[1:]) != [3, 299, 299]:
        got = ", ".join(f"{i.name} {i.shape}" for i in inputs)
        raise ModelFileError(f"{path} is not an Inception-v3 feature network: expected one input "
                             f"(N, 3, 299, 299), got {got}")
    try:
        probe = session.run(None, {inputs[0].name: np.zeros((1, 3, 299, 299), np.float32)})[0]
    except Exception as e:  # noqa: BLE001 - as above
        raise ModelFileError(f"{path} failed on a blank 299x299 image ({type(e).__name__})") from e
    if np.asarray(probe).size != 2048:
        raise ModelFileError(f"{path} is not an Inception-v3 feature network: expected 2048 pool features per "
                             f"image, got an output of shape {tuple(np.shape(probe))}")
    return session, inputs[0].name


def markdown_table(results: list[MethodResult]) -> str:
    """Table I layout: method, FD-DCT (or FID), PSNR and SSIM as mean +- std, angle error on rods."""
    fid = any(r.fid is not None for r in results)
    head = "| method | " + ("FID | " if fid else "") + "FD-DCT | PSNR [dB] | SSIM | rod angle error median / p95 [deg] |"
    lines = [head, "|---" * (head.count("|") - 1) + "|"]
    for r in results:
        a = r.angle_error_deg
        angle = f"{a['median']:.1f} / {a['p95']:.1f}" if a else "-"
        lines.append(f"| {r.name} | " + (f"{r.fid:.2f} | " if fid else "") + f"{r.fd_dct:.2f} | "
                     f"{r.psnr_db[0]:.2f} +- {r.psnr_db[1]:.2f} | {r.ssim[0]:.3f} +- {r.ssim[1]:.3f} | {angle} |")
    return "\n".join(lines) + "\n" + group_tables(results)


def group_tables(results: list[MethodResult]) -> str:
    """Per force band and per sensor draw (where the split has them): PSNR and the share of rod angles within
    5 and 2 deg for each method, one table per breakdown."""
    out = []
    for group in (results[0].per_group if results else {}):
        bands = list(results[0].per_group[group])
        head = f"| {group} | " + " | ".join(f"{r.name}: PSNR dB / rods within 5 / 2 deg" for r in results) + " |"
        lines = ["", head, "|---" * (head.count("|") - 1) + "|"]
        for band in bands:
            cells = []
            for r in results:
                g = r.per_group[group][band]
                rods = (f"{100 * g['angle_within_5_deg']:.1f} % / {100 * g['angle_within_2_deg']:.1f} % "
                        f"(n {g['angle_count']})" if "angle_count" in g else "-")
                cells.append(f"{g['psnr_db']:.2f} / {rods}")
            lines.append(f"| {band} (n {results[0].per_group[group][band]['count']}) | " + " | ".join(cells) + " |")
        out += lines
    return "\n".join(out) + ("\n" if out else "")


def untrained(reconstructor: Reconstructor) -> bool:
    """True for an exported model whose metadata says it was never trained (0 epochs run).

    Files exported before the ``training`` record existed, and the baselines, count as trained.
    """
    inner = getattr(reconstructor, "inner", reconstructor)  # a SymmetrizedReconstructor's model
    record = getattr(inner, "metadata", {}).get("training")
    return record is not None and int(record.get("epochs_run", 0)) == 0


def gallery(path: str | Path, data: PairedDataset, methods: dict[str, Reconstructor],
            rows: list[tuple[str, int]]) -> list[str]:
    """Write :func:`gallery_figure` to ``path`` (PNG); returns the labels of the untrained models left out."""
    fig, skipped = gallery_figure(data, methods, rows)
    fig.savefig(path, dpi=80)
    return skipped


def gallery_figure(data: PairedDataset, methods: dict[str, Reconstructor], rows: list[tuple[str, int]]):
    """Figure like the paper's gallery: one row per (split, dataset index), columns ground truth then each
    method, reconstructed here for just those readings, on one scale (the images' value range, 0-2 mm for
    depth; its colour bar at the right). Untrained models (:func:`untrained`) are left out. Returns (figure, labels left out)."""
    from tactile_manip.plots import _pyplot

    skipped = [label for label, m in methods.items() if untrained(m)]
    methods = {label: m for label, m in methods.items() if label not in skipped}
    plt = _pyplot()
    index = np.array([i for _, i in rows])
    preds = {label: m.reconstruct_batch(data.readings[index]) for label, m in methods.items()}
    fig, axes = plt.subplots(len(rows), len(methods) + 1, figsize=(2.2 * (len(methods) + 1) + 0.9, 2.2 * len(rows)),
                             constrained_layout=True, squeeze=False)
    for r, (split, i) in enumerate(rows):
        images = [data.image_values([i])[0]] + [preds[m][r] for m in methods]
        for c, (img, title) in enumerate(zip(images, ["ground truth (VBTS)"] + list(methods))):
            ax = axes[r, c]
            im = ax.imshow(img, cmap="viridis", vmin=data.image.value_min, vmax=data.image.value_max)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(textwrap.fill(title, 24), fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{data.objects([i])[0]}\n({'unseen' if split == 'test' else 'seen'})", fontsize=8)
    fig.colorbar(im, ax=axes, shrink=min(1.0, 3.0 / len(rows)), label=("depth [mm]" if data.image.unit == "mm" else data.image.unit) + " (every panel)")
    plt.close(fig)  # the caller saves it; closing only drops pyplot's reference
    return fig, skipped


def write_report(out: str | Path, results: list[MethodResult], meta: dict[str, Any]) -> None:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(markdown_table(results))
    (out / "results.json").write_text(json.dumps({**meta, "results": [r.row() for r in results]}, indent=1))
