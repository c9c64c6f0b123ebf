"""Run a reorientation trial scene: every presentation once per method, logged as it completes.

In simulation the scene is wired like this: the kinematic twin holds the presented object; when the twin
gripper closes on it, the simulated tactile sensor is told the contact (the object's shape, its in-hand
angle and offset in the pad frame, the grasp force) and renders the magnetic field of that contact at
125 Hz with fresh chip noise per frame; when the gripper opens, the pad is empty again. The estimator only
ever sees the sensor's frames. The trial is scored from the twin's true object pose after the correction.
With a scene's ``contact_model``, each trial also logs the grip force that model reads from the sensor at the
estimate step.

Each (trial, method) is appended to ``trials.jsonl`` and fsynced as soon as it completes; ``resume=True``
skips the pairs already there, so a killed run loses no completed trial and can be continued.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tactile_manip.behaviours.grip import GripConfig, GripResult
from tactile_manip.behaviours.place import PlaceResult
from tactile_manip.behaviours.reorient import ReorientResult
from tactile_manip.errors import ConfigError
from tactile_manip.extras import require
from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.pose import PoseParams, wrap_axial
from tactile_manip.perception.reconstruct import load_reconstructor
from tactile_manip.perception.confidence import load_calibration_beside
from tactile_manip.perception.symmetry import SymmetrizedReconstructor
from tactile_manip.robot.frames import hand_T_finger_pad, rotation_about, transform
from tactile_manip.sensors.config import SimulatedSensorConfig
from tactile_manip.trials.blind import BLIND, BlindEstimator
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.scene import TASK_TITLES, MethodSpec, TrialObject, TrialScene

if TYPE_CHECKING:
    from tactile_manip.perception.contact import ContactEstimator

# A drawn sensor's baseline: 25 frames (0.2 s) average the chip noise (<= 15 uT per frame) to <= 3 uT, well
# under the 20 uT no-contact threshold, at a fraction of the 1 s a session's first baseline takes.
SENSOR_DRAW_BASELINE_FRAMES = 25


@dataclass(frozen=True)
class Presentation:
    """One trial's draw: which object, at which in-hand angle (rad, pad frame), offset (mm) and force (N)."""

    trial: int
    seed: int
    obj: TrialObject
    angle_rad: float
    offset_mm: tuple[float, float]
    force_n: float
    sensor_spread: float = 0.0      # > 0: this trial's sensor is drawn (see sensor_params)

    def sensor_params(self):
        """The simulator parameters of this trial's sensor (drawn from its seed), or None for the nominal one."""
        if self.sensor_spread == 0:
            return None
        from tactile_manip.sim.params import SimParams, randomise

        return randomise(SimParams(), np.random.default_rng([self.seed, 1]), spread=self.sensor_spread)


def draw_presentation(scene: TrialScene, trial: int) -> Presentation:
    """The presentation of trial ``trial``: a pure function of the scene's seed and the index."""
    seed = int(np.random.SeedSequence([scene.seed, trial]).generate_state(1)[0])
    rng = np.random.default_rng(seed)
    p = scene.presentation
    obj = p.objects[trial % len(p.objects)]
    angle = float(wrap_axial(math.radians(rng.uniform(*p.angle_deg))))
    offset = rng.uniform(-p.offset_mm, p.offset_mm, size=2)
    force = float(rng.uniform(*p.force_n))
    return Presentation(trial, seed, obj, angle, (float(offset[0]), float(offset[1])), force, p.sensor_spread)


def pad_T_object(angle_rad: float, offset_mm: tuple[float, float], width_m: float) -> np.ndarray:
    """Object frame (x along its axis, its centre ``width_m / 2`` off the pad surface) in the pad frame."""
    return transform(rotation_about(np.array([0.0, 0.0, 1.0]), angle_rad),
                     np.array([offset_mm[0] * 1e-3, offset_mm[1] * 1e-3, width_m / 2]))


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
    return str(path)  # the loader raises the clear "missing model" error


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


