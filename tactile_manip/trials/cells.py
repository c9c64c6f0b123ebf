"""The trial cells: where a scene's trials run. Both take a presentation and a method's estimator and run the
scene's task (:meth:`Cell.run_one`: the task's ``run`` on the cell's hardware, the object and its truth) between
:meth:`Cell.connected`'s connect and disconnect.

- :class:`SimulatedCell`: the kinematic FR3 twin holds the presented object; when the twin gripper closes on it,
  the simulated tactile sensor is told the contact (the object's shape, its in-hand angle and offset in the pad
  frame, the force the object feels) and renders the magnetic field of that contact at 125 Hz with fresh chip
  noise per frame; when the gripper opens, the pad is empty again. The estimator only ever sees the sensor's
  frames. The trial is scored from the twin's truth.
- :class:`~tactile_manip.trials.operator.OperatorCell`: a real FR3 through franky-control, with an operator who
  presents each object and measures the result.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Protocol

import numpy as np

from tactile_manip.behaviours.registry import task_class
from tactile_manip.behaviours.task import Task, Trial
from tactile_manip.errors import ConfigError
from tactile_manip.extras import require
from tactile_manip.robot.frames import hand_T_finger_pad
from tactile_manip.sensors.config import SimulatedSensorConfig
from tactile_manip.trials.presentation import Presentation, pad_T_object
from tactile_manip.trials.scene import TrialScene

if TYPE_CHECKING:
    from tactile_manip.perception.tactile_estimator import TactileEstimator


class Cell(Protocol):
    """Where a scene's trials run: what :func:`~tactile_manip.trials.runner.run_scene` needs of a cell."""

    scene: TrialScene
    task: Task

    def connected(self) -> contextlib.AbstractContextManager:
        """Connect the cell's arm, gripper and sensor, take the sensor's baseline, disconnect at the end."""

    def run_one(self, p: Presentation, estimator, *, arm_fault: bool = False, sensor_stall: bool = False,
                observer=None):
        """Present ``p`` and run the scene's task with the method's ``estimator``; the task's result (never
        raises for a fault of the trial: it is an outcome)."""

    # A cell may also offer ``holds(p) -> bool``: whether it can hold presentation ``p`` at all. The runner then
    # draws a trial again where it cannot (see :func:`~tactile_manip.trials.presentation.draw_presentation`).


# A drawn sensor's baseline: 25 frames (0.2 s) average the chip noise (<= 15 uT per frame) to <= 3 uT, well
# under the 20 uT no-contact threshold, at a fraction of the 1 s a session's first baseline takes.
SENSOR_DRAW_BASELINE_FRAMES = 25


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
        self.task = make_task(scene)
        self.twin = KinematicArm(TwinArmConfig(home_q_rad=scene.robot.home_q_rad,
                                               speed_factor=scene.robot.speed_factor))
        self.arm = SafeArm(self.twin, scene.robot.safety)
        self.world = TwinWorld(self.twin)
        self.gripper = TwinGripper(self.twin, self.world)
        self.sensor = SimulatedSensor(scene.sensor)
        self._indenters = {o.display_name: make_indenter(o.name, **o.kwargs) for o in scene.presentation.objects}
        self._presentation: Presentation | None = None
        self._sensor_key: int | None = None      # seed of the drawn sensor in use (None: the nominal one)
        self._pairs: dict[int | None, object] = {}  # the last simulated sensor pair built, by that key
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

    def holds(self, p: Presentation) -> bool:
        """Whether ``p``'s object, pressed at ``p``'s force on ``p``'s sensor, stays within the skin's elastic
        layer. Past it the object would bottom out on the rigid base, which the simulator does not model, and
        the trial could only fail for every method alike; the runner draws such a trial again."""
        from tactile_manip.sim.objects import IndenterPose

        pose = IndenterPose(x_mm=p.offset_mm[0], y_mm=p.offset_mm[1], yaw_rad=p.angle_rad)
        rng = np.random.default_rng(self.scene.sensor.seed)  # the press's noise is not read
        sample = self._pair_of(p).press(self._indenters[p.obj.display_name], pose, p.force_n, rng,
                                        render_depth=False)
        return not sample.bottomed_out

    def _pair_of(self, p: Presentation):
        """The simulated sensor pair of ``p``'s sensor (the scene's board, drawn or nominal); the last one is kept."""
        from tactile_manip.sim.pair import SensorPair

        params = p.sensor_params(self.scene.sensor.board)
        key = None if params is None else p.seed
        if key not in self._pairs:
            self._pairs = {key: SensorPair(params, board=self.sensor.pair.board, seed=self.scene.sensor.seed)}
        return self._pairs[key]

    def _use_sensor_of(self, p: Presentation) -> None:
        """Swap in the trial's drawn sensor (or back to the nominal one) and take its baseline, pad unloaded."""
        key = None if p.sensor_spread == 0 else p.seed
        if key == self._sensor_key:
            return
        self.sensor.replace_pair(self._pair_of(p))
        self.sensor.calibrate_baseline(frames=SENSOR_DRAW_BASELINE_FRAMES)
        self._sensor_key = key

    def run_one(self, p: Presentation, estimator: TactileEstimator, *, arm_fault: bool = False,
                sensor_stall: bool = False, observer=None):
        """Present ``p``, run the scene's task with ``estimator``, release, reset.

        ``observer`` (a :class:`~tactile_manip.behaviours.reorient.PhaseObserver`) is handed to the task.
        """
        with self.presented(p, arm_fault=arm_fault, sensor_stall=sensor_stall) as (obj, truth):
            return self.task.run(trial_of(self, p, estimator, obj.width_m, truth, observer))

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


def make_cell(scene: TrialScene):
    """The trial cell of ``scene.robot.backend``: :class:`SimulatedCell` for the twin, else an operator cell."""
    if scene.robot.backend == "twin":
        return SimulatedCell(scene)
    from tactile_manip.trials.operator import OperatorCell

    return OperatorCell(scene)


def make_task(scene: TrialScene) -> Task:
    """The task ``scene`` runs, built on it (its settings, the behaviour's parameters).

    Raises:
        ConfigError: the task class cannot be built (a method it must define is missing).
    """
    cls = task_class(scene.task)
    try:
        return cls(scene)
    except TypeError as e:
        raise ConfigError(f"task {scene.task!r}: {e}") from None


def trial_of(cell, p: Presentation, estimator: TactileEstimator, object_width_m: float, truth,
             observer=None) -> Trial:
    """What the task is handed for trial ``p`` in ``cell`` (its arm, gripper and sensor)."""
    return Trial(arm=cell.arm, gripper=cell.gripper, sensor=cell.sensor, estimator=estimator,
                 object_width_m=object_width_m, seed=p.seed, presentation=p, truth=truth, observer=observer)
