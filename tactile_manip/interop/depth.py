"""Reconstructed depth for exported episodes: a model run over every frame's field (``export --depth``).

Trial and pair-log frames carry baseline-subtracted fields and go to the model as they are. A recording holds
raw fields: its baseline is taken from its first second (:data:`BASELINE_FRAMES` frames), which must be
quiet (nothing on the pad), as a live sensor's baseline must.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tactile_manip.interop.frames import Episode

BASELINE_FRAMES = 125  # 1 s at 125 Hz, as the live sensor's default baseline
BATCH = 256            # readings per model run


def add_depth(episodes: list[Episode], model: str) -> dict[str, Any]:
    """Set ``depth_mm`` of every frame of ``episodes`` from ``model`` (an .onnx path, a shipped model's name,
    "bilinear" or "bicubic").

    Returns:
        The model's facts for the export's metadata (name, path, metadata of an ONNX file, output shape).

    Raises:
        ModelFileError: the model cannot be loaded.
        CalibrationError: a recording's first second is not quiet enough for a baseline.
        ValueError: the readings do not fit the model.
    """
    from tactile_manip.perception.reconstruct import load_reconstructor, read_metadata

    # offline: each image as the model file says (the default model: averaged over the 4 quarter turns)
    reconstructor = load_reconstructor(model, **({} if str(model) in ("bilinear", "bicubic") else
                                                 {"image_symmetry": "stored"}))
    for e in episodes:
        fields = np.stack([f.field_ut for f in e.frames]).astype(np.float32)
        if e.meta.get("source") == "recording":
            fields = fields - _recording_baseline(e, fields)
        depth = np.concatenate([reconstructor.reconstruct_batch(fields[i:i + BATCH])
                                for i in range(0, len(fields), BATCH)])
        for f, d in zip(e.frames, depth):
            f.depth_mm = np.asarray(d, np.float32)
    path = getattr(reconstructor, "path", None)  # the file an ONNX model was found at (a name resolved)
    facts: dict[str, Any] = {"model": str(model), "output_shape": list(reconstructor.output_shape),
                             "pixel_mm": reconstructor.pixel_mm}
    if path is not None:
        facts["path"] = str(path)
        facts["metadata"] = read_metadata(path)
    return facts


def _recording_baseline(e: Episode, fields: np.ndarray) -> np.ndarray:
    from tactile_manip.chips import ChipModelSpec
    from tactile_manip.errors import CalibrationError
    from tactile_manip.sensors.baseline import baseline_from_frames, noise_thresholds_ut
    from tactile_manip.sensors.config import BaselineConfig

    chip = e.meta.get("chip") or {}
    known = {k: chip[k] for k in ("lsb_xy_ut", "lsb_z_ut", "saturation_counts", "noise_xy_ut", "noise_z_ut")
             if k in chip}
    first = fields[:BASELINE_FRAMES]
    thresholds = noise_thresholds_ut(BaselineConfig(), ChipModelSpec(**known))
    try:
        baseline = baseline_from_frames(first, np.zeros(first.shape, bool), thresholds, source=str(e.meta.get("file")))
    except CalibrationError as err:
        raise CalibrationError(f"--depth needs a baseline, and the recording's first second is not quiet: "
                               f"{str(err).split('. Is something')[0]}; record a second with nothing on the pad "
                               "first") from None
    e.meta["baseline_for_depth"] = f"mean of the first {len(first)} frames"
    return baseline.offset_ut