def build_estimators(scene: TrialScene, scene_path: Path | None = None) -> dict[str, TactilePoseEstimator]:
    """One estimator per method (models are loaded once, before the first trial)."""
    out = {}
    for spec in scene.methods:
        if spec.reconstructor == BLIND:  # the baseline without tactile input
            out[spec.name] = BlindEstimator()
            continue
        target = resolve_model_path(spec, scene_path)
        if target in ("bilinear", "bicubic"):
            kwargs = {"output_px": spec.output_px} if spec.output_px else {}
        else:
            kwargs = {"threads": spec.threads, "samples": spec.samples}
        base = load_reconstructor(target, **kwargs)
        reconstructor = SymmetrizedReconstructor(base) if spec.symmetrize else base
        model = target not in ("bilinear", "bicubic")
        calibration = load_calibration_beside(target) if model and spec.calibrated else None
        params = PoseParams()  # the estimator's pose parameters, which the calibration must have been fitted with
        route = spec.angle_source
        if route == "auto":
            route = "head" if base.angle_head is not None else "image"
        if calibration is not None and not calibration.fits(prior_samples=spec.samples, symmetrized=spec.symmetrize,
                                                            aperture=params.aperture, route=route):
            calibration = None  # fitted for another estimator: its map would not give this one's probability
        escalation = None
        if spec.escalate_below > 0 and spec.escalation == "symmetry":
            escalation = SymmetrizedReconstructor(base)
        elif spec.escalate_below > 0:  # "samples" (MethodSpec refuses it for baselines)
            escalation = load_reconstructor(target, threads=spec.threads, samples=spec.escalation_samples)
            if spec.symmetrize:
                escalation = SymmetrizedReconstructor(escalation, spread=True)
        out[spec.name] = TactilePoseEstimator(reconstructor, params, calibration=calibration, escalation=escalation,
                                              escalate_below=spec.escalate_below, angle_source=spec.angle_source)
    return out


