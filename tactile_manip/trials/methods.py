"""A scene's methods made ready to run: each method's estimator, every file found and checked before the first
trial.

:func:`build_tactile_estimators` gives what each method's behaviour is handed: one
:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` whose pose part is the method's model, an
interpolation baseline or the blind baseline (:func:`build_pose_estimators`), with the method's contact model
where it has one (the blind baseline, which has no tactile input, never has)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from tactile_manip.perception.baselines import BLIND, BlindPoseEstimator
from tactile_manip.perception.loading import load_pose_estimator
from tactile_manip.perception.reconstruct import BASELINES
from tactile_manip.perception.tactile_estimator import PoseEstimator, TactileEstimator
from tactile_manip.trials.scene import MethodSpec, TrialScene

if TYPE_CHECKING:
    from tactile_manip.perception.contact import ContactEstimator


def resolve_model_path(spec: MethodSpec, scene_path: Path | None) -> str:
    """The reconstructor argument for ``spec``: a baseline name, or an existing model path."""
    if spec.reconstructor in ("bilinear", "bicubic"):
        return spec.reconstructor
    return resolve_scene_path(spec.reconstructor, scene_path)


def resolve_scene_path(name: str, scene_path: Path | None) -> str:
    """A file a scene names: ``name`` if absolute, else the first that exists of the working directory's and
    each folder above the scene file's; ``name`` itself when none does (the loader then names it missing)."""
    path = Path(name)
    candidates = [path] if path.is_absolute() else [Path.cwd() / path]
    if scene_path is not None and not path.is_absolute():
        candidates += [parent / path for parent in Path(scene_path).resolve().parents]
    for candidate in candidates:
        if candidate.exists():
            return str(candidate)
    return str(path)  # the loader looks in the source checkout, else names it missing


def build_contact_estimator(scene: TrialScene, scene_path: Path | None = None, *,
                            layout: str | None = None) -> ContactEstimator | None:
    """The scene's contact model on onnxruntime (None when the scene names none), found as the methods' models.

    Raises:
        ModelFileError: the file is missing, or not a contact model.
        ValueError: the model estimates no normal force (``force_n``), or ``layout`` (the sensor's board
            layout) is given and is not the model's.
    """
    if not scene.contact_model:
        return None
    from tactile_manip.perception.contact import ContactEstimator

    contact = ContactEstimator(resolve_scene_path(scene.contact_model, scene_path))
    if "force_n" not in contact.target_names:
        raise ValueError(f"contact_model: {contact.path.name} estimates no grip force (its targets: "
                         f"{', '.join(contact.target_names)}); name a model trained on force_n")
    if layout is not None:
        try:
            contact.check_layout(layout)
        except ValueError as e:
            raise ValueError(f"contact_model: {e}") from None
    return contact


def build_contact_estimators(scene: TrialScene, scene_path: Path | None = None, *,
                             layout: str | None = None) -> dict[str, ContactEstimator | None]:
    """Each method's contact model (its own ``contact_model``, else the scene's; None for a method with
    neither), each file loaded once and checked as :func:`build_contact_estimator` checks the scene's."""
    loaded: dict[str, ContactEstimator | None] = {}
    out = {}
    for spec in scene.methods:
        name = spec.contact_model or scene.contact_model
        if name not in loaded:
            loaded[name] = build_contact_estimator(dataclasses.replace(scene, contact_model=name), scene_path,
                                                   layout=layout)
        out[spec.name] = loaded[name]
    return out


def build_pose_estimators(scene: TrialScene, scene_path: Path | None = None) -> dict[str, PoseEstimator]:
    """Each method's pose part (models are loaded once, before the first trial): a
    :class:`~tactile_manip.perception.estimator.TactilePoseEstimator`, or the blind baseline's
    (:func:`~tactile_manip.perception.loading.load_pose_estimator` of the method's options). A model's images are
    decoded as its file says (``image_symmetry = "stored"``: the default model's four passes), which is how
    every published trial figure was measured."""
    out: dict[str, PoseEstimator] = {}
    for spec in scene.methods:
        target = spec.reconstructor if spec.reconstructor == BLIND else resolve_model_path(spec, scene_path)
        model = target not in (BLIND, *BASELINES)
        out[spec.name] = load_pose_estimator(
            target, threads=spec.threads, samples=spec.samples, symmetrize=spec.symmetrize,
            calibrated=spec.calibrated, angle_source=spec.angle_source, escalate_below=spec.escalate_below,
            escalation=spec.escalation, escalation_samples=spec.escalation_samples, output_px=spec.output_px,
            image_symmetry="stored" if model else "none")
    return out


def build_tactile_estimators(scene: TrialScene, scene_path: Path | None = None, *,
                             layout: str | None = None) -> dict[str, TactileEstimator]:
    """What each method's behaviour is handed: a
    :class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` of its pose part
    (:func:`build_pose_estimators`) and its contact model (:func:`build_contact_estimators`, checked against
    the board ``layout``); without one for a method that has no contact model and for the blind baseline (no
    tactile input). A blind pose part with a contact model of the method's own (``contact_model`` in its
    ``[[methods]]`` entry) is a contact-only method: force and position from the pad, no angle (a board without a
    pose model)."""
    poses = build_pose_estimators(scene, scene_path)
    contacts = build_contact_estimators(scene, scene_path, layout=layout)
    own = {spec.name: bool(spec.contact_model) for spec in scene.methods}
    return {name: TactileEstimator(pose, None if isinstance(pose, BlindPoseEstimator) and not own[name]
                                   else contacts[name])
            for name, pose in poses.items()}
