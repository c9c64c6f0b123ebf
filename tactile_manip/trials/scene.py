"""A reorientation trial scene: the TOML file ``tactile-manip trials --config`` reads, as typed dataclasses.

A scene names only what the job needs (docs/design.md, Scenes): the methods compared, the objects and how they
are presented, the robot backend with its safety limits, the tactile sensor, the behaviour's parameters and
(for robustness runs) a fault plan. See ``configs/scenes/reorient_sim.toml`` for a commented example.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from tactile_manip.behaviours.grip import GripConfig
from tactile_manip.behaviours.reorient import ReorientConfig
from tactile_manip.checks import check_finite_scalar
from tactile_manip.config import load_config
from tactile_manip.perception.estimator import ANGLE_SOURCES
from tactile_manip.robot.safety import SafetyLimits
from tactile_manip.sensors.config import SerialSensorConfig, SimulatedSensorConfig
from tactile_manip.sim.shapes import check_shape_arguments


@dataclass(frozen=True)
class MethodSpec:
    """One compared method: a name for the logs and the reconstructor behind the estimator.

    Attributes:
        name: label in the logs and plots, e.g. "supermag".
        reconstructor: "bilinear", "bicubic", "blind" (no tactile input: the baseline every task is scored
            against, :mod:`tactile_manip.perception.baselines`) or a path to an exported .onnx model (relative paths are
            resolved against the working directory, then against the scene file's repository).
        output_px: baselines only: square output size (16 = the paper's 4x4 -> 16x16 trial baseline; 0 keeps
            the shipped 200x200).
        samples: ONNX models only: prior samples per reading (> 1 adds their spread to the confidence).
        threads: onnxruntime intra-op threads.
        symmetrize: average the reconstruction over the sensor's 8 symmetries
            (:class:`~tactile_manip.perception.symmetry.SymmetrizedReconstructor`; 8 readings per estimate).
        calibrated: use the model's confidence calibration when it has one beside it
            (``<model>.calibration.json``, from ``tactile-manip calibrate``) fitted for this method's
            ``samples`` and ``symmetrize``: the confidence the behaviour's ``min_confidence`` compares is then
            P(angle within the calibration's tolerance); a calibration fitted for another estimator is not used.
        escalate_below: spend extra inference only on estimates whose confidence is below this (0: never).
        escalation: the extra inference: "symmetry" (the reading's 8 symmetric copies averaged) or "samples"
            (``escalation_samples`` prior samples, their spread lowering the confidence).
        escalation_samples: prior samples per reading of the "samples" escalation.
        angle_source: where the angle comes from: "auto" (the model's angle head when its file has one, else the
            image), "image" (the paper's route: the reconstruction's outliers removed, Gaussian-filtered, its
            principal axis by PCA), "head" (the angle head) or "likelier" (whichever of the two is the more
            likely); see :class:`~tactile_manip.perception.estimator.TactilePoseEstimator`.
        contact_model: this method's contact model (an exported ``.onnx``), in place of the scene's
            ``contact_model``; "" takes the scene's.
    """

    name: str
    reconstructor: str
    output_px: int = 0
    samples: int = 1
    threads: int = 1
    symmetrize: bool = False
    calibrated: bool = True
    escalate_below: float = 0.0
    escalation: str = "symmetry"
    escalation_samples: int = 8
    angle_source: str = "auto"
    contact_model: str = ""

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"methods.name must be a non-empty word (letters, digits, _ or -), got {self.name!r}")
        if self.output_px < 0 or self.samples < 1 or self.threads < 1 or self.escalation_samples < 2:
            raise ValueError(f"method {self.name}: output_px >= 0, samples >= 1, threads >= 1 and "
                             "escalation_samples >= 2 are required")
        if not (math.isfinite(self.escalate_below) and 0.0 <= self.escalate_below <= 1.0):
            raise ValueError(f"method {self.name}: escalate_below must be a confidence in [0, 1], got "
                             f"{self.escalate_below}")
        if self.angle_source not in ANGLE_SOURCES:
            raise ValueError(f"method {self.name}: angle_source must be one of {', '.join(ANGLE_SOURCES)}, got "
                             f"{self.angle_source!r}")
        if self.contact_model and not self.contact_model.endswith(".onnx"):
            raise ValueError(f"method {self.name}: contact_model must be an exported .onnx contact model or \"\" "
                             f"(the scene's), got {self.contact_model!r}")
        if self.escalation not in ("symmetry", "samples"):
            raise ValueError(f"method {self.name}: escalation must be 'symmetry' or 'samples', got {self.escalation!r}")
        if self.escalate_below > 0 and self.escalation == "symmetry" and self.symmetrize:
            raise ValueError(f"method {self.name}: symmetrize = true already averages every reading over the "
                             "symmetries; escalate with escalation = \"samples\" or not at all")
        if self.escalate_below > 0 and self.escalation == "samples" and self.reconstructor in ("bilinear", "bicubic"):
            raise ValueError(f"method {self.name}: the 'samples' escalation draws prior samples of an ONNX model; "
                             f"{self.reconstructor} has none")


@dataclass(frozen=True)
class TrialObject:
    """An object the trials present (any simulator shape, see ``tactile-manip params`` / sim.shapes).

    Attributes:
        name: shape name, e.g. "cylinder", "hex_bar", "square_bar".
        label: name in the logs (default: name).
        kwargs: shape arguments, e.g. {size_mm = 3.0}.
        width_mm: width across the fingers, mm (0: the shape's ``size_mm``, right for the rods).
    """

    name: str
    label: str = ""
    kwargs: dict[str, Any] = field(default_factory=dict)
    width_mm: float = 0.0

    def __post_init__(self) -> None:
        check_shape_arguments(self.name, self.kwargs, where="kwargs")  # refused at load, not mid-run

    @property
    def display_name(self) -> str:
        return self.label or self.name

    @property
    def grasp_width_m(self) -> float:
        width = self.width_mm or float(self.kwargs.get("size_mm", 0.0))
        if not width > 0:
            raise ValueError(f"object {self.display_name}: set width_mm (no size_mm to take the width from)")
        return width * 1e-3


@dataclass(frozen=True)
class PresentationConfig:
    """How an object is put between the fingers: its in-hand angle and contact offset, drawn per trial.

    Attributes:
        angle_deg: [low, high] of the uniform in-hand angle of the object's axis in the pad frame, deg.
        offset_mm: the contact centre is uniform within +-offset_mm of the pad centre in pad x and y, mm.
        force_n: [low, high] of the uniform grasp force, N (the gripper's threshold plus overshoot).
        sensor_spread: 0 presents every trial to the nominal simulated sensor; > 0 draws each trial's sensor
            (magnetisation, gap, moduli, chip noise, ...) from the simulator's randomisation ranges shrunk about
            the defaults by this factor (1: the full ranges; ``tactile-manip params`` lists them). The draw is
            a function of the trial's seed: every method meets the same sensor in the same trial.
        objects: presented in turn (trial i gets object i mod len(objects)).
    """

    angle_deg: tuple[float, float] = (-90.0, 90.0)
    offset_mm: float = 2.0
    force_n: tuple[float, float] = (10.0, 11.0)
    sensor_spread: float = 0.0
    objects: list[TrialObject] = field(default_factory=list)

    def __post_init__(self) -> None:
        lo, hi = self.angle_deg
        if not (math.isfinite(lo) and math.isfinite(hi) and -180.0 <= lo <= hi <= 180.0):
            raise ValueError(f"presentation.angle_deg must be [low, high] within [-180, 180], got {self.angle_deg}")
        check_finite_scalar("presentation.offset_mm", self.offset_mm, low=0.0, high=8.0)
        f_lo, f_hi = self.force_n
        if not (math.isfinite(f_lo) and math.isfinite(f_hi) and 0 < f_lo <= f_hi <= 140.0):
            raise ValueError(f"presentation.force_n must be [low, high] within (0, 140] N, got {self.force_n}")
        check_finite_scalar("presentation.sensor_spread", self.sensor_spread, low=0.0, high=1.0)


@dataclass(frozen=True)
class RobotConfig:
    """Which arm and gripper: the kinematic twin, or a real FR3 through franky-control.

    Attributes:
        backend: "twin" or "franky".
        host: franky only: the robot's address (FCI enabled).
        relative_dynamics_factor: franky only: fraction of the robot's velocity/acceleration/jerk limits.
        enforce_realtime: franky only: refuse to move without a real-time (PREEMPT_RT) kernel, as a real FR3
            wants; false to rehearse a scene against franky-sim on an ordinary machine.
        speed_factor: twin only: fraction of the joint velocity limits used for the modelled durations.
        home_q_rad: where each trial starts and the object is presented, rad. The default holds the hand
            pointing straight down with the pad normal along -x of the base (the fingers close along base x),
            so turns of +-95 degrees about the pad normal stay inside the FR3 joint limits in both directions
            (from the twin's home, joint 7 at +pi/4, joint 6 reaches its limit before +90 degrees).
        safety: limits every target is checked against before the arm moves.
    """

    backend: Literal["twin", "franky"] = "twin"
    host: str = ""
    relative_dynamics_factor: float = 0.05
    enforce_realtime: bool = True
    speed_factor: float = 0.1
    home_q_rad: tuple[float, float, float, float, float, float, float] = (
        0.0, -0.3, 0.0, -2.2, 0.0, 1.9, -math.pi / 4)
    safety: SafetyLimits = field(default_factory=SafetyLimits)

    def __post_init__(self) -> None:
        check_finite_scalar("robot.relative_dynamics_factor", self.relative_dynamics_factor, low=0.0,
                            low_open=True, high=1.0)
        check_finite_scalar("robot.speed_factor", self.speed_factor, low=0.0, low_open=True, high=1.0)
        if self.backend == "franky" and not self.host:
            raise ValueError("robot.host: the franky backend needs the robot's address (no default robot)")


@dataclass(frozen=True)
class FaultPlan:
    """Faults injected on purpose (simulation only), to prove a run survives them.

    Attributes:
        arm_fault_trials: trial indices whose correction move stops on an injected reflex.
        sensor_stall_trials: trial indices during which the tactile sensor stops after the grasp.
    """

    arm_fault_trials: list[int] = field(default_factory=list)
    sensor_stall_trials: list[int] = field(default_factory=list)


TASKS = ("reorient", "place", "grip")
TASK_TITLES = {"reorient": "Reorientation trials", "place": "Slot placement trials",
               "grip": "Grip-to-force trials"}


@dataclass(frozen=True)
class PlaceConfig:
    """The slot of the "place" task: drawn per presentation in the pad plane, 4-6 cm beyond the pad centre along
    -pad y, at a random angle; a placement succeeds with the rod within ``tolerance_deg`` of the slot's axis and
    its axis within ``clearance_mm`` of the slot's centre."""

    clearance_mm: float = 1.0

    def __post_init__(self) -> None:
        check_finite_scalar("place.clearance_mm", self.clearance_mm, low=0.0, low_open=True, high=50.0)


@dataclass(frozen=True)
class TrialScene:
    """Everything ``tactile-manip trials`` needs (see ``configs/scenes/reorient_sim.toml``).

    Attributes:
        name: scene name (in the logs and the report title).
        trials: presentations per run; each is run once per method on the same seed.
        seed: master seed: presentation i uses ``numpy.random.SeedSequence([seed, i])``.
        tolerance_deg: success tolerance on |final - target|, deg (re-score later with ``tactile-manip score``).
        target_deg: commanded final angle of the object's axis in the pad frame at grasp, deg.
        methods: the compared methods (default: the shipped SuperMag model, one pass and averaged over the
            sensor's symmetries, and the paper's 16x16 bilinear baseline).
        presentation, robot, behaviour, faults: see their classes.
        sensor: the simulated sensor's settings (twin), or the board's serial settings (``port = ...``, real FR3).
        contact_model: a contact model of the sensor's board (an exported ``.onnx``, found as the methods'
            models are, e.g. ``models/contact_supermag.onnx``): each trial then logs the grip force the model
            estimates at the estimate step (``estimated_grip_force_n``); "" for none. A model of another
            board layout than the sensor's is refused before the first trial.
        task: the behaviour each trial runs: "reorient" (grasp, estimate the in-hand angle, turn the rod to
            ``target_deg``), "place" (grasp, estimate angle and contact centroid, put the rod into a slot
            drawn per presentation; :mod:`tactile_manip.behaviours.place`) or "grip" (grasp at the
            behaviour's ``force_n``, centre the rod on the pad and servo the grip force from the contact model;
            :mod:`tactile_manip.behaviours.grip`). The summary names it.
        place: the slot of the "place" task.
        grip: the tolerances and limits of the "grip" task (its target force is ``behaviour.force_n``; the
            force the gripper really applies is the presentation's ``force_n`` scaled by command / target).
    """

    name: str = "reorient"
    trials: int = 100
    seed: int = 0
    tolerance_deg: float = 5.0
    target_deg: float = 0.0
    methods: list[MethodSpec] = field(default_factory=lambda: [
        MethodSpec("supermag", "models/supermag.onnx"),
        MethodSpec("supermag_sym", "models/supermag.onnx", symmetrize=True),
        MethodSpec("paper_route", "models/supermag.onnx", angle_source="image"),
        MethodSpec("bilinear", "bilinear", output_px=16),
        MethodSpec("blind", "blind")])
    presentation: PresentationConfig = field(default_factory=PresentationConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    sensor: SimulatedSensorConfig | SerialSensorConfig = field(default_factory=SimulatedSensorConfig)
    behaviour: ReorientConfig = field(default_factory=ReorientConfig)
    faults: FaultPlan = field(default_factory=FaultPlan)
    contact_model: str = ""
    task: Literal["reorient", "place", "grip"] = "reorient"
    place: PlaceConfig = field(default_factory=PlaceConfig)
    grip: GripConfig = field(default_factory=GripConfig)

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {', '.join(TASKS)}, got {self.task!r}")
        if self.task == "place" and self.robot.backend != "twin":
            raise ValueError("task = \"place\" runs in the simulated cell only (robot.backend = \"twin\"): the "
                             "slot is a world feature the twin knows")
        if self.task == "grip" and self.robot.backend != "twin":
            raise ValueError("task = \"grip\" runs in the simulated cell only (robot.backend = \"twin\"): it is "
                             "scored on the force the object feels, which only the twin knows")
        if self.task == "grip" and not self.contact_model and not any(m.contact_model for m in self.methods):
            raise ValueError("task = \"grip\" needs a contact_model (the force and position it servoes on), e.g. "
                             "contact_model = \"models/contact_supermag.onnx\"")
        if isinstance(self.trials, bool) or self.trials < 1:
            raise ValueError(f"trials must be a positive integer, got {self.trials!r}")
        check_finite_scalar("tolerance_deg", self.tolerance_deg, low=0.0, low_open=True, high=90.0)
        check_finite_scalar("target_deg", self.target_deg, low=-90.0, high=90.0)
        if not self.methods:
            raise ValueError("methods: name at least one method")
        names = [m.name for m in self.methods]
        if len(set(names)) != len(names):
            raise ValueError(f"methods: names must be unique, got {names}")
        if not self.presentation.objects:
            raise ValueError("presentation.objects: name at least one object")
        if self.contact_model and not self.contact_model.endswith(".onnx"):
            raise ValueError(f"contact_model must be an exported .onnx contact model or \"\" (none), got "
                             f"{self.contact_model!r}")


def load_scene(path: str | Path) -> TrialScene:
    """Read a scene TOML file (raises ConfigError naming the file and the key on any problem)."""
    return load_config(path, TrialScene)