class SimulatedCell:
    """The simulated work cell: kinematic twin arm and gripper, a world holding the object, a simulated sensor.

    Built from a scene; only the parts the scene names (no dynamics engine, no VBTS rendering).
    """

    def __init__(self, scene: TrialScene) -> None:
        from tactile_manip.robot.safety import SafeArm
        from tactile_manip.robot.twin import KinematicArm, TwinArmConfig, TwinGripper, TwinWorld
        from tactile_manip.sensors.simulated import SimulatedSensor
        from tactile_manip.sim.shapes import make_indenter

        require("roboticstoolbox", "the simulated trial cell (kinematic FR3 twin)")  # before the run folder
        if not isinstance(scene.sensor, SimulatedSensorConfig):
            raise ConfigError("sensor: the simulated cell (robot.backend = 'twin') needs the simulated sensor; "
                              "remove the [sensor] port")
        self.scene = scene
        self.twin = KinematicArm(TwinArmConfig(home_q_rad=scene.robot.home_q_rad,
                                               speed_factor=scene.robot.speed_factor))
        self.arm = SafeArm(self.twin, scene.robot.safety)
        self.world = TwinWorld(self.twin)
        self.gripper = TwinGripper(self.twin, self.world)
        self.sensor = SimulatedSensor(scene.sensor)
        self._indenters = {o.display_name: make_indenter(o.name, **o.kwargs) for o in scene.presentation.objects}
        self._presentation: Presentation | None = None
        self._sensor_key: int | None = None      # seed of the drawn sensor in use (None: the nominal one)
        self._stall_after_grasp = False
        self.applied_force_n: float | None = None  # the force the held object feels (None: nothing held)
        self.world.on_grasp.append(self._on_grasp)
        self.world.on_release.append(self._on_release)

    # -------------------------------------------------------------- wiring of the twin to the sensor

    def _on_grasp(self, obj, hand_T_object: np.ndarray, force_n: float) -> None:
        from tactile_manip.sim.objects import IndenterPose

        pad_T_obj = np.linalg.inv(hand_T_finger_pad(obj.width_m)) @ hand_T_object
        yaw = math.atan2(pad_T_obj[1, 0], pad_T_obj[0, 0])
        pose = IndenterPose(x_mm=pad_T_obj[0, 3] * 1e3, y_mm=pad_T_obj[1, 3] * 1e3, yaw_rad=yaw)
        self.applied_force_n = self.applied_force(force_n)
        self.sensor.set_contact(obj.payload, pose, self.applied_force_n)
        if self._stall_after_grasp:
            self.sensor.stall()

    def _on_release(self, obj) -> None:
        self.applied_force_n = None
        self.sensor.clear_contact()

    def applied_force(self, commanded_n: float) -> float:
        """The force the object feels when the gripper is commanded ``commanded_n``: the presentation's force
        (drawn per trial) at the behaviour's force, in proportion to the command (the gripper's force control
        error is a gain); the command itself outside a presentation."""
        if self._presentation is None:
            return float(commanded_n)
        return self._presentation.force_n * float(commanded_n) / self.scene.behaviour.force_n

    # -------------------------------------------------------------- lifecycle

    @contextlib.contextmanager
    def connected(self) -> Iterator[SimulatedCell]:
        """Connect everything, take the sensor's baseline with nothing on the pad, disconnect at the end."""
        with self.sensor, self.arm, self.gripper:
            self.sensor.calibrate_baseline()
            yield self

    @contextlib.contextmanager
    def presented(self, p: Presentation, *, arm_fault: bool = False,
                  sensor_stall: bool = False) -> Iterator[tuple[object, WorldTruth]]:
        """Trial boundary, then ``p``'s object between the open fingers; yields (world object, its truth).

        On exit (also after a fault) the gripper opens, the object is removed and the sensor resumes.
        ``arm_fault`` arms a reflex on the next arm move; ``sensor_stall`` stops the sensor once it is grasped.
        """
        from tactile_manip.robot.twin import WorldObject

        self._ready_for_trial()
        self._use_sensor_of(p)
        obj = WorldObject(p.obj.display_name, p.obj.grasp_width_m, payload=self._indenters[p.obj.display_name])
        self._presentation, self._stall_after_grasp = p, sensor_stall
        self.world.present(obj, hand_T_finger_pad(obj.width_m) @ pad_T_object(p.angle_rad, p.offset_mm, obj.width_m))
        if arm_fault:
            self.twin.inject_fault(kind="reflex", at_fraction=0.5)
        try:
            yield obj, WorldTruth(self.world, obj, lambda: self.applied_force_n)
        finally:
            self._stall_after_grasp = False
            if self.sensor.stalled:
                self.sensor.resume()
            self.gripper.open()
            self.world.remove(obj)
            self._presentation = None

    def _use_sensor_of(self, p: Presentation) -> None:
        """Swap in the trial's drawn sensor (or back to the nominal one) and take its baseline, pad unloaded."""
        from tactile_manip.sim.pair import SensorPair

        params = p.sensor_params()
        key = None if params is None else p.seed
        if key == self._sensor_key:
            return
        self.sensor.replace_pair(SensorPair(seed=self.scene.sensor.seed) if params is None
                                 else SensorPair(params, seed=self.scene.sensor.seed))
        self.sensor.calibrate_baseline(frames=SENSOR_DRAW_BASELINE_FRAMES)
        self._sensor_key = key

    def run_one(self, p: Presentation, estimator: TactilePoseEstimator, *, arm_fault: bool = False,
                sensor_stall: bool = False, observer=None,
                contact: ContactEstimator | None = None) -> ReorientResult | PlaceResult | GripResult:
        """Present ``p``, run the reorientation behaviour with ``estimator``, release, reset.

        ``observer`` (a :class:`~tactile_manip.behaviours.reorient.PhaseObserver`) is told each phase, the
        release included. ``contact`` (a :class:`~tactile_manip.perception.contact.ContactEstimator` of the
        sensor's board) estimates the grip force at the estimate step.
        """
        from tactile_manip.trials.operator import run_reorientation

        with self.presented(p, arm_fault=arm_fault, sensor_stall=sensor_stall) as (obj, truth):
            if self.scene.task == "place":
                return self._place(p, estimator, obj, truth)
            if self.scene.task == "grip":
                return self._grip(estimator, obj, truth, contact)
            return run_reorientation(self, estimator, obj.width_m, truth, observer, contact)

    def _place(self, p: Presentation, estimator: TactilePoseEstimator, obj, truth: WorldTruth) -> PlaceResult:
        """The "place" task: a slot drawn from the presentation's seed, the rod put into it."""
        from tactile_manip.behaviours.place import draw_slot, place_in_slot
        from tactile_manip.robot.frames import hand_T_pad

        base_T_pad = self.arm.state().base_T_hand @ hand_T_pad()  # the fingers' mid-plane before the grasp
        slot = draw_slot(base_T_pad, p.seed, self.scene.place.clearance_mm * 1e-3)
        return place_in_slot(self.arm, self.gripper, self.sensor, estimator, slot, object_width_m=obj.width_m,
                             config=self.scene.behaviour, truth=truth)

    def _grip(self, estimator: TactilePoseEstimator, obj, truth: WorldTruth,
              contact: ContactEstimator | None) -> GripResult:
        """The "grip" task: the method's pose estimator and the scene's contact model as one estimator (the
        closed loop); the blind baseline, or a scene without a contact model, grips open loop."""
        from tactile_manip.behaviours.grip import grip_to_force
        from tactile_manip.perception.contact_pose import TactileEstimator

        tactile = estimator
        if contact is not None and isinstance(estimator, TactilePoseEstimator):
            tactile = TactileEstimator(estimator, contact)
        return grip_to_force(self.arm, self.gripper, self.sensor, tactile, object_width_m=obj.width_m,
                             config=self.scene.behaviour, grip=self.scene.grip, truth=truth)

    def _ready_for_trial(self) -> None:
        """Trial boundary: clear any fault (and an armed but unused fault injection), open, go home."""
        self.twin.recover()
        self.gripper.open()
        self.arm.home()


