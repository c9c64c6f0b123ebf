"""Where is the contact? The reconstructed image's centroid, the contact model's position, and their weighted mean.

    python -m benchmarks.contact_position_fusion --data contact_unseen.npz \
        --pose models/supermag.onnx --contact models/contact_supermag.onnx

For every press of the dataset's validation and test splits, the pose estimator's contact centroid
(``AngleEstimate.centroid_mm``: the moments of the reconstructed image) and the contact model's centre of
pressure (``ContactState.position_mm``) are compared with the labelled ``x_mm``, ``y_mm``, and so is
``w * centroid + (1 - w) * position`` for each share ``w`` of ``--weights``. The share is chosen on the
validation split (the training objects of a simulated dataset) and reported on the test split (objects neither
model was trained on), overall and per object: the share to store with ``export --image-position-weight``.
The centroid counts where ``TactileEstimator`` counts it (an image contact of at least the pose estimator's
smallest area), else the model's position stands; the presses are those labelled in contact. For comparison,
per-press weights from the contact model's sigma (``sigma^2 / (sigma^2 + s^2)``, the image's error ``s`` chosen
on the validation split as well).

Prints markdown and writes docs/results/benchmarks/contact_position_fusion.json; asserts nothing.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from tqdm import tqdm

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset
from tactile_manip.perception.contact import ContactEstimator
from tactile_manip.evaluation.contact import model_predictions
from tactile_manip.perception.tactile_estimator import image_centroid_mm
from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.reconstruct import OnnxReconstructor


def positions(data, index: np.ndarray, pose: TactilePoseEstimator, contact: ContactEstimator
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 2) mm each: the image's centroid (NaN where the image has no contact), the contact model's position
    and its sigma."""
    image = np.full((len(index), 2), np.nan)
    for k, i in enumerate(tqdm(index, desc="reconstructing", leave=False)):
        c = image_centroid_mm(pose.estimate(data.readings[i]), pose.min_contact_area_mm2)
        if c is not None:
            image[k] = c
    mean, sigma = model_predictions(contact, data, index)
    names = list(contact.target_names)
    cols = [names.index("x_mm"), names.index("y_mm")]
    return image, mean[:, cols], sigma[:, cols]


def rmse_2d(estimate: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((estimate - truth) ** 2, axis=1))))


def fused(image: np.ndarray, model: np.ndarray, weight: float | np.ndarray) -> np.ndarray:
    """The weighted mean; the model's position where the image has no contact."""
    return np.where(np.isnan(image), model, weight * np.nan_to_num(image) + (1 - weight) * model)


def inverse_variance(sigma: np.ndarray, image_sigma_mm: float) -> np.ndarray:
    """Per-press image shares (n, 2) from the contact model's sigma and one image error."""
    return sigma ** 2 / (sigma ** 2 + image_sigma_mm ** 2)


def compute(args: argparse.Namespace) -> dict[str, Any]:
    data = load_dataset(args.data, images=False)
    pose = TactilePoseEstimator(OnnxReconstructor(args.pose, image_symmetry="stored"))  # as published
    contact = ContactEstimator(args.contact)
    weights = [float(w) for w in args.weights.split(",")]
    image_sigmas = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0, 1.5]
    out: dict[str, Any] = {"machine": machine_info(), "data": args.data, "pose": args.pose, "contact": args.contact,
                           "in_contact_only": True}
    splits = {}
    for split in ("val", "test"):
        index = data.indices(split)
        index = index[data.target("in_contact")[index] > 0.5] if "in_contact" in data.target_names else index
        truth = np.stack([data.target("x_mm")[index], data.target("y_mm")[index]], 1)
        image, model, sigma = positions(data, index, pose, contact)
        splits[split] = (index, truth, image, model)
        out[split] = {"presses": int(len(index)), "image_has_no_contact": int(np.isnan(image[:, 0]).sum()),
                      "rmse_2d_mm_by_weight": {f"{w:g}": rmse_2d(fused(image, model, w), truth) for w in weights},
                      "rmse_2d_mm_inverse_variance_by_image_sigma": {
                          f"{s:g}": rmse_2d(fused(image, model, inverse_variance(sigma, s)), truth)
                          for s in image_sigmas}}
    by_weight = out["val"]["rmse_2d_mm_by_weight"]
    chosen = min(weights, key=lambda w: by_weight[f"{w:g}"])
    out["chosen_weight"] = chosen
    by_sigma = out["val"]["rmse_2d_mm_inverse_variance_by_image_sigma"]
    out["chosen_image_sigma_mm"] = min(image_sigmas, key=lambda s: by_sigma[f"{s:g}"])
    index, truth, image, model = splits["test"]
    objects = data.objects(index)
    out["test_by_object"] = {
        str(o): {"presses": int((objects == o).sum()),
                 **{name: rmse_2d(est[objects == o], truth[objects == o]) for name, est in
                    (("contact_model", model), ("image_centroid", fused(image, model, 1.0)),
                     ("fused", fused(image, model, chosen)))}}
        for o in sorted(set(objects.tolist()))}
    return out


def markdown(report: dict[str, Any]) -> str:
    w = report["chosen_weight"]
    lines = [f"Contact position on {report['data']} (presses in contact): the image's centroid ({report['pose']}), "
             f"the contact model's position ({report['contact']}), and w x centroid + (1 - w) x position. "
             f"w chosen on the validation split: **{w:g}**.", "",
             "| image share w | validation 2-D RMSE mm | test 2-D RMSE mm |", "|---|---|---|"]
    for key, val in report["val"]["rmse_2d_mm_by_weight"].items():
        mark = "**" if float(key) == w else ""
        lines.append(f"| {mark}{key}{mark} | {val:.3f} | {report['test']['rmse_2d_mm_by_weight'][key]:.3f} |")
    s = f"{report['chosen_image_sigma_mm']:g}"
    lines += ["", f"Per-press shares from the contact model's sigma, the image's error s = {s} mm chosen on "
              f"validation: validation {report['val']['rmse_2d_mm_inverse_variance_by_image_sigma'][s]:.3f} mm, "
              f"test {report['test']['rmse_2d_mm_inverse_variance_by_image_sigma'][s]:.3f} mm (one share: "
              f"validation {report['val']['rmse_2d_mm_by_weight'][f'{w:g}']:.3f} mm).",
              "", f"Test split per object (w = {w:g}):", "",
              "| object | presses | contact model mm | image centroid mm | weighted mean mm |", "|---|---|---|---|---|"]
    for name, r in report["test_by_object"].items():
        lines.append(f"| {name} | {r['presses']} | {r['contact_model']:.3f} | {r['image_centroid']:.3f} | "
                     f"{r['fused']:.3f} |")
    lines.append(f"\nw = 0 is the contact model alone, w = 1 the image's centroid (the model's position where the "
                 f"image has no contact: {report['test']['image_has_no_contact']} test presses). To make the chosen "
                 f"share the default of TactileEstimator with this contact model, export it with "
                 f"`tactile-manip export --checkpoint RUN/best.pt --out MODEL.onnx --image-position-weight {w:g}`.")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a labelled dataset with x_mm and y_mm and val/test splits")
    parser.add_argument("--pose", default="models/supermag.onnx", help="the image model of the pose estimator")
    parser.add_argument("--contact", default="models/contact_supermag.onnx")
    parser.add_argument("--weights", default="0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1",
                        help="image shares to compare, comma-separated")
    parser.add_argument("--out", default="docs/results/benchmarks/contact_position_fusion.json")
    args = parser.parse_args()
    publish(compute(args), args.out, markdown)


if __name__ == "__main__":
    main()
