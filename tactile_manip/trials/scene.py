"""A trial scene: the TOML file ``tactile-manip trials --config`` reads, as typed dataclasses.

A scene names only what the job needs (docs/design.md, Scenes): the task each trial runs and its settings, the
methods compared, the objects and how they are presented, the robot backend with its safety limits, the tactile
sensor, the behaviour's parameters and (for robustness runs) a fault plan. See
``configs/scenes/reorient_sim.toml`` for a commented example, and docs/your_task.md for a task of your own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Literal

from tactile_manip.behaviours.registry import DEFAULT_TASK, task_class
from tactile_manip.behaviours.skills import BehaviourConfig
from tactile_manip.checks import check_finite_scalar
from tactile_manip.config import from_dict, read_toml
from tactile_manip.errors import ConfigError
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
        task: the task each trial runs: a name of the table in :mod:`tactile_manip.behaviours.registry`
            (the shipped tasks: reorient, the default, turns the rod to ``target_deg``; place puts it into a slot
            drawn per presentation; grip servoes the grip force, centred, from the contact model), or
            ``"module:Class"`` for a task of your own (docs/your_task.md). The records and the summary name it.
        task_config: the task's settings, an instance of the task's ``Config`` (a dict is read into one; None:
            its defaults). In a scene file they are the table named after the task (e.g. ``[wipe]``).

    ``settings`` (not a field) is the task's settings in use: ``task_config``, or the defaults of the task's
    ``Config`` where it is None.
    """

    name: str = "scene"
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
    behaviour: BehaviourConfig = field(default_factory=BehaviourConfig)
    faults: FaultPlan = field(default_factory=FaultPlan)
    contact_model: str = ""
    task: str = DEFAULT_TASK
    task_config: Any = None

    def __post_init__(self) -> None:
        cls = task_class(self.task)
        if isinstance(self.task_config, dict):
            object.__setattr__(self, "task_config", from_dict(cls.Config, self.task_config, where="task_config",
                                                              prefix=cls.name))
        elif self.task_config is not None and not isinstance(self.task_config, cls.Config):
            raise ValueError(f"task_config of task {self.task!r} must be a {cls.Config.__name__}, got "
                             f"{type(self.task_config).__name__}")
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
        # the task's settings: task_config, or the defaults of the task's Config where it is None
        object.__setattr__(self, "settings", self.task_config if self.task_config is not None else cls.Config())
        cls.check_scene(self)


def load_scene(path: str | Path) -> TrialScene:
    """Read a scene TOML file (raises ConfigError naming the file and the key on any problem).

    The task's settings are the file's table named after the task (``Task.name``), e.g. ``[wipe]``."""
    raw = read_toml(path)
    ref = raw.get("task", DEFAULT_TASK)
    if isinstance(ref, str) and "task_config" not in raw:
        try:
            cls = task_class(ref)
        except ValueError as e:
            raise ConfigError(f"{path}: {e}") from None
        if cls.name in {f.name for f in fields(TrialScene)}:
            raise ConfigError(f"{path}: task {ref!r} is called {cls.name!r}, the name of a scene key; rename the task")
        if cls.name in raw:
            raw["task_config"] = from_dict(cls.Config, raw.pop(cls.name), where=str(path), prefix=cls.name)
    return from_dict(TrialScene, raw, where=str(path))