class WorldTruth:
    """Ground truth from the twin (for scoring): the object's pose and axis in the base frame."""

    def __init__(self, world, obj, force_n: Callable[[], float | None] | None = None) -> None:
        self._world, self._obj, self._force_n = world, obj, force_n

    def grip_force_n(self) -> float | None:
        """The normal force the held object feels now, N (None when not held or unknown)."""
        return None if self._force_n is None else self._force_n()

    def object_pose_base(self) -> np.ndarray:
        return self._world.object_pose(self._obj)

    def object_axis_base(self) -> np.ndarray:
        return self.object_pose_base()[:3, 0]


def make_record(p: Presentation, method: str, target_rad: float, result: ReorientResult, *,
                commanded_force_n: float | None = None, task: str | None = "reorient") -> TrialRecord:
    """The log line of one trial (a correction without a measured final angle is "unmeasured").

    ``commanded_force_n``: the behaviour's grasp force, logged as ``extra["commanded_force_n"]`` beside the
    grip force a contact model estimated (``result.contact``); ``task``: the scene's task, named in the line.
    """
    est = result.estimate
    grip = result.contact
    outcome, detail = result.outcome, result.detail
    if outcome == "done" and result.error_rad is None:
        outcome, detail = "unmeasured", "the final angle was not measured"
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=float(wrap_axial(target_rad)),
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        action=result.action, regrasps=result.regrasps, final_angle_rad=result.final_angle_rad,
        error_rad=result.error_rad, outcome=outcome, detail=detail,
        timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), "grasp_width_m": result.grasp_width_m, **_sensor_extra(p),
               "correction_rad": result.correction_rad, "escalated": bool(est is not None and est.escalated),
               "estimate_timings_s": dict(est.timings_s) if est is not None else {},
               **({} if commanded_force_n is None else {"commanded_force_n": float(commanded_force_n)})},
        estimated_grip_force_n=_rounded(None if grip is None else grip.force_n),
        estimated_grip_force_sigma_n=_rounded(None if grip is None else grip.force_sigma_n), task=task)


def make_place_record(p: Presentation, method: str, result: PlaceResult, *, clearance_mm: float) -> TrialRecord:
    """The log line of one placement: ``error_rad`` is the rod's axial angle to the slot, ``lateral_error_mm``
    the distance from the slot's centre to its axis (a placement without a measured pose is "unmeasured")."""
    est = result.estimate
    outcome, detail = result.outcome, result.detail
    if outcome == "done" and (result.angle_error_rad is None or result.lateral_error_m is None):
        outcome, detail = "unmeasured", "the rod's final pose was not measured"
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=0.0,
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        error_rad=result.angle_error_rad if outcome == "done" else None, outcome=outcome, detail=detail,
        task="place",
        lateral_error_mm=_rounded(None if result.lateral_error_m is None else result.lateral_error_m * 1e3),
        clearance_mm=float(clearance_mm), timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), **_sensor_extra(p),
               "escalated": bool(est is not None and est.escalated)})


