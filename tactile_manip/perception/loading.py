"""One call from model files (or the shipped models' names) to a ready estimator.

:func:`load_estimator` (``TactileEstimator.load``) loads the pose model and the contact model of one board;
:func:`load_pose_estimator` the pose part alone, with every option a trial scene's method has. Names of shipped
models (``"supermag"``, ``"contact"``, :data:`~tactile_manip.shipped.SHIPPED_MODELS`) and paths of the source
checkout (``models/supermag.onnx``) are found from any working folder
(:func:`~tactile_manip.shipped.resolve_model_path`); ``"bilinear"`` and ``"bicubic"`` are the paper's
interpolation baselines and ``"blind"`` the baseline without tactile input.
"""

from __future__ import annotations

from pathlib import Path

from tactile_manip.perception.baselines import BLIND, BlindPoseEstimator, NoPoseEstimator
from tactile_manip.perception.confidence import load_calibration_beside
from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.pose import PoseParams
from tactile_manip.perception.reconstruct import BASELINES, load_reconstructor
from tactile_manip.perception.symmetry import SymmetrizedReconstructor
from tactile_manip.perception.tactile_estimator import PoseEstimator, TactileEstimator
from tactile_manip.shipped import CONTACT_MODEL, DEFAULT_MODEL, resolve_model_path

ESCALATIONS = ("symmetry", "samples")


def load_pose_estimator(model: str | Path = DEFAULT_MODEL, *, threads: int = 1, samples: int = 1,
                        image_symmetry: str = "none", symmetrize: bool = False, calibrated: bool = True,
                        angle_source: str = "auto", escalate_below: float = 0.0, escalation: str = "symmetry",
                        escalation_samples: int = 8, output_px: int = 0, min_field_ut: float = 20.0,
                        params: PoseParams | None = None) -> PoseEstimator:
    """The pose part of ``model``: a shipped model's name, an ``.onnx`` path, ``"bilinear"``, ``"bicubic"`` or
    ``"blind"`` (:class:`~tactile_manip.perception.baselines.BlindPoseEstimator`; every other option unused).

    Args:
        threads: onnxruntime intra-op threads (1: the real-time setting).
        samples: prior samples per reading (> 1 adds their spread to the confidence).
        image_symmetry: what each depth image is averaged over: ``"none"`` (one decoder pass, the default: a
            reading -> image p99 within 2.5 ms on one thread), ``"rotations"`` (the reading's 4 quarter turns,
            +0.41 dB PSNR on unseen presses at four times the image's cost), ``"all"`` (8 copies) or
            ``"stored"`` (what the model file says: ``"rotations"`` for ``models/supermag.onnx``).
        symmetrize: average every image over the sensor's 8 symmetries
            (:class:`~tactile_manip.perception.symmetry.SymmetrizedReconstructor`).
        calibrated: use the confidence calibration beside the model file when it was fitted for this estimator
            (prior samples, symmetry, aperture and route); otherwise the raw confidence.
        angle_source, min_field_ut, params: as :class:`~tactile_manip.perception.estimator.TactilePoseEstimator`.
        escalate_below, escalation, escalation_samples: re-estimate a reading whose confidence is below
            ``escalate_below`` with the image averaged over the 8 symmetries (``"symmetry"``) or from
            ``escalation_samples`` prior samples (``"samples"``).
        output_px: the baselines' square image size (0: 200 px; 16 is the paper's trial baseline).

    Raises:
        ModelFileError: the file is missing (the message says where it looked) or not a pose model.
        ValueError: an option out of its range, or one the model cannot take.
    """
    key = str(model)
    if key == BLIND:
        return BlindPoseEstimator()
    if escalation not in ESCALATIONS:
        raise ValueError(f"escalation must be one of {', '.join(ESCALATIONS)}, got {escalation!r}")
    baseline = key in BASELINES
    if baseline:
        if escalate_below > 0 and escalation == "samples":
            raise ValueError(f"the 'samples' escalation draws prior samples of an ONNX model; {key} has none")
        base = load_reconstructor(key, **({"output_px": output_px} if output_px else {}))
        target = key
    else:
        target = str(resolve_model_path(model))
        options = {"threads": threads, "samples": samples, "image_symmetry": image_symmetry}
        base = load_reconstructor(target, **options)
    reconstructor = SymmetrizedReconstructor(base) if symmetrize else base
    params = params or PoseParams()  # the calibration must have been fitted with the same parameters
    calibration = load_calibration_beside(target) if calibrated and not baseline else None
    route = ("head" if base.angle_head is not None else "image") if angle_source == "auto" else angle_source
    if calibration is not None and not calibration.fits(prior_samples=samples, symmetrized=symmetrize,
                                                        aperture=params.aperture, route=route):
        calibration = None  # fitted for another estimator: its map would not give this one's probability
    escalating = None
    if escalate_below > 0 and escalation == "symmetry":
        escalating = SymmetrizedReconstructor(base)
    elif escalate_below > 0:
        escalating = load_reconstructor(target, threads=threads, samples=escalation_samples,
                                        image_symmetry=image_symmetry)
        if symmetrize:
            escalating = SymmetrizedReconstructor(escalating, spread=True)
    return TactilePoseEstimator(reconstructor, params, min_field_ut=min_field_ut, calibration=calibration,
                                escalation=escalating, escalate_below=escalate_below, angle_source=angle_source)


def load_estimator(pose_model: str | Path | None = DEFAULT_MODEL, contact_model: str | Path | None = CONTACT_MODEL,
                   *, image_position_weight: float | None = None, **options) -> TactileEstimator:
    """A :class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` from its files, in one call.

    ``pose_model``: the pose part (:func:`load_pose_estimator`, which takes ``options``), or None for a board
    with a contact model alone (:class:`~tactile_manip.perception.baselines.NoPoseEstimator`: no angle);
    ``contact_model``: the contact model of the same board (a shipped model's name or an ``.onnx`` path, on
    ``options["threads"]`` threads), or None for none (the blind baseline never has one). The defaults are the
    shipped SuperMag models, found from any working folder.

    Raises:
        ModelFileError: a file is missing (the message says where it looked) or not a model of its kind.
        ValueError: the two models read different boards, or an option is out of its range.
    """
    if pose_model is None and contact_model is None:
        raise ValueError("an estimator needs a pose model, a contact model or both; both are None")
    pose = NoPoseEstimator() if pose_model is None else load_pose_estimator(pose_model, **options)
    contact = None
    if contact_model is not None and not isinstance(pose, BlindPoseEstimator):  # no tactile input, no contact
        from tactile_manip.perception.contact import ContactEstimator

        contact = ContactEstimator(contact_model, threads=int(options.get("threads", 1)))
    return TactileEstimator(pose, contact, image_position_weight=image_position_weight)
