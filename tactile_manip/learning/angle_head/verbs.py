"""The angle head's verbs (kind ``"angle_head"``, :mod:`tactile_manip.learning.kinds`): ``tactile-manip train``
on its config and ``export --checkpoint ... --attach-to MODEL.onnx`` of its checkpoint."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tactile_manip.learning.kinds import ExportRequest, TrainRequest



def run_train(request: TrainRequest) -> int:
    """Train the pose model's angle head on simulated presses (:mod:`.train`); the CVAE-only flags are refused."""
    from tactile_manip.learning.angle_head.train import load_angle_config, train_angle_head
    from tactile_manip.learning.verbs import small_net_config, start_run

    cfg = small_net_config(request, 'an angle head (kind = "angle_head")', load_angle_config)
    bars = []

    def start(total: int) -> None:
        bars.append(start_run(request, total=total, desc="training angle head"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(loss=f"{row['loss']:.3f}", val_nll=f"{row['val_nll']:.3f}",
                            within_5=f"{row['val_within_5']:.1%}")

    try:
        summary = train_angle_head(cfg, list(request.data), request.out, progress=progress, on_start=start)
    finally:
        for bar in bars:
            bar.close()
    val = summary["val"]
    print(f"validation: {val['val_within_5']:.1%} within 5 deg, {val['val_within_2']:.1%} within 2 deg, median "
          f"{val['val_median_deg']:.2f} deg on the axial presses, NLL {val['val_nll']:.3f} "
          f"({summary['val_presses']} presses; best epoch {summary['best_epoch']}; "
          f"{summary['train_seconds'] / 60:.1f} min); wrote {request.out}/best.pt, history.json")
    return 0


def run_export(request: ExportRequest) -> int:
    """Copy --attach-to to --out with the angle head inside (:mod:`.export`); ``data`` gives real readings to check
    it on."""
    import numpy as np

    from tactile_manip.data import load_dataset
    from tactile_manip.learning.angle_head.export import attach_angle_head

    if request.attach_to is None:
        raise ValueError(f"{request.checkpoint} is an angle head: give the pose model to attach it to with --attach-to "
                         "MODEL.onnx (a pose model without a head of its own)")
    given = [f"--{n.replace('_', '-')}" for n in ("metrics", "pixel_mm", "card", "history", "table", "latency")
             if getattr(request, n) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: not for an angle head, whose validation figures travel in its record")
    readings = None
    if request.data:  # datasets with and without images: each is read alone
        readings = np.concatenate([d.readings[d.indices("val")][:64] for d in map(load_dataset, request.data)])
    record = attach_angle_head(request.checkpoint, request.attach_to, request.out, check_readings=readings,
                               symmetries=request.head_symmetries == 8, image_symmetry=request.image_symmetry)
    val = record["validation"]
    copies = "its 8 symmetric copies" if record["symmetries"] == 8 else "1 copy (no symmetric copies)"
    print(f"wrote {request.out}: {request.attach_to} with an angle head of {record['parameters']:,} parameters reading "
          f"{copies} "
          f"(validation {val.get('val_within_5', float('nan')):.1%} within 5 deg), ONNX vs torch max |diff| "
          f"{record['parity_max_abs']:.2e}")
    return 0