def make_grip_record(p: Presentation, method: str, result: GripResult, *, grip: GripConfig,
                     target_force_n: float) -> TrialRecord:
    """The log line of one grip: ``error_rad`` is the estimated in-hand angle minus the true one,
    ``lateral_error_mm`` the distance from the pad centre to the rod's axis, ``force_error_n`` the force the rod
    felt minus the target (a grip without those measured is "unmeasured")."""
    est = result.estimate
    outcome, detail = result.outcome, result.detail
    measured = None not in (result.angle_error_rad, result.centre_error_m, result.force_error_n)
    if outcome == "done" and not measured:
        outcome, detail = "unmeasured", "the final force or pose was not measured"
    grip_state = result.contact
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=0.0,
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        action="regrasp" if result.recentres or result.force_steps else "act",
        regrasps=result.recentres + result.force_steps,
        error_rad=result.angle_error_rad if outcome == "done" else None, outcome=outcome, detail=detail, task="grip",
        lateral_error_mm=_rounded(None if result.centre_error_m is None else result.centre_error_m * 1e3),
        clearance_mm=float(grip.centre_tolerance_mm), force_error_n=_rounded(result.force_error_n),
        force_tolerance_n=float(grip.force_tolerance_n),
        timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), **_sensor_extra(p), "commanded_force_n": float(target_force_n),
               "final_command_n": _rounded(result.commanded_force_n), "applied_force_n": _rounded(result.true_force_n),
               "force_steps": result.force_steps, "recentres": result.recentres,
               "position_mm": None if result.position_mm is None else [round(v, 4) for v in result.position_mm],
               "escalated": bool(est is not None and est.escalated)},
        estimated_grip_force_n=_rounded(None if grip_state is None or not grip_state.plausible else grip_state.force_n),
        estimated_grip_force_sigma_n=_rounded(None if grip_state is None or not grip_state.plausible
                                              else grip_state.force_sigma_n))


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(float(value), 4)


def _sensor_extra(p: Presentation) -> dict:
    params = p.sensor_params()
    if params is None:
        return {}
    from tactile_manip.sim.params import randomised_values

    return {"sensor": {k: round(v, 6) for k, v in randomised_values(params).items()}}


def make_cell(scene: TrialScene):
    """The trial cell of ``scene.robot.backend``: :class:`SimulatedCell` for the twin, else an operator cell."""
    if scene.robot.backend == "twin":
        return SimulatedCell(scene)
    from tactile_manip.trials.operator import OperatorCell

    return OperatorCell(scene)


def run_scene(scene: TrialScene, write: Callable[[TrialRecord], None], *, estimators: dict[str, TactilePoseEstimator],
              skip: set[tuple[int, str]] = frozenset(), progress: bool = True, cell=None,
              trial_observer=None, frames_dir: str | Path | None = None,
              contact: ContactEstimator | Mapping[str, ContactEstimator | None] | None = None) -> int:
    """Run every (trial, method) of ``scene`` not in ``skip``; ``write`` each record.

    ``cell`` (default: built from ``scene.robot.backend``: :class:`SimulatedCell` for the twin,
    :class:`~tactile_manip.trials.operator.OperatorCell` for a real FR3) provides ``connected()`` and ``run_one``.
    ``trial_observer`` (e.g. :class:`~tactile_manip.interop.rerun_trials.RerunTrialObserver`), when given, is told
    ``trial_started(presentation, method, cell)`` before each trial and ``trial_finished(record)`` after it
    was written; it watches, it changes nothing.
    With ``frames_dir``, each trial's per-frame streams go to ``frames_dir/<method>-<trial>.tmframes``
    (:mod:`tactile_manip.trials.frames`; the cell also needs ``sensor``, ``arm`` and ``gripper``).
    With ``contact`` (the scene's contact model, :func:`build_contact_estimator`, or one per method,
    :func:`build_contact_estimators`), each record carries the grip force it estimated at the estimate step (and
    the "grip" task servoes on it).

    Returns the number of trials run. Outcomes other than "done" are recorded, never raised; only an
    interrupt (Ctrl-C) or a failure to build the cell stops the run.
    """
    from tqdm.auto import tqdm

    cell = cell if cell is not None else make_cell(scene)
    code = _code_version() if frames_dir is not None else None
    todo = [(i, m) for i in range(scene.trials) for m in estimators if (i, m) not in skip]
    faults = scene.faults
    target = math.radians(scene.target_deg)
    count = 0
    with cell.connected(), tqdm(total=len(todo), desc=f"trials ({scene.name})", unit="trial",
                                disable=not progress) as bar:
        for i, method in todo:
            p = draw_presentation(scene, i)
            if trial_observer is not None:
                trial_observer.trial_started(p, method, cell)
            t0 = time.perf_counter()
            try:
                with _frame_stream(cell, frames_dir, p, method, scene, code) as observer:
                    kwargs = {} if observer is None else {"observer": observer}
                    mine = contact.get(method) if isinstance(contact, Mapping) else contact
                    if mine is not None:
                        kwargs["contact"] = mine
                    result = cell.run_one(p, estimators[method], arm_fault=i in faults.arm_fault_trials,
                                          sensor_stall=i in faults.sensor_stall_trials, **kwargs)
            except Exception as exc:  # noqa: BLE001 - a broken trial is recorded, the run goes on
                failed = {"place": PlaceResult, "grip": GripResult}.get(scene.task, ReorientResult)
                result = failed(outcome="error", detail=f"{type(exc).__name__}: {exc}")
            result.timings_s.setdefault("trial", time.perf_counter() - t0)
            if isinstance(result, PlaceResult):
                record = make_place_record(p, method, result, clearance_mm=scene.place.clearance_mm)
            elif isinstance(result, GripResult):
                record = make_grip_record(p, method, result, grip=scene.grip, target_force_n=scene.behaviour.force_n)
            else:
                record = make_record(p, method, target, result, commanded_force_n=scene.behaviour.force_n,
                                     task=scene.task)
            write(record)
            if trial_observer is not None:
                trial_observer.trial_finished(record)
            count += 1
            bar.update()
    return count


def _code_version() -> str:
    from tactile_manip.version import code_version

    return code_version()


def _frame_stream(cell, frames_dir: str | Path | None, p: Presentation, method: str, scene: TrialScene,
                  code_version: str | None):
    """The trial's frame recorder (a context manager yielding the behaviour's observer), or a null one."""
    if frames_dir is None:
        return contextlib.nullcontext()
    from tactile_manip.trials.frames import TrialFrameStream

    header = {"code_version": code_version, "trial": p.trial, "method": method, "seed": p.seed,
              "object": p.obj.display_name, "scene": scene.name,
              "true_angle_rad": p.angle_rad, "offset_mm": list(p.offset_mm), "force_n": p.force_n}
    return TrialFrameStream(Path(frames_dir) / f"{method}-{p.trial:04d}.tmframes", sensor=cell.sensor, arm=cell.arm,
                            gripper=cell.gripper, header=header,
                            target_angle_rad=float(wrap_axial(math.radians(scene.target_deg))))


def run_trials(scene: TrialScene, out_dir: str | Path, *, scene_path: str | Path | None = None,
               resume: bool = False, progress: bool = True, tolerance_deg: float | None = None,
               trial_observer=None, frames: bool = True):
    """Run ``scene`` into ``out_dir`` (trials.jsonl fsynced per trial, then the report) and return the summary.

    ``trial_observer``: see :func:`run_scene`. With ``frames`` (the default) each trial's per-frame streams go to
    ``out_dir/frames/`` (:mod:`tactile_manip.trials.frames`): what ``tactile-manip export`` turns into episodes.

    With ``resume=True`` the (trial, method) pairs already in ``out_dir/trials.jsonl`` are skipped (the scene
    must be the same: the log refuses a different one).
    """
    from tactile_manip.config import to_dict
    from tactile_manip.trials.log import TrialLog, completed_keys, read_run_info, read_trials
    from tactile_manip.trials.report import write_report

    out = Path(out_dir)
    # every part the scene names is built before the run folder is made, so a bad scene leaves no folder behind
    estimators = build_estimators(scene, Path(scene_path) if scene_path is not None else None)
    cell = make_cell(scene)
    contact = build_contact_estimators(scene, Path(scene_path) if scene_path is not None else None,
                                       layout=cell.sensor.layout.name)
    skip = completed_keys(out / "trials.jsonl") if resume and (out / "trials.jsonl").exists() else set()
    with TrialLog(out, config=to_dict(scene), resume=resume) as log:
        run_scene(scene, log.append, estimators=estimators, skip=skip, progress=progress, cell=cell,
                  trial_observer=trial_observer, contact=contact,
                  frames_dir=out / "frames" if frames and scene.task == "reorient" else None)
    tolerance = math.radians(scene.tolerance_deg if tolerance_deg is None else tolerance_deg)
    return write_report(out, read_trials(out / "trials.jsonl"), tolerance,
                        title=f"{TASK_TITLES[scene.task]}: {scene.name}", run_info=read_run_info(out), task=scene.task)
